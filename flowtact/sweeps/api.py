"""``flowtact.sweep(...)``: one graph over a grid of parameters and a set of recordings, as a table.

Each row is an in-process ``--fast`` run on an executor (a local process pool by default, Dask, or
any ``concurrent.futures.Executor``), seeded from the graph's seed and the row's key; a failing
run is a row with its error, and so is a run past its timeout; an existing ``out`` table is
resumed (its ``ok`` rows are kept) only if the same setup made it: the same graph text and fixed
settings (:func:`setup`), and for each row the same replayed files (by content).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import time
from collections.abc import Iterator, Mapping, Sequence
from concurrent.futures import Executor
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from flowtact.errors import SweepSpecError
from flowtact.inputs.limits import positive_seconds
from flowtact.sweeps.grid import Axis, Row, expand_replays, parse_grid, read_table, rows
from flowtact.sweeps.metrics import MetricSpec, parse_metrics
from flowtact.sweeps.progress import SweepProgress
from flowtact.sweeps.runs import RunTask
from flowtact.sweeps.schedule import drive
from flowtact.sweeps.seeds import row_seed

__all__ = ["DEFAULT_ROW_TIMEOUT_S", "MAX_WORKERS", "ROW_TIMEOUT_PER_GRAPH_S", "need_extras", "setup", "sweep"]

WRITE_EVERY_S = 1.0
"""How often, at most, the table is rewritten while rows finish (and once at the end)."""
DEFAULT_ROW_TIMEOUT_S = 600.0
"""A row's timeout by default: 10 minutes of start-up and slack, plus :data:`ROW_TIMEOUT_PER_GRAPH_S`."""
ROW_TIMEOUT_PER_GRAPH_S = 10.0
"""...plus 10 wall seconds per graph second of the run (a --fast run is rarely slower than real time)."""
MAX_WORKERS = 4096
"""Most worker processes a sweep starts (--workers)."""
SEED_POLICY = "row-seed-1: SeedSequence(graph seed, sha256(row key))"
"""How a row's seed is made (:func:`flowtact.sweeps.seeds.row_seed`); a table made otherwise is not resumed."""


def need_extras() -> None:
    """Raise :class:`SweepSpecError` naming the extra to install when pandas or pyarrow is missing."""
    from flowtact.graphfile.extras import install_hint, module_available

    missing = [m for m in ("pandas", "pyarrow") if not module_available(m)]
    if missing:
        _, how = install_hint("flowtact", missing[0], "sweep")
        raise SweepSpecError(f"flowtact sweep needs {', '.join(missing)}: {how}")


def _graph_text(graph: str | Path) -> tuple[str, str]:
    """(source name, YAML text) of a graph file, a shipped graph's name, or a recording's graph."""
    path = Path(graph)
    if path.suffix in (".h5", ".hdf5"):
        from flowtact.recording.hdf5 import read_recording

        return f"{path}#graph", read_recording(path, streams=()).provenance["graph_yaml"]
    from flowtact.errors import SafeYamlError
    from flowtact.graphfile.graph import resolve_graph_path
    from flowtact.graphfile.safe_yaml import read_graph_text

    source = resolve_graph_path(graph)
    try:
        return str(source), read_graph_text(source)
    except SafeYamlError:
        return str(source), ""  # load_graph reports it with its place
    except OSError as e:
        raise SweepSpecError(f"{source}: cannot read graph file: {e.strerror or e}") from None


def setup(
    text: str, overrides: Sequence[str], duration_s: float | None, metrics: MetricSpec
) -> dict[str, Any]:
    """What makes every row of a sweep what it is besides its own values: the graph text's hash,
    the fixed ``--set`` overrides, ``--duration``, the metrics, flowtact's version and the seed
    policy. Recorded in the table; a table with another setup is not resumed."""
    from flowtact.version import __version__

    return {
        "graph": hashlib.sha256(text.encode()).hexdigest()[:16],
        "set": list(overrides),
        "duration_s": duration_s,
        "metrics": [*metrics.builtins, *metrics.user],
        "rmse": [f"{a}={b}" for a, b in metrics.rmse_pairs],
        "flowtact": __version__,
        "seeds": SEED_POLICY,
    }


def _file_digest(path: str) -> str:
    """SHA-256 of a replayed file's content (streamed), so a row knows the data it played."""
    h = hashlib.sha256()
    try:
        with open(path, "rb") as f:
            while block := f.read(1 << 20):
                h.update(block)
    except OSError as e:
        raise SweepSpecError(f"--replay {path}: cannot read it: {e.strerror or e}") from None
    return h.hexdigest()


