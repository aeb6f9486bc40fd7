"""``flowtact.sweep(...)``: one graph over a grid of parameters and a set of recordings, as a table.

Each row is an in-process ``--fast`` run on an executor (a local process pool by default, Dask, or
any ``concurrent.futures.Executor``), seeded from the graph's seed and the row's key; a failing
run is a row with its error; an existing ``out`` table is resumed (its ``ok`` rows are kept).
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
from collections.abc import Iterator, Mapping, Sequence
from concurrent.futures import Executor
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from flowtact.sweeps.grid import Axis, Row, SweepSpecError, expand_replays, parse_grid, read_table, rows
from flowtact.sweeps.metrics import MetricSpec, parse_metrics
from flowtact.sweeps.progress import SweepProgress
from flowtact.sweeps.runs import RunTask
from flowtact.sweeps.schedule import drive
from flowtact.sweeps.seeds import row_seed

__all__ = ["need_extras", "sweep"]

WRITE_EVERY_S = 1.0


def need_extras() -> None:
    """Raise :class:`SweepSpecError` naming the extra to install when pandas or pyarrow is missing."""
    from flowtact.extras import install_hint, module_available

    missing = [m for m in ("pandas", "pyarrow") if not module_available(m)]
    if missing:
        _, how = install_hint("flowtact", missing[0], "sweep")
        raise SweepSpecError(f"flowtact sweep needs {', '.join(missing)}: {how}")


def _graph_text(graph: str | Path) -> tuple[str, str]:
    """(source name, YAML text) of a graph file, a shipped graph's name, or a recording's graph."""
    path = Path(graph)
    if path.suffix in (".h5", ".hdf5"):
        from flowtact.record import read_recording

        return f"{path}#graph", read_recording(path, streams=()).provenance["graph_yaml"]
    from flowtact.graph import resolve_graph_path
    from flowtact.safe_yaml import SafeYamlError, read_graph_text

    source = resolve_graph_path(graph)
    try:
        return str(source), read_graph_text(source)
    except SafeYamlError:
        return str(source), ""  # load_graph reports it with its place
    except OSError as e:
        raise SweepSpecError(f"{source}: cannot read graph file: {e.strerror or e}") from None


def _axes(grid: Mapping[str, Sequence[Any]] | Sequence[str] | None) -> list[Axis]:
    if grid is None:
        return []
    if isinstance(grid, Mapping):
        out = []
        for name, values in grid.items():
            node, dot, param = str(name).partition(".")
            vals = tuple(values) if isinstance(values, (list, tuple)) else (values,)
            if not dot or not node or not param or not vals:
                raise SweepSpecError(f"grid: '{name}' must be node.param with a list of values")
            out.append(Axis(f"{node}.{param}", vals))
        return out
    return parse_grid([grid] if isinstance(grid, str) else grid)


def _table(table: Any) -> list[dict[str, Any]]:
    if table is None:
        return []
    if isinstance(table, (str, Path)):
        return read_table(table)
    if hasattr(table, "to_dict"):  # a DataFrame
        return [dict(r) for r in table.to_dict(orient="records")]
    return [dict(r) for r in table]


def _check(source: str, text: str, overrides: Sequence[str], first: Row, names: set[str],
           metrics: MetricSpec, duration_s: float | None, allow_modules: Sequence[str]) -> Any:  # fmt: skip
    """Load the graph as the first row would run it (without the swept values): graph problems
    raise GraphErrors (exit 2); unknown swept nodes or parameters, unrecorded RMSE streams too."""
    from flowtact.compile import compile_graph
    from flowtact.graph import load_graph
    from flowtact.source_ends import default_duration

    graph = load_graph(source, text=text, overrides=overrides, replays=_abs(first.recordings),
                       allow_modules=allow_modules)  # fmt: skip
    for name in sorted(names):
        node, _, param = name.partition(".")
        nd = graph.nodes.get(node)
        if nd is None:
            raise SweepSpecError(f"{name}: the graph has no node '{node}' (nodes: {', '.join(graph.nodes)})")
        fields = {f.name for f in dataclasses.fields(nd.config)} | {"preset"}
        if param not in fields:
            raise SweepSpecError(f"{name}: block {nd.block} has no parameter '{param}' "
                                 f"(parameters: {', '.join(sorted(fields))})")  # fmt: skip
    plan = compile_graph(graph)
    if default_duration(plan, duration_s) is None:
        raise SweepSpecError(f"{source}: the graph has no duration_s and replays no file: give --duration")
    recorded = {f"{n}.{p}" for n, p in plan.record}
    for est, ref in metrics.rmse_pairs:
        for s in (est, ref):
            if s not in recorded:
                raise SweepSpecError(f"--rmse {est}={ref}: '{s}' is not a recorded stream of the graph "
                                     f"(recorded: {', '.join(sorted(recorded))})")  # fmt: skip
    return graph


def _abs(recordings: Mapping[str, str]) -> dict[str, str]:
    """Replayed files as absolute names: workers may run in another folder."""
    from flowtact.replay_spec import split_replay

    out = {}
    for node, text in recordings.items():
        path, port_map = split_replay(text)
        out[node] = f"{os.path.abspath(path)}:{port_map}" if port_map else os.path.abspath(path)
    return out


@contextmanager
def _executor(
    executor: Executor | str, workers: int | None, scheduler: str | None, preload: Sequence[str] = ()
) -> Iterator[dict[str, Any]]:
    """Keyword arguments for :func:`drive`, and the worker count, for an executor choice."""
    if isinstance(executor, Executor):
        yield {"executor": executor, "n": workers or os.cpu_count() or 1}
    elif executor == "local":
        from flowtact.sweeps.executors import local_pool_factory

        yield {"make_executor": local_pool_factory(workers, preload), "n": workers or os.cpu_count() or 1}
    elif executor == "dask":
        from flowtact.sweeps.executors import dask_executor

        with dask_executor(scheduler, workers) as (ex, n):
            yield {"executor": ex, "n": n}
    else:
        raise SweepSpecError(f"executor '{executor}': expected local, dask or a concurrent.futures.Executor")


def sweep(
    graph: str | Path,
    *,
    grid: Mapping[str, Sequence[Any]] | Sequence[str] | None = None,
    table: str | Path | Sequence[Mapping[str, Any]] | Any = None,
    replay: Mapping[str, str] | None = None,
    overrides: Sequence[str] = (),
    metrics: Sequence[str] | str | None = None,
    rmse: Sequence[str] = (),
    executor: Executor | str = "local",
    workers: int | None = None,
    scheduler: str | None = None,
    out: str | Path | None = None,
    duration_s: float | None = None,
    progress: bool | SweepProgress = False,
    allow_modules: Sequence[str] = (),
) -> Any:
    """Run ``graph`` once per row and return the table (a pandas DataFrame, one row per run).

    ``grid``: ``{"sa1.tau_s": [0.005, 0.01]}`` or ``["sa1.tau_s=0.005,0.01"]`` (a Cartesian
    product); ``table``: rows of ``node.param`` values (a .yaml/.csv file, dicts or a DataFrame);
    ``replay``: ``{node: "GLOB[:MAP]"}``, one run per matching recording; ``overrides``: fixed
    ``--set`` strings. ``metrics``: built-ins (``spikes``, ``rmse``, ``runtime``) and
    ``module:function`` (see :mod:`flowtact.sweeps.metrics`); ``rmse``: ``STREAM=REFERENCE`` pairs.
    ``executor``: ``"local"`` (processes), ``"dask"`` (``scheduler`` address, else a LocalCluster
    of ``workers``) or any ``concurrent.futures.Executor``. ``out``: a Parquet file, written as
    rows finish and resumed when it exists. ``df.attrs["executed"]`` is the number of runs made.
    ``allow_modules``: the modules whose ``module:Class`` blocks the graph may import (``--allow-module``).
    """
    need_extras()
    source, text = _graph_text(graph)
    axes, trows = _axes(grid), _table(table)
    recordings = expand_replays(replay or {})
    spec = parse_metrics(metrics, rmse)
    all_rows = rows(axes, trows, recordings)
    names = {a.name for a in axes} | {k for r in trows for k in r}
    base = _check(source, text, overrides, all_rows[0], names, spec, duration_s, tuple(allow_modules))
    first_cols = [
        *dict.fromkeys(k for r in all_rows for k in r.params),
        *(f"recording:{n}" for n in recordings),
    ]

    from flowtact.sweeps.store import done_rows, to_frame, write_table

    previous = done_rows(out) if out is not None else []
    kept = {r["key"]: r for r in previous if r.get("status") == "ok"}
    tasks = [
        RunTask(
            index=i,
            key=r.key,
            seed=row_seed(base.seed, r.key),
            source=source,
            text=text,
            overrides=(*overrides, *r.overrides()),
            replays=_abs(r.recordings),
            duration_s=duration_s,
            metrics=spec,
            allow_modules=base.allow_modules,
        )
        for i, r in enumerate(all_rows)
        if r.key not in kept
    ]
    by_key = {r.key: r for r in all_rows}
    results: dict[str, dict[str, Any]] = {}
    bar = (
        progress if isinstance(progress, SweepProgress) else SweepProgress(len(tasks), enabled=bool(progress))
    )
    last_write = [time.monotonic()]

    def table_now() -> Any:
        order = {r.key: i for i, r in enumerate(all_rows)}
        merged = {r["key"]: r for r in previous}  # kept ok rows, older failures, rows of other grids
        merged.update(results)
        return to_frame(sorted(merged.values(), key=lambda r: order.get(r["key"], math.inf)), first_cols)

    def on_row(task: RunTask, result: dict[str, Any]) -> None:
        row = by_key[task.key]
        results[task.key] = {**row.params, **{f"recording:{n}": p for n, p in row.recordings.items()},
                             "graph": base.name, **result}  # fmt: skip
        bar.row(result.get("status") == "ok")
        if out is not None and time.monotonic() - last_write[0] >= WRITE_EVERY_S:
            write_table(table_now(), out)
            last_write[0] = time.monotonic()

    try:
        blocks = sorted({nd.cls.__module__ for nd in base.nodes.values()})
        with _executor(executor, workers, scheduler, blocks) as ex, bar:
            n = ex.pop("n")
            drive(tasks, on_row, in_flight=2 * n, **ex)
    finally:
        df = table_now()
        if out is not None and (results or not Path(out).exists()):
            write_table(df, out)
    df.attrs["executed"] = len(results)
    df.attrs["kept"] = len(kept)
    return df
