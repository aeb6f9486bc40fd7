"""The same sweep on local processes and on a dask.distributed LocalCluster gives the same table."""

from __future__ import annotations

import pytest

import flowtact

pytest.importorskip("distributed")

from test_sweep_runs import GRID, same_table


@pytest.mark.slow
def test_local_and_dask_local_cluster_give_identical_tables() -> None:
    from distributed import Client, LocalCluster

    local = flowtact.sweep("touch", grid=GRID, workers=2, duration_s=0.5)
    with (
        LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster,
        Client(cluster) as client,
    ):
        on_dask = flowtact.sweep("touch", grid=GRID, executor=client.get_executor(pure=False), duration_s=0.5)
        workers = {w for w in client.run(lambda: __import__("os").getpid()).values()}
    assert len(local) == 12 and (local["status"] == "ok").all(), local["error"].tolist()
    assert len(workers) == 2
    same_table(local, on_dask)


@pytest.mark.slow
def test_executor_dask_builds_and_closes_its_own_local_cluster(tmp_path) -> None:
    out = tmp_path / "r.parquet"
    df = flowtact.sweep("touch", grid={"sa1.tau_s": [0.005, 0.01]}, executor="dask", workers=2,
                        duration_s=0.3, out=out)  # fmt: skip
    assert (df["status"] == "ok").all(), df["error"].tolist()
    again = flowtact.sweep("touch", grid={"sa1.tau_s": [0.005, 0.01]}, workers=1, duration_s=0.3)
    same_table(df, again)
