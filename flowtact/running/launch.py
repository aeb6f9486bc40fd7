"""Load, compile and run a graph: the one path shared by the CLI and by ``flowtact.testing``.

Also builds the provenance bundle a recording carries (resolved graph, every parameter, every
node's seed, versions), from which ``flowtact run out.h5`` re-creates the run exactly.
"""

from __future__ import annotations

import datetime as _dt
import json
import sys
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

import yaml

from flowtact.errors import UsageError
from flowtact.graphfile.deployment import DEFAULT_QUEUE, STOP_GRACE_S
from flowtact.graphfile.graph import load_graph, resolve_graph_path
from flowtact.inputs.limits import run_ticks_problem
from flowtact.running.compile import CompiledGraph, compile_graph
from flowtact.running.source_ends import EndWatch, default_duration
from flowtact.runtime.clock import DEFAULT_TICK_REALTIME_S, tick_for
from flowtact.runtime.executors import DEFAULT_EXECUTOR, Executor, RunOptions, executor_for
from flowtact.runtime.summary import RunSummary
from flowtact.version import __version__

__all__ = ["load_compiled", "provenance", "resolved_graph", "run_compiled", "versions"]


def load_compiled(
    source: str | Path,
    *,
    overrides: Iterable[str] = (),
    replays: Mapping[str, str] | None = None,
    allow_modules: Iterable[str] = (),
) -> CompiledGraph:
    """Load and compile a graph file, or the graph stored in a recording (``.h5``).

    ``allow_modules`` (``--allow-module``) are the modules whose ``module:Class`` blocks may be
    imported (:func:`flowtact.graphfile.graph.load_graph`); a recording's stored graph never widens them."""
    path = Path(source)
    if path.suffix in (".h5", ".hdf5"):
        text = _stored_graph(path)
        graph = load_graph(
            f"{path}#graph", text=text, overrides=overrides, replays=replays, allow_modules=allow_modules
        )
    else:
        graph = load_graph(
            resolve_graph_path(source), overrides=overrides, replays=replays, allow_modules=allow_modules
        )
    return compile_graph(graph)


def _stored_graph(path: Path) -> str:
    """The resolved graph a recording stores; a file refused as input (not a regular file, not a
    recording, beyond the reader's bounds, no stored graph) is a located graph error (exit 2)."""
    from flowtact.errors import GraphFileError, NotARecording, RecordingRefused
    from flowtact.graphfile.located import GraphProblem, Loc
    from flowtact.graphfile.safe_yaml import MAX_GRAPH_BYTES
    from flowtact.inputs.safe_text import shown
    from flowtact.recording.hdf5 import read_recording

    where = shown(path)
    try:
        text = read_recording(path, streams=()).provenance.get("graph_yaml")
    except (RecordingRefused, NotARecording) as e:
        msg = str(e)
        raise GraphFileError([GraphProblem(Loc(where), msg.removeprefix(f"{where}: "))]) from None
    if not isinstance(text, str):
        raise GraphFileError(
            [GraphProblem(Loc(where), "the recording stores no graph (no 'graph_yaml' text)")]
        )
    if len(text.encode("utf-8", "surrogatepass")) > MAX_GRAPH_BYTES:
        raise GraphFileError(
            [GraphProblem(Loc(where), f"stored graph larger than {MAX_GRAPH_BYTES >> 20} MiB")]
        )
    return text


def resolved_graph(plan: CompiledGraph) -> dict[str, Any]:
    """The graph with every parameter (defaults included) and every node's seed written out."""
    g = plan.graph
    doc: dict[str, Any] = {"name": g.name, "seed": g.seed}
    if g.description:
        doc["description"] = g.description
    if g.duration_s is not None:
        doc["duration_s"] = g.duration_s
    if g.tick_s is not None:
        doc["tick_s"] = g.tick_s
    nodes = {}
    for name, node in g.nodes.items():
        entry: dict[str, Any] = {
            "block": node.block,
            "params": node.config.to_dict(),
            "seed": plan.seeds[name],
        }
        if node.process:
            entry["process"] = node.process
        nodes[name] = entry
    doc["nodes"] = nodes
    doc["edges"] = [
        str(e)
        if (e.policy, e.queue) == ("block", DEFAULT_QUEUE)
        else {
            "from": f"{e.src}.{e.src_port}",
            "to": f"{e.dst}.{e.dst_port}",
            "policy": e.policy,
            "queue": e.queue,
        }
        for e in g.edges
    ]
    doc["record"] = [f"{n}.{p}" for n, p in plan.record]
    dep = g.deployment
    if dep.processes:
        doc["processes"] = {
            name: {
                "restart": p.restart,
                "max_restarts": p.max_restarts,
                **({"host": p.host} if p.host else {}),
                **{k: getattr(p, k) for k in ("stall_s", "startup_s") if getattr(p, k) is not None},
                **({"stop_grace_s": p.stop_grace_s} if p.stop_grace_s != STOP_GRACE_S else {}),
            }
            for name, p in dep.processes.items()
        }
    if dep.remote:
        net = dep.network
        doc["network"] = {"listen": net.listen, "port": net.port, **({"keys": net.keys} if net.keys else {})}
    if dep.deadlines:
        doc["deadlines"] = [{"from": d.src, "to": d.dst, "budget": d.budget_s} for d in dep.deadlines]
    return doc


