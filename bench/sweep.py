"""Suite ``sweep``: what ``flowtact sweep`` costs per run on a trivial graph, local vs Dask.

The same N runs of a trivial graph (the touch sensor and its force calibration, 50 ms of graph
time, one grid value per run) go (1) through a plain loop of ``run_task`` in this process (the
baseline: the per-run work itself: load, compile, run, metrics), (2) through ``flowtact.sweep`` on
local processes (2 workers, pool start included) and (3) on a ``dask.distributed`` LocalCluster of
2 single-threaded worker processes (started once, its start-up reported apart). Figures are ms of
wall time per run; the ratio is the loop's time over the sweep's (> 1: the sweep finishes sooner;
< 1: its overhead outweighs running in parallel). The per-run overhead is the sweep's time per
run × workers − the loop's time per run (what each run costs a worker beyond its own work),
meaningful only when the two cores are otherwise idle.
"""

from __future__ import annotations

import contextlib
import time
from importlib.resources import files
from pathlib import Path

from flowtact.benchmark import Context, Suite

WORKERS = 2


def _graph() -> str:
    return str(files("flowtact.bench") / "graphs" / "sweep_trivial.yaml")


def _grid(n: int) -> dict[str, list[float]]:
    return {"sensor.rate_hz": [1000.0 + i for i in range(n)]}


def _loop(n: int) -> float:
    """Seconds for the N runs in a plain loop in this process."""
    from flowtact.sweeps.grid import Row
    from flowtact.sweeps.metrics import parse_metrics
    from flowtact.sweeps.runs import RunTask, run_task
    from flowtact.sweeps.seeds import row_seed

    src = _graph()
    text = Path(src).read_text()  # read once, like the sweep does
    spec = parse_metrics(None)
    t0 = time.perf_counter()
    for v in _grid(n)["sensor.rate_hz"]:
        key = Row({"sensor.rate_hz": v}).key
        row = run_task(RunTask(0, key, row_seed(1, key), src, text, (f"sensor.rate_hz={v!r}",), metrics=spec))
        assert row["status"] == "ok", row["error"]
    return time.perf_counter() - t0


def _sweep(n: int, executor: object) -> float:
    import flowtact

    t0 = time.perf_counter()
    df = flowtact.sweep(_graph(), grid=_grid(n), executor=executor, workers=WORKERS)
    secs = time.perf_counter() - t0
    assert (df["status"] == "ok").all() and len(df) == n, df["error"].tolist()
    return secs


def run(ctx: Context) -> None:
    n = 24 if ctx.quick else 96
    repeats = 3 if ctx.quick else 5
    params = {"runs": n, "workers": WORKERS}
    with contextlib.ExitStack() as stack:
        dask_ex = _dask(ctx, stack, params)
        ctx.step("warm-up")
        _loop(4)  # imports, kernels
        _sweep(4, "local")  # the fork server
        if dask_ex is not None:
            _sweep(4, dask_ex)  # imports and kernels in each dask worker
        loop, local, dask = [], [], []
        for i in range(repeats):  # in rounds: round i of each under the same load
            ctx.step(f"round {i + 1}/{repeats}")
            loop.append(1e3 * _loop(n) / n)
            local.append(1e3 * _sweep(n, "local") / n)
            if dask_ex is not None:
                dask.append(1e3 * _sweep(n, dask_ex) / n)
    base = "plain loop, ms per run"
    ctx.figure(base, loop, "ms per run", "lower", is_baseline=True, reference=True, params=params)
    figs = {"local processes": ctx.figure("sweep, local processes, ms per run", local, "ms per run", "lower",
                                          baseline=base, paired=True, params=params)}  # fmt: skip
    if dask:
        figs["dask LocalCluster"] = ctx.figure("sweep, dask LocalCluster, ms per run", dask, "ms per run",
                                               "lower", baseline=base, paired=True, params=params)  # fmt: skip
    rows = [[k, f"{f.median:.2f}", f"{f.median * WORKERS - _median(loop):.2f}"] for k, f in figs.items()]
    ctx.table(f"Per run, {n} runs of a trivial graph on {WORKERS} workers (median of {repeats} rounds)",
              ["executor", "ms per run (wall)", "overhead per run and worker, ms"], rows,
              note=f"the plain loop takes {_median(loop):.2f} ms per run; each local sweep starts its "
              "own pool (2 forked workers), whose start-up is spread over its runs")  # fmt: skip


def _dask(ctx: Context, stack: contextlib.ExitStack, params: dict) -> object | None:
    """A started LocalCluster's executor, as ``--executor dask`` makes it (its start-up recorded), or None without Dask."""
    try:
        from distributed import Client

        from flowtact.sweeps.executors import DaskRows, local_cluster
    except ImportError:
        ctx.note('Dask is not installed (pip install "flowtact[dask]"): the Dask part was not measured.')
        return None
    import logging

    logging.getLogger("distributed").setLevel(logging.ERROR)
    ctx.step("dask LocalCluster start")
    t0 = time.perf_counter()
    cluster = stack.enter_context(local_cluster(WORKERS))  # the sweep's own: TLS, temporary credentials
    client = stack.enter_context(Client(cluster, security=cluster.security))
    ctx.figure("dask LocalCluster(2) start, s", time.perf_counter() - t0, "s", "lower", params=params)
    return DaskRows(client, restart_workers=True)


def _median(xs: list[float]) -> float:
    s = sorted(xs)
    return s[len(s) // 2] if len(s) % 2 else 0.5 * (s[len(s) // 2 - 1] + s[len(s) // 2])


SUITE = Suite(
    name="sweep",
    title="flowtact sweep: overhead per run, local processes vs Dask",
    measures="ms of wall time per run of `flowtact.sweep` over a trivial graph (touch sensor + force, 50 ms), "
    "on 2 local worker processes (pool start included) and on a dask.distributed LocalCluster of 2 "
    "single-threaded workers (its start-up reported apart), and the per-run overhead beyond the run's work.",
    baseline="the same runs (`run_task`) in a plain loop in this process",
    run=run,
    needs=("pandas", "pyarrow"),
    minutes_quick=0.4,
    minutes_full=2.0,
    # quick: one process (its sweeps start fresh worker processes every round already; a second
    # process would repeat the Dask cluster's start and every warm-up); full: 3 fresh processes
    processes=(1, 3),
)
