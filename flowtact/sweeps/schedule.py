"""Drive a sweep's runs through a ``concurrent.futures.Executor``, surviving dying workers.

At most ``in_flight`` runs are submitted at a time. When the pool breaks (a worker process was
killed: ``BrokenProcessPool``) every run it held becomes a suspect and a fresh pool takes over;
suspects then run one at a time, so one that breaks the pool again alone is the culprit: its row
fails saying its worker died, and the others complete. An executor the caller passed cannot be
rebuilt: its remaining runs fail with the error it gives.

A run that has not answered ``row_timeout_s`` after it started becomes a failed row ("timed out
after S s") and the others go on: the executor's ``kill(future)`` ends it where the executor has
one (:class:`flowtact.sweeps.executors.RowPool` kills the run's process), else the future is
cancelled (Dask drops a task still queued; one already running keeps its worker thread until it
returns). A run's clock starts when its future is first seen running, or, for executors that
never say (``clock="submitted"``: Dask), when it was handed over.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Iterable
from concurrent.futures import FIRST_COMPLETED, BrokenExecutor, Executor, Future, wait
from typing import Any, Literal

from flowtact.sweeps.runs import RunTask, failed_row, one_line, run_task

__all__ = ["WORKER_DIED", "drive", "timed_out"]

WORKER_DIED = "the worker process running it died (killed by a signal, or out of memory?)"


def timed_out(seconds: float) -> str:
    """The error of a row that overran its timeout."""
    return f"timed out after {seconds:g} s (--row-timeout)"


class _Pool:
    """The executor in use, and how to get a fresh one when it breaks (None: the caller's own)."""

    def __init__(self, executor: Executor | None, make: Callable[[], Executor] | None) -> None:
        self.make = make
        self.executor = executor if executor is not None else make()  # type: ignore[misc]

    def renew(self) -> bool:
        if self.make is None:
            return False
        self.executor.shutdown(wait=False, cancel_futures=True)
        self.executor = self.make()
        return True


def drive(
    tasks: Iterable[RunTask],
    on_row: Callable[[RunTask, dict[str, Any]], None],
    *,
    executor: Executor | None = None,
    make_executor: Callable[[], Executor] | None = None,
    in_flight: int = 4,
    on_idle: Callable[[], None] | None = None,
    fn: Callable[[RunTask], dict[str, Any]] = run_task,
    row_timeout_s: float | None = None,
    clock: Literal["running", "submitted"] = "running",
) -> None:
    """Run every task, calling ``on_row(task, row)`` as each finishes (in the calling thread).

    ``executor`` is used as given (and not shut down); otherwise ``make_executor`` builds one (and
    again after it breaks) and it is shut down at the end. ``on_idle`` is called about twice a
    second while waiting (progress). A run still going ``row_timeout_s`` after its clock started
    (``clock``: when first seen running, or when submitted) is abandoned as a failed row. Ctrl-C
    cancels what has not started and re-raises.
    """
    pool = _Pool(executor, None if executor is not None else make_executor)
    _Driver(pool, deque(tasks), on_row, in_flight, fn, row_timeout_s, clock).run(on_idle)


class _Driver:
    """The loop of :func:`drive`: submit, wait, hand rows over, recover from a broken pool."""

    def __init__(self, pool: _Pool, queue: deque[RunTask], on_row: Callable[[RunTask, dict[str, Any]], None],
                 in_flight: int, fn: Callable[[RunTask], dict[str, Any]], row_timeout_s: float | None = None,
                 clock: str = "running") -> None:  # fmt: skip
        self.pool, self.queue, self.on_row, self.in_flight, self.fn = pool, queue, on_row, in_flight, fn
        self.timeout, self.clock = row_timeout_s, clock
        self.suspects: deque[RunTask] = deque()
        self.running: dict[Future, tuple[RunTask, bool]] = {}
        self.started: dict[Future, float] = {}

    def run(self, on_idle: Callable[[], None] | None) -> None:
        try:
            while self.queue or self.suspects or self.running:
                self._fill()
                if self.running:
                    self._collect()
                    self._expire()
                if on_idle is not None:
                    on_idle()
        finally:
            for f in self.running:
                f.cancel()
            if self.pool.make is not None:
                self.pool.executor.shutdown(wait=False, cancel_futures=True)

    def _fill(self) -> None:
        """Suspects run one at a time, alone; otherwise keep ``in_flight`` runs submitted."""
        if self.suspects:
            if not self.running:
                self._submit(self.suspects.popleft(), True)
            return
        while self.queue and len(self.running) < self.in_flight:
            self._submit(self.queue.popleft(), False)

    def _submit(self, task: RunTask, alone: bool) -> None:
        try:
            f = self.pool.executor.submit(self.fn, task)
        except BrokenExecutor as e:
            if not self.pool.renew():
                self.on_row(task, failed_row(task, f"the executor is broken: {one_line(e)}"))
                return
            f = self.pool.executor.submit(self.fn, task)
        self.running[f] = (task, alone)
        if self.clock == "submitted":
            self.started[f] = time.monotonic()

    def _expire(self) -> None:
        """Runs past their timeout become failed rows; their executor ends them if it can."""
        if self.timeout is None:
            return
        now = time.monotonic()
        for f, (task, _) in list(self.running.items()):
            if f.done():
                continue
            if f not in self.started:
                if f.running():
                    self.started[f] = now
                continue
            if now - self.started[f] >= self.timeout:
                del self.running[f]
                self.started.pop(f, None)
                kill = getattr(self.pool.executor, "kill", None)
                if kill is None or not kill(f):
                    f.cancel()
                self.on_row(task, failed_row(task, timed_out(self.timeout)))

    def _collect(self) -> None:
        done, _ = wait(list(self.running), timeout=0.5, return_when=FIRST_COMPLETED)
        broken: list[tuple[RunTask, bool, BaseException]] = []
        for f in done:
            task, alone = self.running.pop(f)
            self.started.pop(f, None)
            try:
                self.on_row(task, f.result())
            except BrokenExecutor as e:
                broken.append((task, alone, e))
            except Exception as e:  # noqa: BLE001 - the executor's own failure (dask KilledWorker, ...)
                self.on_row(task, failed_row(task, one_line(e)))
        if broken:
            self._recover(broken)

    def _recover(self, broken: list[tuple[RunTask, bool, BaseException]]) -> None:
        """The pool broke: runs still held by it become suspects (a run alone is the culprit)."""
        for f, (task, alone) in list(self.running.items()):
            if f.done() and not f.cancelled() and f.exception() is None:
                self.on_row(task, f.result())  # finished just before the break
            else:
                broken.append((task, alone, BrokenExecutor("the pool broke")))
        self.running.clear()
        self.started.clear()
        renewed = self.pool.renew()
        for task, alone, e in broken:
            if alone or not renewed:
                self.on_row(
                    task, failed_row(task, WORKER_DIED if alone else f"the executor broke: {one_line(e)}")
                )
            else:
                self.suspects.append(task)
