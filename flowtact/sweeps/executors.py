"""The executors a sweep runs on: a local pool of row processes, or a ``dask.distributed`` cluster.

Local rows run in a :class:`RowPool`: worker processes forked from a server that has already
imported flowtact and the graph's blocks (safe with threads in the parent, cheap per worker), each
running one row at a time. Unlike a ``ProcessPoolExecutor`` it knows which process runs which row,
so a row that overruns its timeout is ended by killing its own process (:meth:`RowPool.kill`) and
a process that dies fails its own row only; the others go on. Dask connects to ``scheduler`` or
starts a ``LocalCluster`` of ``workers`` single-threaded processes that only holders of the
sweep's temporary TLS credentials can reach (:func:`local_cluster`); :class:`DaskRows` hands it
the rows as a standard ``concurrent.futures.Executor`` whose :meth:`DaskRows.kill` cancels a row
that overran its timeout and, on a cluster the sweep started itself, restarts the worker running
it (a running Python thread cannot be stopped otherwise).
"""

from __future__ import annotations

import contextlib
import multiprocessing
import multiprocessing.connection
import os
import threading
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Executor, Future, InvalidStateError
from typing import Any

from flowtact.errors import SweepSpecError, WorkerDied
from flowtact.running.python_child import safe_path_env
from flowtact.sweeps.schedule import WORKER_DIED

__all__ = ["DaskRows", "RowPool", "dask_executor", "local_cluster", "local_pool_factory"]


def local_pool_factory(workers: int | None, preload: Sequence[str] = ()) -> Callable[[], Executor]:
    """A function returning a fresh :class:`RowPool` of ``workers`` (default: the CPU count) whose
    workers fork from a server that has imported flowtact and the ``preload`` modules (the graph's
    blocks), so no worker imports them again. The server is started once per process: the first
    pool's preload list holds for later ones."""
    n = workers or os.cpu_count() or 1
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(
        ["flowtact.sweeps.runs", "flowtact.running.launch", "flowtact.running.compile", *preload]
    )

    def make() -> Executor:
        from multiprocessing import forkserver

        with safe_path_env():  # the fork server (and its resource tracker): no cwd on their import path
            forkserver.ensure_running()
        return RowPool(n, ctx)

    return make


def _serve(conn: Any) -> None:
    """A worker's loop: run each ``(fn, args)`` it is sent, answer ``(True, result)`` or ``(False, error)``."""
    while True:
        try:
            msg = conn.recv()
        except (EOFError, OSError, KeyboardInterrupt):  # the pool went away, or Ctrl-C while idle
            return
        if msg is None:
            return
        fn, args = msg
        try:
            answer: tuple[bool, Any] = (True, fn(*args))
        except BaseException as e:  # noqa: BLE001 - every failure goes back to the pool as the row's
            answer = (False, e)
        try:
            conn.send(answer)
        except Exception as e:  # noqa: BLE001 - an answer that does not pickle
            conn.send((False, RuntimeError(f"the row's answer cannot be sent back: {type(e).__name__}: {e}")))
        except (OSError, KeyboardInterrupt):
            return


class _Worker:
    """One worker process, its end of the pipe, and the future of the row it runs (None: idle)."""

    def __init__(self, ctx: Any) -> None:
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=_serve, args=(child,), daemon=True, name="flowtact-sweep-row")
        self.proc.start()
        child.close()
        self.future: Future | None = None

    def stop(self, kill: bool) -> None:
        with contextlib.suppress(OSError, ValueError):
            if kill:
                self.proc.kill()
            else:
                self.conn.send(None)
        self.proc.join(timeout=None if kill else 5)
        if self.proc.exitcode is None:
            self.proc.kill()
            self.proc.join()
        self.conn.close()


