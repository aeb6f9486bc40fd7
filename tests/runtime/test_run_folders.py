"""Run folders left by a killed run are swept by the next start, and nothing else is (issue 30: temp
folders removed even when the supervisor is killed, safely: only this user's, only dead owners')."""

from __future__ import annotations

import fcntl
import os
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest
from runs import ROOT, env

from flowtact.runtime.rundir import (
    LOCK_NAME,
    MAX_STALE_PER_SWEEP,
    clean_stale,
    is_stale,
    make_run_folder,
    process_start,
)

MAKE_AND_WAIT = (
    "import sys; from flowtact.runtime.rundir import make_run_folder; "
    "f = make_run_folder('run', root=sys.argv[1]); print(f.path, flush=True); sys.stdin.read()"
)


def gone_pid() -> int:
    """The pid of a process that has exited and been reaped."""
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def fake_folder(root: Path, pid: int, start: int, *, mode: int = 0o700, tail: str = "abcd_123") -> Path:
    """A folder as a run of ``pid`` started at ``start`` leaves it (its lock not held), holding a file."""
    path = root / f"flowtact-run-{tail}"
    path.mkdir(mode=mode)
    os.chmod(path, mode)
    (path / LOCK_NAME).write_text(f"{pid} {start}\n")
    (path / "ctl").write_text("socket stand-in")
    return path


def owner(folder: Path) -> int:
    return int((folder / LOCK_NAME).read_text().split()[0])


def readline_within(proc: subprocess.Popen, timeout_s: float) -> str:
    ready, _, _ = select.select([proc.stdout], [], [], timeout_s)
    assert ready, f"no line within {timeout_s:g} s"
    return proc.stdout.readline().strip()


