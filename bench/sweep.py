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
    ctx.step("loop")
    _loop(4)  # warm-up: imports, kernels
    loop = [1e3 * _loop(n) / n for _ in range(repeats)]
    ctx.figure("plain loop, ms per run", loop, "ms per run", "lower", is_baseline=True, params=params)
    ctx.step("local processes")
    _sweep(4, "local")  # warm-up: the fork server
    local = [1e3 * _sweep(n, "local") / n for _ in range(repeats)]
    fig_local = ctx.figure("sweep, local processes, ms per run", local, "ms per run", "lower",
                           baseline="plain loop, ms per run", params=params)  # fmt: skip
    rows = [
        ["local processes", f"{fig_local.median:.2f}", f"{fig_local.median * WORKERS - _median(loop):.2f}"]
    ]
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        ctx.note('Dask is not installed (pip install "flowtact[dask]"): the Dask part was not measured.')
    else:
        import logging

        logging.getLogger("distributed").setLevel(logging.ERROR)
        ctx.step("dask LocalCluster start")
        t0 = time.perf_counter()
        with (
            LocalCluster(
                n_workers=WORKERS, threads_per_worker=1, processes=True, dashboard_address=None
            ) as c,
            Client(c) as client,
        ):
            ctx.figure("dask LocalCluster(2) start, s", time.perf_counter() - t0, "s", "lower", params=params)
            ex = client.get_executor(pure=False)
            ctx.step("dask")
            _sweep(4, ex)  # warm-up: imports and kernels in each worker
            dask = [1e3 * _sweep(n, ex) / n for _ in range(repeats)]
        fig_dask = ctx.figure("sweep, dask LocalCluster, ms per run", dask, "ms per run", "lower",
                              baseline="plain loop, ms per run", params=params)  # fmt: skip
        rows.append(
            [
                "dask LocalCluster",
                f"{fig_dask.median:.2f}",
                f"{fig_dask.median * WORKERS - _median(loop):.2f}",
            ]
        )
    ctx.table(f"Per run, {n} runs of a trivial graph on {WORKERS} workers (median of {repeats})",
              ["executor", "ms per run (wall)", "overhead per run and worker, ms"], rows,
              note=f"the plain loop takes {_median(loop):.2f} ms per run; each local sweep starts its "
              "own pool (2 forked workers), whose start-up is spread over its runs")  # fmt: skip


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
    minutes_quick=0.5,
    minutes_full=2.0,
)
