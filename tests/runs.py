"""Helpers for tests that run ``flowtact`` as a user would: in a subprocess, with real workers.

They wait for events (a worker appears, a recording holds data, a line is printed) with generous
bounds instead of sleeping a fixed time, so they hold on a loaded 2-core machine.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

from flowtact.recording.hdf5 import read_recording
from flowtact.runtime.forked import comm_name

ROOT = Path(__file__).resolve().parent.parent
TESTS = Path(__file__).resolve().parent


TEST_BLOCKS = ("toyblocks", "hotpathblocks", "sealblocks", "brokenblocks", "warmblocks", "sweepblocks")
"""The test modules whose ``module:Class`` blocks the tests' graphs name: a graph may import them
only when allowed (``allow_modules=TEST_BLOCKS``, ``--allow-module``; docs/security.md)."""

GRAPH_COMMANDS = ("run", "validate", "graph", "sweep")


def allow_args(args: tuple[str, ...] | list[str]) -> list[str]:
    """``args`` with ``--allow-module M`` for each test block module when its command loads a graph."""
    command = next((a for a in args if not a.startswith("-")), None)
    extra = [w for m in TEST_BLOCKS for w in ("--allow-module", m)] if command in GRAPH_COMMANDS else []
    return [*args, *extra]


def env() -> dict[str, str]:
    """The environment with the test blocks (``toyblocks:Class``) importable."""
    out = dict(os.environ)
    out["PYTHONPATH"] = os.pathsep.join([str(TESTS), out.get("PYTHONPATH", "")])
    return out


def flowtact(*args: str, **kw) -> subprocess.Popen:
    """Start ``flowtact ARGS`` (text stdout/stderr pipes), the test blocks allowed (:func:`allow_args`)."""
    return subprocess.Popen(
        [sys.executable, "-m", "flowtact.cli", *allow_args(args)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env(),
        **kw,
    )


def children(pid: int) -> list[int]:
    """Process ids whose parent is ``pid``."""
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            out.append(int(stat.parent.name))
    return out


def alive(pid: int) -> bool:
    """Is ``pid`` a live (not zombie) process?"""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def wait_children(pid: int, n: int, timeout: float = 60.0) -> list[int]:
    """Wait until the supervisor ``pid`` has started ``n`` workers; their pids."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        kids = []
        for k in children(pid):
            try:
                if _is_worker(k):
                    kids.append(k)
            except OSError:
                continue
        if len(kids) >= n:
            return kids
        time.sleep(0.05)
    raise AssertionError(f"expected {n} workers")


def _is_worker(pid: int) -> bool:
    """A worker started as its own interpreter (its command line) or forked (its ``ft:`` name)."""
    if Path(f"/proc/{pid}/comm").read_text().startswith("ft:"):
        return True
    return "flowtact.runtime.worker" in Path(f"/proc/{pid}/cmdline").read_text()


def worker_of(kids: list[int], process: str) -> int:
    """The pid of the worker running process group ``process`` (by its name when forked)."""
    for k in kids:
        if Path(f"/proc/{k}/comm").read_text().strip() == comm_name(process):
            return k
        if process in Path(f"/proc/{k}/cmdline").read_bytes().decode().split("\0"):
            return k
    raise LookupError(f"no worker runs process group {process!r}")


def wait_recorded(path: Path, stream: str, n: int, timeout: float = 90.0) -> None:
    """Wait until a run's committed recording holds ``n`` samples of ``stream`` (it flushes each second)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if path.exists():
            try:
                got = len(read_recording(path).streams[stream].t)
            except (OSError, KeyError):
                got = 0
            if got >= n:
                return
        time.sleep(0.2)
    raise AssertionError(f"{path} never held {n} samples of {stream}")


def wait_for_line(path: Path, text: str, timeout: float = 90.0) -> str:
    """Wait until the text file ``path`` has a line containing ``text``; that line."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if path.exists():
            for line in path.read_text().splitlines():
                if text in line:
                    return line
        time.sleep(0.05)
    raise AssertionError(f"{path} never had a line with {text!r}")