class RowPool(Executor):
    """At most ``workers`` processes, each running one submitted call at a time; futures are
    *running* exactly while a process runs them. :meth:`kill` ends one call's process; a call whose
    process died fails with :class:`WorkerDied`, and a fresh process takes the next call."""

    def __init__(self, workers: int, ctx: Any = None) -> None:
        self._ctx = ctx or multiprocessing.get_context("forkserver")
        self._size = max(1, workers)
        self._lock = threading.Lock()
        self._pending: deque[tuple[Future, Callable[..., Any], tuple[Any, ...]]] = deque()
        self._workers: list[_Worker] = []
        self._closing = False
        self._kill_all = False
        self._wake_r, self._wake_w = os.pipe()
        self._thread = threading.Thread(target=self._manage, name="flowtact-row-pool", daemon=True)
        self._thread.start()

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future:
        """Queue ``fn(*args)``; it starts when a process is free (keyword arguments are not taken)."""
        if kwargs:
            raise TypeError("RowPool.submit takes positional arguments only")
        f: Future = Future()
        with self._lock:
            if self._closing:
                raise RuntimeError("cannot schedule new futures after shutdown")
            self._pending.append((f, fn, args))
        self._wake()
        return f

    def kill(self, future: Future) -> bool:
        """End the process running ``future`` (SIGKILL); False if no process runs it."""
        with self._lock:
            for w in self._workers:
                if w.future is future:
                    with contextlib.suppress(OSError, ValueError):
                        w.proc.kill()
                    return True
        return False

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        """Stop taking calls; ``cancel_futures`` cancels queued ones and, without ``wait``, also
        kills the processes still running one (nothing is left running behind the caller)."""
        with self._lock:
            self._closing = True
            if cancel_futures:
                while self._pending:
                    self._pending.popleft()[0].cancel()
                self._kill_all = not wait
        self._wake()
        if wait:
            self._thread.join()

    def _wake(self) -> None:
        with contextlib.suppress(OSError):
            os.write(self._wake_w, b"x")

    def _manage(self) -> None:
        """The pool's thread: start calls on free processes, hand answers and deaths to futures."""
        try:
            while True:
                with self._lock:
                    self._dispatch()
                    busy = [w for w in self._workers if w.future is not None]
                    if self._closing and (self._kill_all or (not busy and not self._pending)):
                        break
                watch = [self._wake_r, *(w.conn for w in busy), *(w.proc.sentinel for w in busy)]
                ready = multiprocessing.connection.wait(watch)
                if self._wake_r in ready:
                    os.read(self._wake_r, 4096)
                for w in busy:
                    if w.conn in ready or w.proc.sentinel in ready:
                        self._answer(w)
        finally:
            self._close_workers()

    def _dispatch(self) -> None:
        """Give queued calls to idle live processes, starting processes up to the pool's size."""
        self._workers = [w for w in self._workers if w.future is not None or w.proc.is_alive()]
        while self._pending:
            idle = next((w for w in self._workers if w.future is None), None)
            if idle is None and len(self._workers) >= self._size:
                return
            f, fn, args = self._pending.popleft()
            if not f.set_running_or_notify_cancel():
                continue
            if idle is None:
                idle = _Worker(self._ctx)
                self._workers.append(idle)
            try:
                idle.conn.send((fn, args))
            except (OSError, ValueError):  # it died while idle: the call never reached it
                f.set_exception(WorkerDied(WORKER_DIED))
                self._workers.remove(idle)
                continue
            except Exception as e:  # noqa: BLE001 - the call does not pickle: nothing was sent
                f.set_exception(e)
                continue
            idle.future = f

    def _answer(self, w: _Worker) -> None:
        """``w`` answered or died: settle its future; a dead process leaves the pool."""
        f, w.future = w.future, None
        assert f is not None
        try:
            if w.conn.poll():
                ok, value = w.conn.recv()
                if ok:
                    f.set_result(value)
                else:
                    f.set_exception(value)
                return
        except (EOFError, OSError):
            pass
        except Exception as e:  # noqa: BLE001 - an answer that does not unpickle here
            f.set_exception(RuntimeError(f"the row's answer cannot be read: {type(e).__name__}: {e}"))
            return
        f.set_exception(WorkerDied(WORKER_DIED))
        with self._lock:
            self._workers.remove(w)
        w.stop(kill=True)

    def _close_workers(self) -> None:
        with self._lock:
            workers, self._workers = self._workers, []
            pending, self._pending = list(self._pending), deque()
        for w in workers:
            if w.future is not None and not w.future.done():
                w.future.set_exception(WorkerDied(WORKER_DIED))
            w.stop(kill=w.future is not None)
        for f, _, _ in pending:
            f.cancel()
        for fd in (self._wake_r, self._wake_w):
            with contextlib.suppress(OSError):
                os.close(fd)