def _row_setup(common: str, row: Row, digests: dict[str, str]) -> str:
    """A row's ``setup`` hash: the sweep's setup and the content of each file the row replays
    (``digests`` caches each file's hash for this sweep)."""
    from flowtact.graphfile.replay_spec import split_replay

    files = {}
    for node, text in row.recordings.items():
        path = os.path.abspath(split_replay(text)[0])
        if path not in digests:
            digests[path] = _file_digest(path)
        files[node] = digests[path]
    return hashlib.sha256((common + json.dumps(files, sort_keys=True)).encode()).hexdigest()[:16]


def _refusal(out: str | Path, what: str) -> SweepSpecError:
    return SweepSpecError(f"{out}: made by another setup ({what}); use another --out or --fresh")


def _check_setup(out: str | Path, made: Mapping[str, Any]) -> None:
    """Refuse to resume into a table another setup made (one line naming ``out`` and what differs)."""
    from flowtact.sweeps.store import read_setup, setup_differences

    old = read_setup(out)
    if old is None:
        raise _refusal(out, "it records none: an older flowtact or another tool wrote it")
    if diff := setup_differences(old, made):
        raise _refusal(out, "; ".join(diff))


def _check_rows(
    out: str | Path, previous: Sequence[Mapping[str, Any]], row_setups: Mapping[str, str]
) -> None:
    """Refuse a table whose rows of this sweep were made from other replayed data (or have no setup)."""
    if any("setup" not in r for r in previous):
        raise _refusal(out, "a row records none: an older flowtact or another tool wrote it")
    for r in previous:
        want = row_setups.get(r["key"])
        if want is not None and r["setup"] != want:
            raise _refusal(out, "a row's setup differs: a file it replayed has changed")


def _check_numbers(workers: int | None, duration_s: float | None, row_timeout_s: float | None) -> None:
    """Range-check the sweep's numeric arguments (one line naming the flag)."""
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int)
                                or not 1 <= workers <= MAX_WORKERS):  # fmt: skip
        raise SweepSpecError(f"--workers: expected a whole number from 1 to {MAX_WORKERS}; got {workers!r}")
    if duration_s is not None and positive_seconds(duration_s) is None:
        raise SweepSpecError(f"--duration: must be a finite number of seconds > 0; got {duration_s!r}")
    if row_timeout_s is not None and positive_seconds(row_timeout_s) is None:
        raise SweepSpecError(f"--row-timeout: must be a finite number of seconds > 0; got {row_timeout_s!r}")


def _default_timeout(plan_duration_s: float) -> float:
    return DEFAULT_ROW_TIMEOUT_S + ROW_TIMEOUT_PER_GRAPH_S * plan_duration_s


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
           metrics: MetricSpec, duration_s: float | None,
           allow_modules: Sequence[str]) -> tuple[Any, float]:  # fmt: skip
    """Load the graph as the first row would run it (without the swept values): graph problems
    raise GraphFileError (exit 2); unknown swept nodes or parameters, unrecorded RMSE streams too.
    Returns the graph and the run's graph seconds."""
    from flowtact.graphfile.graph import load_graph
    from flowtact.running.compile import compile_graph
    from flowtact.running.source_ends import default_duration

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
    seconds = default_duration(plan, duration_s)
    if seconds is None:
        raise SweepSpecError(f"{source}: the graph has no duration_s and replays no file: give --duration")
    recorded = {f"{n}.{p}" for n, p in plan.record}
    for est, ref in metrics.rmse_pairs:
        for s in (est, ref):
            if s not in recorded:
                raise SweepSpecError(f"--rmse {est}={ref}: '{s}' is not a recorded stream of the graph "
                                     f"(recorded: {', '.join(sorted(recorded))})")  # fmt: skip
    return graph, float(seconds)


def _abs(recordings: Mapping[str, str]) -> dict[str, str]:
    """Replayed files as absolute names: workers may run in another folder."""
    from flowtact.graphfile.replay_spec import split_replay

    out = {}
    for node, text in recordings.items():
        path, port_map = split_replay(text)
        out[node] = f"{os.path.abspath(path)}:{port_map}" if port_map else os.path.abspath(path)
    return out


