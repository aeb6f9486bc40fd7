"""The executors a sweep runs on: a local process pool, or a ``dask.distributed`` cluster.

Local pools start their workers from a fork server that has already imported flowtact (safe with
threads in the parent, cheap per worker). Dask connects to ``scheduler`` or starts a
``LocalCluster`` of ``workers`` single-threaded processes; its ``Client.get_executor()`` is a
standard ``concurrent.futures.Executor``.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor
from typing import Any

from flowtact.python_child import safe_path_env
from flowtact.sweeps.grid import SweepSpecError

__all__ = ["dask_executor", "local_pool_factory"]


def local_pool_factory(workers: int | None, preload: Sequence[str] = ()) -> Callable[[], Executor]:
    """A function returning a fresh process pool of ``workers`` (default: the CPU count) whose
    workers fork from a server that has imported flowtact and the ``preload`` modules (the graph's
    blocks), so no worker imports them again. The server is started once per process: the first
    pool's preload list holds for later ones."""
    n = workers or os.cpu_count() or 1
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(["flowtact.sweeps.runs", "flowtact.launch", "flowtact.compile", *preload])

    def make() -> Executor:
        from multiprocessing import forkserver

        with safe_path_env():  # the fork server (and its resource tracker): no cwd on their import path
            forkserver.ensure_running()
        return ProcessPoolExecutor(max_workers=n, mp_context=ctx)

    return make


@contextlib.contextmanager
def dask_executor(scheduler: str | None, workers: int | None) -> Iterator[tuple[Executor, int]]:
    """A dask executor and its worker count; a ``LocalCluster`` (closed at the end) without ``scheduler``."""
    from flowtact.extras import install_hint, module_available

    if not module_available("distributed"):
        what, how = install_hint("flowtact", "distributed", "dask")
        raise SweepSpecError(f"--executor dask needs {what}: {how}")
    import logging

    from distributed import Client, LocalCluster

    logging.getLogger("distributed").setLevel(logging.ERROR)  # worker restarts are reported as rows
    with contextlib.ExitStack() as stack:
        if scheduler:
            try:
                client: Any = stack.enter_context(Client(scheduler, timeout="10s"))
            except OSError as e:
                raise SweepSpecError(f"--scheduler {scheduler}: cannot connect ({e})") from None
        else:
            import dask

            # its workers (restarts too) and helpers start without the cwd on their import path
            safe = dask.config.set({"distributed.nanny.pre-spawn-environ.PYTHONSAFEPATH": "1"})
            with safe, safe_path_env():
                cluster = stack.enter_context(
                    LocalCluster(
                        n_workers=workers or os.cpu_count() or 1,
                        threads_per_worker=1,
                        processes=True,
                        dashboard_address=None,
                    )
                )
            client = stack.enter_context(Client(cluster))
        n = max(sum(w.get("nthreads", 1) for w in client.scheduler_info()["workers"].values()), 1)
        yield client.get_executor(pure=False), n