class DaskRows(Executor):
    """A dask ``Client`` as a ``concurrent.futures.Executor`` (like ``client.get_executor()``) that
    can end a row: :meth:`kill` cancels its task and, with ``restart_workers``, restarts the worker
    running it (only for a cluster the sweep owns: other clients' tasks may share a worker)."""

    def __init__(self, client: Any, restart_workers: bool = False) -> None:
        self.client, self.restart = client, restart_workers
        self._tasks: dict[Future, Any] = {}

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future:
        """Submit ``fn(*args)`` as a dask task (never cached: ``pure=False``)."""
        if kwargs:
            raise TypeError("DaskRows.submit takes positional arguments only")
        task = self.client.submit(fn, *args, pure=False)
        f: Future = Future()
        self._tasks[f] = task

        def settle(done: Any) -> None:
            self._tasks.pop(f, None)
            with contextlib.suppress(InvalidStateError):  # cancelled by kill() meanwhile
                try:
                    result = done.result()
                except BaseException as e:  # noqa: BLE001 - the task's failure (KilledWorker, cancelled, ...)
                    f.set_exception(e)
                else:
                    f.set_result(result)

        task.add_done_callback(settle)
        return f

    def kill(self, future: Future) -> bool:
        """Cancel ``future``'s task; restart the worker running it when this sweep owns the cluster."""
        task = self._tasks.pop(future, None)
        if task is None:
            return False
        where = []
        if self.restart:
            with contextlib.suppress(Exception):
                where = [w for w, keys in self.client.processing().items() if task.key in keys]
        task.cancel()
        if where:
            with contextlib.suppress(Exception):  # a worker that fails to restart is reported by dask
                self.client.restart_workers(where, raise_for_error=False)
        future.cancel()
        return True

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        """Cancel the tasks still out when asked (the client and cluster are closed by their owner)."""
        if cancel_futures or not wait:
            tasks, self._tasks = list(self._tasks.values()), {}
            with contextlib.suppress(Exception):
                self.client.cancel(tasks)


def _temporary_security() -> Any:
    """Dask TLS with a fresh self-signed certificate, required of every connection."""
    from distributed.security import Security

    try:
        return Security.temporary()
    except ImportError:
        from flowtact.graphfile.extras import install_hint

        _, how = install_hint("flowtact", "cryptography", "dask")
        raise SweepSpecError(
            f"--executor dask needs cryptography (TLS for its local cluster): {how}"
        ) from None


@contextlib.contextmanager
def local_cluster(workers: int | None) -> Iterator[Any]:
    """A ``LocalCluster`` of ``workers`` single-threaded processes on loopback that requires TLS
    with temporary credentials (held by this process only): another local process cannot submit
    tasks to it. Closed at the end."""
    import dask
    from distributed import LocalCluster

    security = _temporary_security()
    # its workers (restarts too) and helpers start without the cwd on their import path
    safe = dask.config.set({"distributed.nanny.pre-spawn-environ.PYTHONSAFEPATH": "1"})
    with safe, safe_path_env():
        cluster = LocalCluster(
            n_workers=workers or os.cpu_count() or 1,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            host="127.0.0.1",
            protocol="tls://",
            security=security,
        )
    with cluster:
        yield cluster


@contextlib.contextmanager
def dask_executor(scheduler: str | None, workers: int | None) -> Iterator[tuple[Executor, int]]:
    """A dask executor and its worker count; a :func:`local_cluster` (closed at the end) without ``scheduler``."""
    from flowtact.graphfile.extras import install_hint, module_available

    if not module_available("distributed"):
        what, how = install_hint("flowtact", "distributed", "dask")
        raise SweepSpecError(f"--executor dask needs {what}: {how}")
    import logging

    from distributed import Client

    logging.getLogger("distributed").setLevel(logging.ERROR)  # worker restarts are reported as rows
    with contextlib.ExitStack() as stack:
        own = not scheduler
        if scheduler:
            try:
                client: Any = stack.enter_context(Client(scheduler, timeout="10s"))
            except OSError as e:
                raise SweepSpecError(f"--scheduler {scheduler}: cannot connect ({e})") from None
        else:
            cluster = stack.enter_context(local_cluster(workers))
            client = stack.enter_context(Client(cluster, security=cluster.security))
        n = max(sum(w.get("nthreads", 1) for w in client.scheduler_info()["workers"].values()), 1)
        yield DaskRows(client, restart_workers=own), n
