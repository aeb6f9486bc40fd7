"""Workers forked from the supervisor (flowtact.runtime.forked) run the graph exactly as workers
started as their own interpreters do, are told apart by name, and are watched as Popen objects are."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading

import pytest
from runs import ROOT, children, wait_children

from flowtact.recording.hdf5 import read_recording
from flowtact.runtime.forked import NO_FORK_ENV, ForkedWorker, can_fork, comm_name

TOUCH = str(ROOT / "graphs" / "touch.yaml")


def _run(tmp_path, name: str, *, fork: bool, fast: bool = True) -> dict:
    env = dict(os.environ)
    env.pop(NO_FORK_ENV, None)
    if not fork:
        env[NO_FORK_ENV] = "1"
    rec = tmp_path / f"{name}.h5"
    mode = ["--fast"] if fast else []
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "flowtact.cli",
            "run",
            TOUCH,
            *mode,
            "--duration",
            "1",
            "--record",
            str(rec),
            "--json",
        ],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr
    return {"summary": json.loads(proc.stdout), "recording": read_recording(rec)}


def test_forked_and_own_interpreter_workers_record_the_same_bits(tmp_path):
    forked = _run(tmp_path, "forked", fork=True)
    own = _run(tmp_path, "own", fork=False)
    a, b = forked["recording"].streams, own["recording"].streams
    assert a.keys() == b.keys() and a
    for name, s in a.items():
        assert s.t.tobytes() == b[name].t.tobytes() and s.data.tobytes() == b[name].data.tobytes(), name
    # the forked run set numba up before forking; the other did not
    assert "kernels" in forked["summary"]["startup_parts"]
    assert "kernels" not in own["summary"]["startup_parts"]


def test_start_up_parts_add_up_to_the_start_up(tmp_path):
    s = _run(tmp_path, "parts", fork=True, fast=False)["summary"]
    parts = s["startup_parts"]
    assert {"launch", "start", "build", "warm_up", "bind", "wiring", "other"} <= parts.keys()
    assert all(v >= 0 for v in parts.values()), parts
    # "other" is the remainder, so the parts add up (float sums: a few ulps of ~1 s)
    assert sum(parts.values()) == pytest.approx(s["startup_s"], abs=1e-9), parts
    assert s["wall_s"] >= s["startup_s"]


def test_forked_workers_are_named_for_their_group():
    proc = subprocess.Popen(
        [sys.executable, "-m", "flowtact.cli", "run", TOUCH, "--duration", "30", "--quiet"],
        env={k: v for k, v in os.environ.items() if k != NO_FORK_ENV},
    )
    try:
        kids = wait_children(proc.pid, 3)
        names = set()
        for k in kids:
            with open(f"/proc/{k}/comm") as f:
                names.add(f.read().strip())
        assert names == {comm_name(g) for g in ("sensing", "encoding", "afferents")}
        assert set(kids) <= set(children(proc.pid))  # children of the run: it reaps them
    finally:
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=120) == 0


def test_a_forked_worker_reports_its_exit_as_popen_does():
    pid = os.fork()
    if pid == 0:
        os._exit(3)
    w = ForkedWorker(pid)
    assert w.wait(timeout=60) == 3 and w.poll() == 3
    w.kill()  # reaped: never signals a pid that may be another process's now

    pid = os.fork()
    if pid == 0:
        signal.pause()
        os._exit(0)
    w = ForkedWorker(pid)
    assert w.poll() is None
    with pytest.raises(subprocess.TimeoutExpired):
        w.wait(timeout=0.01)
    w.kill()
    assert w.wait(timeout=60) == -signal.SIGKILL


def test_no_fork_with_a_second_thread_or_when_turned_off(monkeypatch):
    monkeypatch.delenv(NO_FORK_ENV, raising=False)
    assert can_fork() is (sys.platform.startswith("linux") and threading.active_count() == 1)
    stop = threading.Event()
    t = threading.Thread(target=stop.wait)
    t.start()
    try:
        assert not can_fork()  # a lock held by another thread would stay held in the fork
    finally:
        stop.set()
        t.join()
    monkeypatch.setenv(NO_FORK_ENV, "1")
    assert not can_fork()


def test_comm_name_fits_linux_15_bytes():
    assert comm_name("afferents") == "ft:afferents"
    assert len(comm_name("a_very_long_process_group_name").encode()) == 15
