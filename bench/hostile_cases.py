"""Hostile inputs too large to keep in the corpus, generated on demand, and a child that measures itself.

Each case writes its file(s) into a folder and returns the ``flowtact`` arguments and the
``file:line:col: text`` the refusal must show. :func:`run_measured` runs ``flowtact`` in a child
Python that reports its own peak RSS, under a generous timeout that only catches hangs.
Used by tests/test_hostile_input.py (through tests/hostile.py) and by the ``hostile_input`` suite
(wall time, peak RSS); it lives here so that the suite runs from an installed wheel.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path

TOUCH = str(files("flowtact.graphs") / "touch.yaml")

# the child: run the CLI, then print its own peak resident set size: VmHWM, which starts afresh at
# exec (ru_maxrss would carry the parent's peak across fork + exec, e.g. a 1 GB pytest process)
_CHILD = (
    "import resource, sys\n"
    "resource.setrlimit(resource.RLIMIT_AS, (4 << 30, 4 << 30))  # a backstop: fail, never swap\n"
    "from flowtact.cli import main\n"
    "try:\n"
    "    rc = main(sys.argv[1:])\n"
    "except SystemExit as e:\n"
    "    rc = e.code\n"
    "hwm = next(x for x in open('/proc/self/status') if x.startswith('VmHWM:')).split()[1]\n"
    "print(f'peak_rss_kib={hwm}', file=sys.stderr)\n"
    "sys.exit(rc)\n"
)


@dataclass(frozen=True)
class Measured:
    """What one child run did: exit status, stderr, wall seconds and peak RSS in MiB."""

    returncode: int
    stderr: str
    seconds: float
    peak_mib: float


def run_measured(args: list[str], timeout_s: float = 120.0) -> Measured:
    """``flowtact ARGS`` in a child process; a hang raises ``subprocess.TimeoutExpired``."""
    start = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-c", _CHILD, *args],
        capture_output=True,
        text=True,
        timeout=timeout_s,
        env={**os.environ, "PYTHONFAULTHANDLER": "1"},
    )
    seconds = time.perf_counter() - start
    m = re.search(r"peak_rss_kib=(\d+)", proc.stderr)
    peak = int(m.group(1)) / 1024 if m else float("nan")
    return Measured(proc.returncode, proc.stderr, seconds, peak)


def _write(folder: Path, name: str, text: str | bytes) -> str:
    path = folder / name
    path.write_bytes(text.encode() if isinstance(text, str) else text)
    return str(path)


def big_file(folder: Path) -> tuple[list[str], str]:
    path = folder / "big.yaml"
    with open(path, "wb") as f:
        f.truncate(50 << 20)  # 50 MB (sparse): only the size matters
    return ["validate", str(path)], f"{path}:1:1: graph file larger than 1 MiB"


def big_file_grown_text(folder: Path) -> tuple[list[str], str]:
    line = b"# " + b"x" * 1000 + b"\n"
    path = _write(folder, "comments.yaml", line * (60 << 10))  # 60 MB of comments
    return ["validate", path], f"{path}:1:1: graph file larger than 1 MiB"


def alias_bomb(folder: Path) -> tuple[list[str], str]:
    lines = ['a0: &a0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    for i in range(1, 10):
        lines.append(f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 9)}]")
    path = _write(folder, "laughs.yaml", "\n".join(lines) + "\nnodes: {}\n")
    return ["validate", path], "the document expands to more than 50000 values"


def deep_lists(folder: Path) -> tuple[list[str], str]:
    path = _write(folder, "deep_lists.yaml", "nodes: " + "[" * 5000 + "]" * 5000 + "\n")
    return ["validate", path], f"{path}:1:71: nested more than 64 levels deep"


def deep_mappings(folder: Path) -> tuple[list[str], str]:
    path = _write(folder, "deep_maps.yaml", "nodes: " + "{a: " * 3000 + "1" + "}" * 3000 + "\n")
    return ["validate", path], f"{path}:1:"  # the column of the 65th '{'


def wide_list(folder: Path) -> tuple[list[str], str]:
    # just under the size limit: half a million values, refused by the node count, not by memory
    path = _write(folder, "wide.yaml", "nodes: [" + "0," * ((1 << 19) - 16) + "0]\n")
    return ["validate", path], "the document expands to more than 50000 values"


def dev_zero(folder: Path) -> tuple[list[str], str]:  # noqa: ARG001 - every case takes the folder
    return ["validate", "/dev/zero"], "/dev/zero:1:1: not a regular file"


def fifo(folder: Path) -> tuple[list[str], str]:
    path = folder / "graph.fifo"
    os.mkfifo(path)  # nobody ever writes: opening it for reading would block forever
    return ["validate", str(path)], f"{path}:1:1: not a regular file"


def huge_population(folder: Path) -> tuple[list[str], str]:  # noqa: ARG001
    return [
        "validate",
        TOUCH,
        "--set",
        "sa1.n=99999999999999",
    ], "--set:1:1: sa1 (nlif): 'n' must be small enough"


def huge_window(folder: Path) -> tuple[list[str], str]:  # noqa: ARG001
    return [
        "validate",
        TOUCH,
        "--set",
        "dforce.window=1000001",
    ], "--set:1:1: dforce (savgol): 'window' must be <= 10001"


def alias_bomb_in_set(folder: Path) -> tuple[list[str], str]:  # noqa: ARG001
    value = "[" + ", ".join(["&a [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]"] + ["*a"] * 20000) + "]"
    return ["validate", TOUCH, "--set", f"sa1.tau_s={value}"], "--set:1:1: --set 'sa1.tau_s="


CASES: dict[str, Callable[[Path], tuple[list[str], str]]] = {
    f.__name__: f
    for f in (
        big_file,
        big_file_grown_text,
        alias_bomb,
        deep_lists,
        deep_mappings,
        wide_list,
        dev_zero,
        fifo,
        huge_population,
        huge_window,
        alias_bomb_in_set,
    )
}
"""Every hostile case by name: folder -> (flowtact arguments, text the refusal must show)."""
