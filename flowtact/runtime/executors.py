"""Executors by name: what runs a compiled plan, found in a table as Brian2 finds its devices.

``inproc`` is the engine with local links in this process (:mod:`flowtact.runtime.inproc`);
``processes``, the default, a supervisor and one worker per process group joined by ZeroMQ
(:mod:`flowtact.runtime.supervisor`). Each class is named as ``module:Class`` and imported on
first use (the process executor's ZeroMQ stack is not loaded by an in-process run). Another
executor is one class with a ``for_run`` constructor, added with :func:`register_executor`.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

from flowtact.running.compile import CompiledGraph

if TYPE_CHECKING:
    from flowtact.runtime.summary import RunSummary

__all__ = ["DEFAULT_EXECUTOR", "EXECUTORS", "Executor", "RunOptions", "executor_for", "register_executor"]


@dataclass(frozen=True)
class RunOptions:
    """What ``flowtact run`` asks of any executor; an executor ignores what it has no use for."""

    fast: bool = True
    tick_s: float | None = None
    recorder: Any = None
    """Where recorded streams go (:class:`~flowtact.runtime.engine.Sink`), or None."""
    progress: Callable[[float, float | None], None] | None = None
    live: Any = None
    """The live view (processes only)."""
    warn: Callable[[str], None] | None = None
    startup_s: float | None = None
    """``--startup-s``: every process group's start-up window (processes only)."""
    launched_at: float | None = None
    """When the command started (monotonic): start-up is counted from there (processes only)."""


class Executor(Protocol):
    """Runs a plan until a duration of graph time (None: until interrupted) and sums it up."""

    def run(self, duration_s: float | None) -> RunSummary: ...


class ExecutorClass(Protocol):
    def for_run(self, plan: CompiledGraph, options: RunOptions) -> Executor: ...


DEFAULT_EXECUTOR = "processes"
EXECUTORS: dict[str, str | ExecutorClass] = {
    "inproc": "flowtact.runtime.inproc:InprocExecutor",
    "processes": "flowtact.runtime.supervisor:ProcessExecutor",
}
"""Executor name -> its class, or ``module:Class`` until first used."""


def register_executor(name: str, cls: str | ExecutorClass) -> None:
    """Make ``cls`` (a class with ``for_run``, or its ``module:Class``) the executor ``name``."""
    EXECUTORS[name] = cls


def executor_for(name: str) -> ExecutorClass:
    """The executor class registered as ``name``."""
    try:
        found = EXECUTORS[name]
    except KeyError:
        raise ValueError(f"unknown executor {name!r} (known: {', '.join(sorted(EXECUTORS))})") from None
    if isinstance(found, str):
        module, _, attr = found.partition(":")
        found = EXECUTORS[name] = getattr(importlib.import_module(module), attr)
    return found
