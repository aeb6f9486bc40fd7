"""``flowtact.run(graph, ...)``: run a graph from Python (a script, a notebook) and get its streams back.

The same path as ``flowtact run`` (:func:`flowtact.running.launch.run_compiled`): the graph is
loaded and compiled by the file loader, run in this process (default) or in worker processes
(``processes=True``, one per process group, as ``flowtact run`` does), and its ``record:``
streams are recorded to HDF5 (a temporary file unless ``record=`` names one) and read back, so a
run from Python and one from the shell give the same arrays. Nothing here exits the interpreter
or keeps a signal handler: a bad graph raises :class:`~flowtact.errors.GraphFileError`, a failed
run :class:`~flowtact.errors.WorkerFailed`; Ctrl-C (a notebook's interrupt) stops the run cleanly,
as in the shell, and the handlers are put back when it returns.
"""

from __future__ import annotations

import sys
import tempfile
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

import yaml

from flowtact.running.builder import GraphBuilder
from flowtact.running.results import RunResult, streams_of

__all__ = ["GraphSource", "compile_source", "override_texts", "run"]

GraphSource = str | Path | GraphBuilder | Mapping[str, Any]
"""A graph file's path, a shipped graph's name (``"touch"``), a recording (``.h5``: the graph it
was made with), a :class:`~flowtact.running.builder.GraphBuilder`, or a graph file's document as
a mapping."""


def override_texts(values: Mapping[str, Any] | Iterable[str]) -> list[str]:
    """``{"sa1.n": 200}`` (or ``["sa1.n=200"]``) as ``--set`` texts, each value written as YAML."""
    if isinstance(values, Mapping):
        return [
            f"{k}={yaml.safe_dump([v], default_flow_style=True, width=2**31).strip()[1:-1]}"
            for k, v in values.items()
        ]
    if isinstance(values, str):
        return [values]
    return list(values)


def compile_source(
    graph: GraphSource,
    *,
    overrides: Mapping[str, Any] | Iterable[str] = (),
    replay: Mapping[str, str] | None = None,
    allow_modules: Iterable[str] = (),
) -> Any:
    """The compiled plan of ``graph`` (:class:`~flowtact.running.compile.CompiledGraph`), with
    ``overrides`` (``{"node.param": value}``, as ``--set``) and ``replay`` (``{node: FILE}``,
    as ``--replay``) applied."""
    from flowtact.running.compile import compile_graph
    from flowtact.running.launch import load_compiled

    texts = override_texts(overrides)
    allow = tuple(allow_modules)
    if isinstance(graph, Mapping):
        builder = GraphBuilder()
        builder.doc = dict(graph)
        graph = builder
    if isinstance(graph, GraphBuilder):
        return compile_graph(graph.load(overrides=texts, replays=replay, allow_modules=allow))
    return load_compiled(graph, overrides=texts, replays=replay, allow_modules=allow)


def run(
    graph: GraphSource,
    *,
    duration_s: float | None = None,
    fast: bool = True,
    processes: bool = False,
    record: str | Path | None = None,
    overrides: Mapping[str, Any] | Iterable[str] = (),
    replay: Mapping[str, str] | None = None,
    tick_s: float | None = None,
    allow_modules: Iterable[str] = (),
    warn: Callable[[str], None] | None = None,
) -> RunResult:
    """Run ``graph`` and return its recorded streams as arrays (:class:`~flowtact.running.results.RunResult`).

    ``duration_s``: graph seconds (default: the graph's ``duration_s``, or the end of the replayed
    files). ``fast``: as fast as possible on the virtual clock (default), else in real time.
    ``processes``: one worker process per process group, joined by ZeroMQ (``flowtact run``);
    default all in this process (``--inproc``); in ``fast`` mode both give identical recordings.
    ``record``: also keep the HDF5 recording there. ``overrides``: parameters changed, as ``--set``:
    ``{"sa1.n": 200}``; ``replay``: ``{"sensor": "old.h5"}``. ``warn`` receives each warning the
    run prints (default: written to standard error, and kept in ``result.warnings``).
    """
    from flowtact.recording.hdf5 import read_recording
    from flowtact.running.launch import run_compiled

    plan = compile_source(graph, overrides=overrides, replay=replay, allow_modules=allow_modules)
    warnings: list[str] = []

    def on_warning(message: str) -> None:
        warnings.append(message)
        if warn is not None:
            warn(message)
        else:
            print(f"flowtact: {message}", file=sys.stderr)

    with tempfile.TemporaryDirectory(prefix="flowtact-run-") as scratch:
        path = Path(record) if record is not None else Path(scratch) / "run.h5"
        summary = run_compiled(
            plan,
            duration_s=duration_s,
            fast=fast,
            inproc=not processes,
            record=path,
            tick_s=tick_s,
            warn=on_warning,
            argv=["flowtact.run", plan.graph.path],
        )
        streams = streams_of(read_recording(path))
    return RunResult(streams, summary, Path(record) if record is not None else None, warnings)
