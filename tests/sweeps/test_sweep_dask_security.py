"""The LocalCluster a Dask sweep starts is reachable by the sweep only (issue 30): TLS with
temporary credentials, so a foreign client on the same machine cannot submit a task; the sweep
itself runs on it, and a hung row there times out as a failed row whose worker is restarted."""

from __future__ import annotations

import asyncio
import multiprocessing
import os
from pathlib import Path

import pytest

import flowtact

pytest.importorskip("distributed")
pytest.importorskip("cryptography")

from distributed import Client
from distributed.security import Security
from runs import TEST_BLOCKS
from sweepblocks import TOY_GRAPH

from flowtact.sweeps.executors import DaskRows, local_cluster


@pytest.fixture(scope="module")
def cluster():
    with local_cluster(2) as c:
        yield c


@pytest.fixture(scope="module")
def client(cluster):
    with Client(cluster, security=cluster.security) as c:
        yield c


def foreign_submit(address: str, security: Security | None, ran: str) -> str:
    """What a foreign client got trying to run a task on ``address`` (the task would create ``ran``)."""
    try:
        kwargs = {"security": security} if security is not None else {}
        with Client(address, timeout="5s", **kwargs) as c:
            c.submit(Path(ran).touch).result(timeout=10)
        return "ran"
    except Exception as e:  # noqa: BLE001 - any refusal will do; the test checks the task did not run
        return f"refused: {type(e).__name__}"


def foreign_connect(address: str, security: Security | None) -> str:
    """What a raw connection to a worker's address got (a worker runs what it is sent)."""
    from distributed.comm import connect

    async def go() -> str:
        args = security.get_connection_args("client") if security is not None else {}
        comm = await connect(address, timeout=5, **args)
        await comm.write({"op": "identity"})
        await comm.read()
        await comm.close()
        return "answered"

    try:
        return asyncio.run(go())
    except Exception as e:  # noqa: BLE001
        return f"refused: {type(e).__name__}"


def test_a_foreign_client_cannot_submit_to_the_sweeps_cluster(cluster, client, tmp_path: Path) -> None:
    ran = tmp_path / "ran"
    address = cluster.scheduler_address
    assert address.startswith("tls://127.0.0.1:")
    attempts = [
        (address, None),  # no credentials at all
        (address.replace("tls://", "tcp://"), None),  # plain TCP to the TLS port
        (address, Security.temporary()),  # TLS with credentials of its own
    ]
    ctx = multiprocessing.get_context("spawn")  # another process, as another user's program would be
    with ctx.Pool(1) as pool:
        got = pool.starmap(foreign_submit, [(a, s, str(ran)) for a, s in attempts])
    assert all(g.startswith("refused") for g in got), got
    workers = list(client.scheduler_info()["workers"])
    assert len(workers) == 2 and all(w.startswith("tls://127.0.0.1:") for w in workers)
    for w in workers:
        for attempt in (None, Security.temporary()):
            assert foreign_connect(w, attempt).startswith("refused"), w
    assert not ran.exists()
    assert client.submit(sum, [1, 2]).result(timeout=30) == 3  # the sweep's own client gets through


def test_the_sweep_runs_on_it_and_a_hung_row_there_times_out(client, tmp_path: Path) -> None:
    toy, flag, log = tmp_path / "toy.yaml", tmp_path / "armed", tmp_path / "opens.log"
    toy.write_text(TOY_GRAPH)
    flag.touch()
    rows = DaskRows(client, restart_workers=True)  # as dask_executor makes it for its own cluster
    df = flowtact.sweep(toy, allow_modules=TEST_BLOCKS, grid=["probe.mode=ok,hang"], overrides=[f"probe.flag={flag}", f"probe.log={log}"],
                        executor=rows, workers=2, row_timeout_s=3)  # fmt: skip
    by = df.set_index("probe.mode")
    assert by.loc["ok", "status"] == "ok", by.loc["ok", "error"]
    assert by.loc["hang", "error"] == "timed out after 3 s (--row-timeout)"
    hung = [int(line.split()[1]) for line in log.read_text().splitlines() if line.startswith("hang ")]
    assert len(hung) == 1
    with pytest.raises(ProcessLookupError):  # its worker was restarted: the hung task is gone
        os.kill(hung[0], 0)
    assert len(client.scheduler_info()["workers"]) == 2
    assert client.submit(sum, [1, 2]).result(timeout=30) == 3