@contextmanager
def _executor(
    executor: Executor | str, workers: int | None, scheduler: str | None, preload: Sequence[str] = ()
) -> Iterator[dict[str, Any]]:
    """Keyword arguments for :func:`drive` for an executor choice: the executor (or how to make
    one), how many runs to hand it at once, and when a run's timeout clock starts. Executors that
    do not mark a future running when it starts get no more runs than workers, so a run's clock
    starts (about) when it does."""
    n = workers or os.cpu_count() or 1
    if isinstance(executor, Executor):  # it may not say when a run starts: clock from submission
        yield {"executor": executor, "in_flight": n, "clock": "submitted"}
    elif executor == "local":
        from flowtact.sweeps.executors import local_pool_factory

        yield {"make_executor": local_pool_factory(workers, preload), "in_flight": 2 * n, "clock": "running"}
    elif executor == "dask":
        from flowtact.sweeps.executors import dask_executor

        with dask_executor(scheduler, workers) as (ex, n):
            yield {"executor": ex, "in_flight": n, "clock": "submitted"}
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
    row_timeout_s: float | None = None,
    fresh: bool = False,
) -> Any:
    """Run ``graph`` once per row and return the table (a pandas DataFrame, one row per run).

    ``grid``: ``{"sa1.tau_s": [0.005, 0.01]}`` or ``["sa1.tau_s=0.005,0.01"]`` (a Cartesian
    product); ``table``: rows of ``node.param`` values (a .yaml/.csv file, dicts or a DataFrame);
    ``replay``: ``{node: "GLOB[:MAP]"}``, one run per matching recording; ``overrides``: fixed
    ``--set`` strings. ``metrics``: built-ins (``spikes``, ``rmse``, ``runtime``) and
    ``module:function`` (see :mod:`flowtact.sweeps.metrics`); ``rmse``: ``STREAM=REFERENCE`` pairs.
    ``executor``: ``"local"`` (processes), ``"dask"`` (``scheduler`` address, else a LocalCluster
    of ``workers``) or any ``concurrent.futures.Executor``. ``out``: a Parquet file, checked
    writable before the first run, written as rows finish and resumed when it exists (refused if
    another setup made it; ``fresh=True`` starts it over). ``row_timeout_s``: a run still going
    after this many seconds is a failed row (default :data:`DEFAULT_ROW_TIMEOUT_S` plus
    :data:`ROW_TIMEOUT_PER_GRAPH_S` per graph second). ``df.attrs["executed"]`` is the number of
    runs made. ``allow_modules``: the modules whose ``module:Class`` blocks the graph may import
    (``--allow-module``).
    """
    need_extras()
    _check_numbers(workers, duration_s, row_timeout_s)
    from flowtact.sweeps.store import check_writable, done_rows, to_frame, write_table

    if out is not None:
        check_writable(out)
    source, text = _graph_text(graph)
    axes, trows = _axes(grid), _table(table)
    recordings = expand_replays(replay or {})
    spec = parse_metrics(metrics, rmse)
    all_rows = rows(axes, trows, recordings)
    names = {a.name for a in axes} | {k for r in trows for k in r}
    base, seconds = _check(source, text, overrides, all_rows[0], names, spec, duration_s,
                           tuple(allow_modules))  # fmt: skip
    timeout = row_timeout_s if row_timeout_s is not None else _default_timeout(seconds)
    made = setup(text, overrides, duration_s, spec)
    common = json.dumps(made, sort_keys=True)
    digests: dict[str, str] = {}
    row_setups = {r.key: _row_setup(common, r, digests) for r in all_rows}
    first_cols = [
        *dict.fromkeys(k for r in all_rows for k in r.params),
        *(f"recording:{n}" for n in recordings),
    ]

    previous = []
    if out is not None and not fresh and Path(out).exists():
        _check_setup(out, made)  # from the footer, before reading any row
        previous = done_rows(out)
        _check_rows(out, previous, row_setups)
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
                             "graph": base.name, **result, "setup": row_setups[task.key]}  # fmt: skip
        bar.row(result.get("status") == "ok")
        if out is not None and time.monotonic() - last_write[0] >= WRITE_EVERY_S:
            write_table(table_now(), out, made)
            last_write[0] = time.monotonic()

    try:
        blocks = sorted({nd.cls.__module__ for nd in base.nodes.values()})
        with _executor(executor, workers, scheduler, blocks) as ex, bar:
            drive(tasks, on_row, row_timeout_s=timeout, **ex)
    finally:
        df = table_now()
        if out is not None and (results or fresh or not Path(out).exists()):
            write_table(df, out, made)
    df.attrs["executed"] = len(results)
    df.attrs["kept"] = len(kept)
    return df