def versions() -> dict[str, str]:
    """Python, flowtact, HDF5 and dependency versions (:func:`flowtact.recording.hdf5.package_versions`)."""
    from flowtact.recording.hdf5 import package_versions

    return {**package_versions(), "flowtact": __version__}


def provenance(plan: CompiledGraph, argv: list[str] | None = None) -> dict[str, Any]:
    """Everything needed to re-create a run exactly."""
    resolved = resolved_graph(plan)
    return {
        "flowtact_version": __version__,
        "graph_name": plan.graph.name,
        "graph_path": plan.graph.path,
        "graph_yaml": yaml.safe_dump(resolved, sort_keys=False),
        "graph_source": plan.graph.text,
        "overrides": json.dumps(plan.graph.overrides),
        "graph_seed": plan.graph.seed,
        "params": json.dumps({n: node.config.to_dict() for n, node in plan.graph.nodes.items()}),
        "seeds": json.dumps(plan.seeds),
        "pruned": json.dumps(plan.pruned),
        "versions": json.dumps(versions()),
        "command": " ".join(argv if argv is not None else sys.argv),
        "created_utc": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
    }


def has_feedback(plan: CompiledGraph) -> bool:
    """Whether the graph closes a loop (an edge into a delayed input): then the tick shapes its
    dynamics, so a ``--fast`` run keeps the real-time tick to behave as the live graph does."""
    g = plan.graph
    return any(g.nodes[e.dst].cls.inputs[e.dst_port].delay for e in g.edges)


def check_run_length(plan: CompiledGraph, duration_s: float | None, tick_s: float | None, fast: bool) -> None:
    """Refuse, before anything starts, a run of more than :data:`~flowtact.inputs.limits.MAX_RUN_TICKS`
    ticks: :class:`~flowtact.errors.UsageError` naming where the duration and the tick came from."""
    duration = default_duration(plan, duration_s)
    tick = tick_for(
        fast, tick_s or plan.graph.tick_s or (DEFAULT_TICK_REALTIME_S if has_feedback(plan) else None)
    )
    problem = run_ticks_problem(duration, tick)
    if problem is None:
        return
    if duration_s is not None:
        said = "--duration"
    else:
        said = "the graph's duration_s" if duration == plan.graph.duration_s else "the replayed files' end"
    if tick_s is not None:
        said += " and --tick"
    elif plan.graph.tick_s is not None:
        said += " and the graph's tick_s"
    else:
        said += f" and the default tick ({'--fast' if fast else 'real time'})"
    raise UsageError(f"{said}: {problem}")


def run_compiled(
    plan: CompiledGraph,
    *,
    duration_s: float | None = None,
    fast: bool = True,
    inproc: bool = False,
    record: str | Path | None = None,
    tick_s: float | None = None,
    progress: Callable[[float, float | None], None] | None = None,
    live: Any = None,
    warn: Callable[[str], None] | None = None,
    argv: list[str] | None = None,
    sink: Any = None,
    startup_s: float | None = None,
    executor: str | None = None,
    launched_at: float | None = None,
    view: Any = None,
) -> RunSummary:
    """Run a compiled plan across processes (or, with ``inproc``, in this one), recording its
    ``record:`` streams to ``record``. A failing worker raises
    :class:`~flowtact.errors.WorkerFailed` after the recording is closed. Without
    ``record``, an ``inproc`` run may hand its recorded streams to ``sink`` in memory (sweeps).
    ``startup_s`` (``--startup-s``) replaces every process group's start-up window. ``executor``
    names the executor (:data:`~flowtact.runtime.executors.EXECUTORS`); ``inproc`` is short for
    ``executor="inproc"``. A multi-process run counts its start-up from ``launched_at``
    (monotonic) when given. ``view`` (a :class:`flowtact.view.session.ViewSession`) is handed
    its streams by a tee in the recorder's place; the file records only the graph's own."""
    duration = default_duration(
        plan, duration_s
    )  # --duration, else the replayed files' end, else the graph's
    check_run_length(plan, duration_s, tick_s, fast)
    tick_s = tick_s or plan.graph.tick_s or (DEFAULT_TICK_REALTIME_S if has_feedback(plan) else None)
    ends = EndWatch(plan, duration, warn)
    progress = ends.progress(progress)

    name = executor or ("inproc" if inproc else DEFAULT_EXECUTOR)
    make = executor_for(name)

    run_plan = plan if view is None else view.plan_for(plan)

    def executor_with(recorder: Any) -> Executor:
        if view is not None:
            recorder = view.sink(recorder, [f"{n}.{p}" for n, p in plan.record])
        options = RunOptions(
            fast=fast,
            tick_s=tick_s,
            recorder=recorder,
            progress=progress,
            live=live,
            warn=warn,
            startup_s=startup_s,
            launched_at=launched_at,
        )
        return make.for_run(run_plan, options)

    if record is None:
        summary = executor_with(sink).run(duration)
        ends.finish(summary)
        return summary
    from flowtact.recording.hdf5 import Recorder

    streams = {f"{n}.{p}": plan.specs[(n, p)] for n, p in plan.record}
    with Recorder(record, streams, provenance(plan, argv)) as recorder:
        try:
            summary = executor_with(recorder).run(duration)
        except Exception as e:
            partial = getattr(e, "summary", None)
            recorder.close({**(partial.to_dict() if partial else {}), "error": str(e)})
            raise
        ends.finish(summary)
        recorder.close(summary.to_dict())
    return summary
