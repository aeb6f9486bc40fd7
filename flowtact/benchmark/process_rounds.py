"""Measuring a suite's figures in several fresh processes, so a reported spread covers what changes
from one process to the next (memory layout, compiled code, which core and neighbour) and a second
run's ratios land inside it.

The runner starts ``parts - 1`` children, one after another (never side by side: they would time
each other), each running the whole suite with its share of every figure's repeats and writing the
raw samples of every figure. The last part runs in the runner's own process with those samples as
``prior``: every figure it records merges them, so medians, ranges, ratios, checks, tables and
plots all see every process. A child that fails costs its samples, never the suite: the report
says how many processes measured each figure.
"""

from __future__ import annotations

import json
import os
import subprocess
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any

from flowtact.running.python_child import python_command
from flowtact.runtime.rundir import make_run_folder

__all__ = ["STEP_MARK", "Prior", "measure_children", "share"]

STEP_MARK = "\x1eflowtact-bench-step "
"""Prefix of a child's progress lines on its stdout (a suite's own prints pass unremarked)."""

Prior = dict[str, dict[str, Any]]
"""Figure key -> ``{"samples", "seconds", "pairs", "processes"}`` measured by earlier processes."""


def share(total: int, part: int, parts: int) -> int:
    """Repeats of part ``part`` (0-based) of ``parts`` when ``total`` are split between them (>= 1)."""
    return max(1, total // parts + (1 if part < total % parts else 0))


def measure_children(
    name: str, quick: bool, peers: bool, parts: int, on_step: Callable[[str], None]
) -> tuple[Prior, list[str]]:
    """Run parts ``0 .. parts - 2`` of suite ``name`` (a registered name, or ``module:attribute``)
    in child processes; their merged samples and a line for each child that failed."""
    prior: Prior = {}
    failures: list[str] = []
    for part in range(parts - 1):
        with make_run_folder("bench") as folder:  # swept by a later start if this process is killed
            out = Path(folder.path) / "figures.json"
            cmd = python_command("-m", "flowtact.benchmark.round_child", name, "--part", str(part), "--parts", str(parts), "--out",
                                 str(out), *(["--quick"] if quick else []), *(["--peers"] if peers else []))  # fmt: skip
            tail = _run_child(cmd, lambda text, p=part: on_step(f"process {p + 1}/{parts}: {text}"))
            if tail is not None or not out.exists():
                last = tail[-1] if tail else "no figures written"
                failures.append(f"process {part + 1} of {parts} failed ({last}); its samples are missing")
                continue
            _merge(prior, json.loads(out.read_text()))
    return prior, failures


def _run_child(cmd: list[str], on_step: Callable[[str], None]) -> list[str] | None:
    """Run a child, forwarding its progress; None when it succeeded, else its last output lines."""
    tail: deque[str] = deque(maxlen=20)
    with subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    ) as proc:  # fmt: skip
        assert proc.stdout is not None
        for line in proc.stdout:
            if line.startswith(STEP_MARK):
                on_step(line[len(STEP_MARK) :].rstrip("\n"))
            elif line.strip():
                tail.append(line.rstrip("\n"))
        status = proc.wait()
    return None if status == 0 else list(tail)


def _merge(prior: Prior, figures: dict[str, dict[str, Any]]) -> None:
    for key, f in figures.items():
        p = prior.setdefault(key, {"samples": [], "seconds": [], "pairs": [], "processes": 0})
        p["samples"] += f["samples"]
        p["seconds"] += f.get("seconds") or []
        p["pairs"] += f.get("pairs") or []
        p["processes"] += 1
