"""One run of a sweep = one row: a picklable task and the function a worker process calls on it.

The run is a ``--fast`` in-process run of the graph (no worker processes of its own) whose recorded
streams stay in memory for the metrics; only the row (scalars) travels back. Whatever goes wrong —
a bad parameter value, a block raising, a metric failing — becomes a row with status ``failed``
and a one-line error, never an exception out of :func:`run_task`.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import time
from collections import defaultdict
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from flowtact.chunk import Chunk, concat
from flowtact.sweeps.metrics import MetricSpec, compute_metrics

__all__ = ["MemorySink", "RunTask", "failed_row", "one_line", "run_task"]


@dataclass(frozen=True)
class RunTask:
    """Everything a worker needs for one row (graph text, not a path: workers may be elsewhere)."""

    index: int
    key: str
    seed: int
    source: str
    text: str
    overrides: tuple[str, ...] = ()
    replays: dict[str, str] = field(default_factory=dict)
    duration_s: float | None = None
    metrics: MetricSpec = field(default_factory=MetricSpec)
    allow_modules: tuple[str, ...] = ()
    """The user's ``--allow-module``: the modules whose ``module:Class`` blocks the row may import."""


class MemorySink:
    """Collects a run's recorded streams in memory (the executor's recorder interface)."""

    def __init__(self, plan: Any) -> None:
        self.specs = {f"{n}.{p}": plan.specs[(n, p)] for n, p in plan.record}
        self.chunks: dict[str, list[Chunk]] = defaultdict(list)

    def write(self, stream: str, chunk: Chunk) -> None:
        self.chunks[stream].append(Chunk(np.array(chunk.t), np.array(chunk.data), chunk.end))

    def maybe_flush(self) -> None:
        """Nothing to flush: everything stays in memory."""

    def streams(self) -> dict[str, Any]:
        """Each recorded stream as a :class:`flowtact.recording.hdf5.RecordedStream`, as read back from a file."""
        from flowtact.recording.hdf5 import RecordedStream

        out = {}
        for name, spec in self.specs.items():
            c = concat(self.chunks.get(name, []), spec)
            attrs = {"end_s": c.end} if c.end is not None else {}
            out[name] = RecordedStream(c.t, c.data, spec, attrs)
        return out


def one_line(e: BaseException) -> str:
    """An exception as one line: its first line, with the type when the message does not say it."""
    from flowtact.errors import FlowtactError

    text = str(e).strip().splitlines()[0] if str(e).strip() else ""
    known = isinstance(e, (FlowtactError, ValueError, OSError, KeyError, TypeError))
    return text if known and text else f"{type(e).__name__}: {text}" if text else type(e).__name__


def failed_row(task: RunTask, error: str) -> dict[str, Any]:
    """The row of a run that did not finish."""
    return {"key": task.key, "seed": task.seed, "status": "failed", "error": error}


@functools.cache
def _versions_text() -> str:
    from flowtact.running.launch import versions

    return json.dumps(versions(), sort_keys=True)


def provenance_hash(plan: Any) -> str:
    """SHA-256 (16 hex digits) of what makes a run what it is: the resolved graph (every parameter,
    every node's seed) and the package versions."""
    from flowtact.running.launch import resolved_graph

    doc = json.dumps(resolved_graph(plan), sort_keys=True, default=str) + _versions_text()
    return hashlib.sha256(doc.encode()).hexdigest()[:16]


def _plan(task: RunTask) -> Any:
    from flowtact.graphfile.graph import load_graph
    from flowtact.running.compile import compile_graph

    graph = load_graph(task.source, text=task.text, overrides=task.overrides, replays=task.replays,
                       allow_modules=task.allow_modules)  # fmt: skip
    return compile_graph(dataclasses.replace(graph, seed=task.seed))


def run_task(task: RunTask) -> dict[str, Any]:
    """Run one row; return its row: key, seed, status, error, provenance, duration, metrics, run_s."""
    from flowtact.running.launch import run_compiled

    t0 = time.perf_counter()
    row: dict[str, Any] = {"key": task.key, "seed": task.seed}
    try:
        plan = _plan(task)
        row["provenance"] = provenance_hash(plan)
        sink = MemorySink(plan)
        summary = run_compiled(plan, duration_s=task.duration_s, fast=True, inproc=True, sink=sink)
        if summary.stopped_by == "interrupted":  # Ctrl-C reached this run: it did not finish
            raise KeyboardInterrupt
        row["duration_s"] = summary.duration_s
        row["notes"] = "; ".join(summary.notes)
        row.update(compute_metrics(task.metrics, sink.streams(), summary))
        row["status"], row["error"] = "ok", ""
    except Exception as e:  # noqa: BLE001 - a failing run is a row saying why, not a dead sweep
        row["status"], row["error"] = "failed", one_line(e)
    row["run_s"] = time.perf_counter() - t0
    return row
