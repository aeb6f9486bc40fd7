"""flowtact.sweep on local processes: rows, seeds, metrics, failures, killed workers, resume."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from runs import TEST_BLOCKS

import flowtact
from flowtact.sweeps.grid import Row
from flowtact.sweeps.metrics import parse_metrics
from flowtact.sweeps.runs import RunTask, run_task
from flowtact.sweeps.schedule import WORKER_DIED
from flowtact.sweeps.seeds import row_seed

TOY = """
name: toy
seed: 3
duration_s: 0.5
nodes:
  src:   {block: "toyblocks:Ramp", params: {noise: 0.1}}
  probe: {block: "sweepblocks:Probe"}
  dbl:   {block: "toyblocks:Scale", params: {gain: 2.0}}
edges: [src.y -> probe.x, src.y -> dbl.x]
record: [src.y, probe.y, dbl.y]
"""

GRID = {"sa1.tau_s": [0.005, 0.01, 0.02], "sa1.sigma": [1.0, 2.0], "sensor.scenario": ["touch", "slip"]}


def metric_columns(df: pd.DataFrame) -> list[str]:
    """Columns that must not depend on where or when a run ran (not run times)."""
    timing = {"run_s", "wall_s", "startup_s", "realtime_factor"}
    return sorted(c for c in df.columns if c not in timing)


def same_table(a: pd.DataFrame, b: pd.DataFrame) -> None:
    """Equal row for row, bit for bit, whatever the order rows finished in."""
    cols = metric_columns(a)
    assert cols == metric_columns(b)
    a = a[cols].sort_values("key").reset_index(drop=True)
    b = b[cols].sort_values("key").reset_index(drop=True)
    pd.testing.assert_frame_equal(a, b, check_exact=True)


@pytest.fixture
def toy(tmp_path: Path) -> Path:
    p = tmp_path / "toy.yaml"
    p.write_text(TOY)
    return p


def test_seeds_depend_on_the_graph_seed_and_row_only() -> None:
    key = Row({"a.b": 1}).key
    assert row_seed(7, key) == row_seed(7, Row({"a.b": 1}).key)
    assert len({row_seed(7, Row({"a.b": v}).key) for v in range(50)}) == 50
    assert row_seed(7, key) != row_seed(8, key)


@pytest.mark.slow
def test_touch_sweep_is_independent_of_worker_count_and_matches_a_direct_run() -> None:
    one = flowtact.sweep("touch", grid=GRID, workers=1, duration_s=0.5)
    two = flowtact.sweep("touch", grid=GRID, workers=2, duration_s=0.5)
    assert len(one) == 12 and (one["status"] == "ok").all(), one["error"].tolist()
    same_table(one, two)
    # seeds come from the row: the same τ, σ and scenario in another row order keeps its seed and spikes
    assert one["seed"].nunique() == 12
    spikes = one["spikes:sa1.spikes"]
    assert spikes.nunique() > 6, "τ, σ and the scenario must change SA1's spike count"
    # a row run directly in this process (no pool) gives the pooled row's numbers exactly
    r = one.iloc[5]
    from flowtact.graphfile.graph import resolve_graph_path

    src = str(resolve_graph_path("touch"))
    params = {k: r[k] for k in GRID}
    task = RunTask(0, Row(params).key, int(r["seed"]), src, Path(src).read_text(),
                   tuple(f"{k}={v}" for k, v in params.items()), duration_s=0.5,
                   metrics=parse_metrics(None))  # fmt: skip
    direct = run_task(task)
    assert direct["status"] == "ok"
    assert direct["spikes:sa1.spikes"] == r["spikes:sa1.spikes"]
    assert direct["rate_hz:fa1.spikes"] == r["rate_hz:fa1.spikes"]
    assert direct["provenance"] == r["provenance"]
    # rates are spikes / units / duration
    assert r["rate_hz:sa1.spikes"] == pytest.approx(r["spikes:sa1.spikes"] / 20 / 0.5)


def test_rmse_and_user_metrics_against_numpy(toy: Path) -> None:
    df = flowtact.sweep(toy, allow_modules=TEST_BLOCKS, grid={"src.noise": [0.0, 0.5]}, workers=1, rmse=["dbl.y=src.y"],
                        metrics="spikes,sweepblocks:mean_y")  # fmt: skip
    assert (df["status"] == "ok").all(), df["error"].tolist()
    clean = df[df["src.noise"] == 0.0].iloc[0]
    t = np.arange(500) / 1000.0  # the ramp's samples in 0.5 s at 1 kHz from t = 0 (y = t; dbl.y = 2t)
    assert clean["rmse:dbl.y"] == pytest.approx(math.sqrt(np.mean(t**2)), rel=1e-12)
    assert clean["mean_y:mean"] == pytest.approx(np.mean(t), rel=1e-12)
    assert clean["mean_y:n"] == len(t)
    noisy = df[df["src.noise"] == 0.5].iloc[0]
    assert noisy["rmse:dbl.y"] > clean["rmse:dbl.y"]


def test_failing_rows_killed_workers_and_resume(toy: Path, tmp_path: Path) -> None:
    flag, log, out = tmp_path / "armed", tmp_path / "opens.log", tmp_path / "res.parquet"
    flag.touch()
    fixed = [f"probe.flag={flag}", f"probe.log={log}"]
    grid = ["probe.mode=ok,raise,kill", "src.noise=0,0.1,-1"]
    first = flowtact.sweep(toy, allow_modules=TEST_BLOCKS, grid=grid, overrides=fixed, workers=2, out=out)
    assert len(first) == 9 and first.attrs["executed"] == 9
    by = {(r["probe.mode"], r["src.noise"]): r for _, r in first.iterrows()}
    assert [k for k, r in by.items() if r["status"] == "ok"] == [("ok", 0), ("ok", 0.1)]
    assert by[("raise", 0.1)]["error"].startswith("node 'probe' (probe) failed at t=")
    assert "ZeroDivisionError: probe raised as asked" in by[("raise", 0.1)]["error"]
    for noise in (0, 0.1):
        assert by[("kill", noise)]["error"] == WORKER_DIED
    for mode in ("ok", "raise", "kill"):  # a bad value fails its row only, saying which parameter
        err = by[(mode, -1)]["error"]
        assert "noise" in err and "\n" not in err, err
    on_disk = pd.read_parquet(out)
    same_table(first, on_disk)

    flag.unlink()  # the cause goes away: a resumed sweep runs the 7 failed rows only
    log.write_text("")
    again = flowtact.sweep(toy, allow_modules=TEST_BLOCKS, grid=grid, overrides=fixed, workers=2, out=out)
    assert again.attrs == {"executed": 7, "kept": 2}
    assert len(log.read_text().splitlines()) == 4  # raise ×2, kill ×2 built and ran; bad values never build
    assert sorted(again.loc[again["status"] != "ok", "src.noise"]) == [-1, -1, -1]
    assert (again.loc[again["src.noise"] != -1, "status"] == "ok").all()
    kept = first[first["status"] == "ok"].set_index("key")
    now = again.set_index("key").loc[kept.index]
    assert now["seed"].tolist() == kept["seed"].tolist()  # kept as they were, not run again
    assert now["run_s"].tolist() == kept["run_s"].tolist()
    log.write_text("")
    third = flowtact.sweep(toy, allow_modules=TEST_BLOCKS, grid=grid, overrides=fixed, workers=2, out=out)
    assert third.attrs == {"executed": 3, "kept": 6} and log.read_text() == ""
