"""Every command in the README's code blocks runs, as written, in a fresh copy of the checkout.

The copy holds only the files git tracks (no leftover recordings), and the commands run in README
order in it, so a command that needs an earlier one's output (``touch.h5``) gets exactly what the
reader would have. The set-up and test commands are CI's own (``.ci/run`` runs them verbatim);
everything else must exit 0 without a traceback (commands too long for the suite are replaced by
their cheap check, ``doc_pages.CHECKED_ONLY``). The README's graph example is validated too.
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from doc_pages import CHECKED_ONLY, clean_env

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"

#: Run by .ci/run itself (installing into a fresh venv; the suite this test belongs to).
CI_OWN = {
    'python3 -m venv .venv && . .venv/bin/activate && pip install -c constraints.txt -e ".[dev]"',
    "pytest",
}
#: Commands that serve until stopped: run until they print this, then Ctrl-C, expect exit 0.
SERVES = {"flowtact sim exo": "PORT "}
TIMEOUT_S = 1200  # a hang, not a slow machine: the longest command takes ~1 min idle

pytestmark = [pytest.mark.slow, pytest.mark.cli]


def code_blocks(lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", README.read_text(), re.S)


def readme_commands() -> list[str]:
    """The README's shell commands in order, comments stripped, each once."""
    out: list[str] = []
    for block in code_blocks("bash"):
        for line in block.splitlines():
            cmd = line.split("  #", 1)[0].strip()
            if cmd and not cmd.startswith("#") and cmd not in out:
                out.append(cmd)
    return out


def fresh_checkout(dest: Path) -> Path:
    """The files git tracks, copied from this working tree (uncommitted edits included)."""
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    files = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout.split(
        b"\0"
    )
    for name in filter(None, files):
        src = ROOT / os.fsdecode(name)
        if src.is_file():
            (dest / os.fsdecode(name)).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest / os.fsdecode(name))
    return dest


def argv(cmd: str) -> list[str]:
    """``flowtact ...`` through the flowtact installed beside this interpreter."""
    words = shlex.split(cmd)
    if words[0] == "flowtact":
        exe = Path(sys.executable).parent / "flowtact"
        words[:1] = [str(exe)] if exe.exists() else [sys.executable, "-m", "flowtact.cli"]
    return words


def serve_then_stop(words: list[str], ready: str, cwd: Path) -> tuple[int, str]:
    proc = subprocess.Popen(
        words,
        cwd=cwd,
        env=clean_env(cwd),
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    assert proc.stdout is not None
    first = proc.stdout.readline()  # blocks until it serves (or exits)
    if ready in first:
        proc.send_signal(signal.SIGINT)
    try:
        rest = proc.communicate(timeout=60)[0]
    except subprocess.TimeoutExpired:
        proc.kill()
        rest = proc.communicate()[0] + "\n(did not stop on Ctrl-C)"
    return proc.returncode, first + rest


def test_the_readme_shows_the_ci_commands():
    cmds = [c.strip() for block in code_blocks("bash") for c in block.splitlines()]
    assert set(cmds) >= CI_OWN, "the README's set-up or test command changed: update .ci/run and CI_OWN"


@pytest.mark.timeout(3 * TIMEOUT_S)  # every README command in turn: longer than the suite's per-test 600 s
def test_every_readme_command_runs(tmp_path):
    work = fresh_checkout(tmp_path / "checkout")
    env = {**clean_env(work), "COLUMNS": "100"}  # no variable the README does not set
    failures = []
    for cmd in readme_commands():
        if cmd in CI_OWN:
            continue
        cmd = CHECKED_ONLY.get(cmd, cmd)  # too long for the suite: its cheap check (doc_pages)
        ready = SERVES.get(cmd)
        if ready:
            code, out = serve_then_stop(argv(cmd), ready, work)
        else:
            proc = subprocess.run(
                ["bash", "-e", "-c", cmd],  # as typed in a shell (eval, quotes, pipes)
                cwd=work,
                env=env,
                stdin=subprocess.DEVNULL,
                capture_output=True,
                text=True,
                timeout=TIMEOUT_S,
            )
            code, out = proc.returncode, proc.stdout + proc.stderr
        if code != 0 or "Traceback" in out:
            failures.append(f"$ {cmd}\n(exit {code})\n{out[-2000:]}")
    assert not failures, "\n\n".join(failures)


def test_the_readme_graph_validates(tmp_path):
    graphs = [b for b in code_blocks("yaml") if "nodes:" in b and "block: ..." not in b]
    assert graphs, "the README shows a graph"
    for i, text in enumerate(graphs):
        path = tmp_path / f"readme{i}.yaml"
        path.write_text(text)
        proc = subprocess.run(
            [*argv("flowtact validate"), str(path)], capture_output=True, text=True, timeout=120
        )
        assert proc.returncode == 0, proc.stderr