def test_the_folder_of_a_run_killed_with_sigkill_is_swept(tmp_path):
    proc = subprocess.Popen(
        [sys.executable, "-c", MAKE_AND_WAIT, str(tmp_path)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        path = Path(readline_within(proc, 60))
        assert not clean_stale(str(tmp_path)) and path.is_dir()  # its owner runs: kept
        proc.kill()
        proc.wait(timeout=30)
    finally:
        proc.kill()
        proc.stdin.close()
        proc.stdout.close()
    assert path.is_dir()  # SIGKILL skipped the owner's own clean-up
    assert (path.stat().st_mode & 0o777) == 0o700
    assert clean_stale(str(tmp_path)) == [str(path)]
    assert not path.exists()


def test_a_new_run_folder_sweeps_a_dead_runs_folder_first(tmp_path):
    dead = fake_folder(tmp_path, gone_pid(), 12345)
    with make_run_folder("serial", root=str(tmp_path)) as mine:
        assert not dead.exists()
        assert Path(mine.path).name.startswith("flowtact-serial-")
        assert owner(Path(mine.path)) == os.getpid()
    assert not Path(mine.path).exists()  # close removes its own folder


def test_a_reused_pid_does_not_keep_a_dead_runs_folder(tmp_path):
    start = process_start(os.getpid())
    assert start  # Linux: /proc gives the start time
    reused = fake_folder(tmp_path, os.getpid(), start + 1)  # this pid, but another process's start
    assert is_stale(str(reused))
    live = fake_folder(tmp_path, os.getpid(), start, tail="live_000")  # lock not held, owner alive
    assert not is_stale(str(live))


def test_live_foreign_and_look_alike_entries_are_kept(tmp_path):
    start = process_start(os.getpid())
    live = make_run_folder("run", root=str(tmp_path))
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "precious").write_text("keep me")
    link = tmp_path / "flowtact-run-link_000"
    link.symlink_to(elsewhere, target_is_directory=True)
    (elsewhere / LOCK_NAME).write_text(f"{gone_pid()} 1\n")
    shared = fake_folder(tmp_path, gone_pid(), 1, mode=0o755, tail="shared00")
    plain = tmp_path / "flowtact-run-file_000"
    plain.write_text("a file named like a run folder")
    nolock = fake_folder(tmp_path, gone_pid(), 1, tail="nolock00")
    (nolock / LOCK_NAME).unlink()
    lockln = fake_folder(tmp_path, gone_pid(), 1, tail="lockln00")
    (lockln / LOCK_NAME).unlink()
    (lockln / LOCK_NAME).symlink_to(elsewhere / LOCK_NAME)
    older = tmp_path / "flowtact-abcd1234"  # an older release's name: no pid to judge by
    older.mkdir(mode=0o700)
    example = tmp_path / "flowtact-camera-example-v1"
    example.mkdir(mode=0o700)
    held = fake_folder(tmp_path, gone_pid(), 1, tail="held_000")  # e.g. its owner in another pid namespace
    fd = os.open(held / LOCK_NAME, os.O_RDONLY)
    fcntl.flock(fd, fcntl.LOCK_EX)
    try:
        assert clean_stale(str(tmp_path)) == []
    finally:
        os.close(fd)
        live.close()
    for kept in (elsewhere / "precious", link, shared, plain, nolock, lockln, older, example, held):
        assert os.path.lexists(kept), kept
    assert (elsewhere / "precious").read_text() == "keep me"
    assert start is not None


@pytest.mark.skipif(os.getuid() != 0, reason="making another user's folder needs root")
def test_another_users_folder_is_kept(tmp_path):
    theirs = fake_folder(tmp_path, gone_pid(), 1)
    os.chown(theirs, 65534, 65534)
    assert not is_stale(str(theirs))
    assert clean_stale(str(tmp_path)) == [] and theirs.is_dir()


def test_one_sweep_removes_a_bounded_number(tmp_path):
    pid = gone_pid()
    for i in range(MAX_STALE_PER_SWEEP + 3):
        fake_folder(tmp_path, pid, 1, tail=f"n{i:07d}")
    assert len(clean_stale(str(tmp_path))) == MAX_STALE_PER_SWEEP
    assert len(clean_stale(str(tmp_path))) == 3


def wait_for_run_folder(tmp: Path, proc: subprocess.Popen, timeout_s: float) -> Path:
    """The supervisor's run folder in ``tmp``, polled until it appears (bounded)."""
    deadline = time.monotonic() + timeout_s
    while True:
        found = [f for f in tmp.glob("flowtact-run-*") if (f / LOCK_NAME).is_file() and owner(f) == proc.pid]
        if found and any(found[0].glob("s*")):  # its worker sockets: the run is under way
            return found[0]
        assert proc.poll() is None, proc.communicate()[1]
        assert time.monotonic() < deadline, f"no run folder in {tmp} after {timeout_s:g} s"
        time.sleep(0.02)


def test_a_killed_supervisors_folder_is_swept_by_the_next_run():
    tmp = Path(tempfile.mkdtemp(prefix="ft-"))  # short: ipc socket paths are limited to 107 bytes
    try:
        killed_and_swept(tmp)
    finally:
        shutil.rmtree(tmp)


def killed_and_swept(tmp: Path) -> None:
    run_env = {**env(), "TMPDIR": str(tmp)}
    touch = str(ROOT / "graphs" / "touch.yaml")
    proc = subprocess.Popen(
        [sys.executable, "-m", "flowtact.cli", "run", touch, "--duration", "3600", "--quiet"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env=run_env,
        start_new_session=True,
    )
    try:
        folder = wait_for_run_folder(tmp, proc, 120)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate(timeout=30)
    assert folder.is_dir()  # kill -9 left it behind
    again = subprocess.run(
        [sys.executable, "-m", "flowtact.cli", "run", touch, "--duration", "0.2", "--fast", "--quiet"],
        capture_output=True,
        text=True,
        env=run_env,
        timeout=300,
    )
    assert again.returncode == 0, again.stderr
    assert not folder.exists()
    assert not list(tmp.glob("flowtact-run-*"))  # the second run removed its own folder too
