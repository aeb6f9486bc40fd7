"""The supervisor's view of its worker processes: one :class:`Proc` per process group, how a
failure is told, and the windows and periods of supervision."""

from __future__ import annotations

import math
import subprocess
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import zmq

from flowtact.runtime.forked import ForkedWorker
from flowtact.runtime.protocol import Beat, ErrorReport, Stats

__all__ = ["Proc", "describe_failure", "stop_tick"]

PING_S = 0.25
WATCH_S = 0.02
"""Exits and stalls of workers are looked for this often (the pump also wakes for every message)."""
WARMUP_S = 1.0
"""CPU is reported over the running phase after this warm-up (JIT compilation, first allocations)."""
STOP_MARGIN_S = 0.25
"""A stop ends on the tick this far (in wall time) ahead of the furthest worker: it reaches them first."""
DEADLINE_WARN_EVERY_S = 5.0
"""Deadline misses are told at the first one, then at most this often (with their count)."""
WAITING_EVERY_S = 15.0
"""How often the run repeats that it is waiting for a worker on another host."""
LAST_WORDS_S = 0.2
"""After a worker exits, how long its last control messages (an error report) may take to arrive."""
SILENT_PROBE_S = 0.3
"""How long a worker without progress has its CPU time watched, to tell a hung process from a busy one."""
IDLE_CPU = 0.05
"""A worker without progress that uses less than this share of a core is not working: it has stalled."""


def stop_tick(procs: Iterable[Any], now: float, wall_s: float | None, tick_s: float) -> int:
    """The tick every worker ends on after Ctrl-C: one past the furthest any can have reached.

    No worker may have started a tick past the stop tick when the stop reaches it: in a loop
    through several processes one would wait inside that tick for a peer that stopped. Each
    worker's reach is extrapolated from its heartbeats (``last_k``, its ``tick_rate`` lately,
    :data:`STOP_MARGIN_S` ahead). In real time (``wall_s``: seconds since graph time 0) no worker
    runs ahead of the wall clock, so that bounds it: workers far behind the clock stop near where
    they are instead of first computing their whole backlog (an overloaded whole hand, seconds
    behind, would not drain within its stop grace). Before every worker's rate is measured, the
    clock alone bounds it. ``--fast`` (``wall_s`` None): the heartbeats alone.
    """
    procs = list(procs)
    reach = max((p.last_k + p.tick_rate * (now - p.beat_at + STOP_MARGIN_S) for p in procs), default=0.0)
    if wall_s is not None:
        wall = (wall_s + STOP_MARGIN_S) / tick_s
        reach = min(reach, wall) if all(p.tick_rate > 0 for p in procs) else max(reach, wall)
    return math.ceil(reach) + 1


@dataclass
class Proc:
    """One process group as the supervisor sees it: its definition, its process and what it reported."""

    name: str
    nodes: list[str]
    host: str | None
    restart: str
    max_restarts: int
    stall_s: float
    startup_s: float
    stop_grace_s: float
    popen: subprocess.Popen[bytes] | ForkedWorker | None = None
    spawned_at: float = 0.0  # when its process was started (monotonic)
    hello_at: float = 0.0  # when its first message arrived
    ready_at: float = 0.0  # when it said ready (warm, inputs bound)
    setup: dict[str, float] = field(default_factory=dict)  # its own start-up parts (s): build, warm_up, bind
    ident: bytes | None = None
    sock: zmq.Socket | None = None
    pid: int | None = None
    state: str = "starting"
    restarts: int = 0
    endpoints: dict[int, str] = field(default_factory=dict)
    stats: Stats = field(default_factory=Stats)
    """Its latest statistics (``Stats()`` before any)."""
    warm: tuple[float, int] | None = None  # (cpu_s, wall_ns) at the end of the warm-up
    cpu_pct: float | None = None
    done: bool = False
    rec_done: bool = False
    counters: dict[str, dict[str, int]] = field(default_factory=dict)
    summaries: dict[str, str] = field(default_factory=dict)
    """What its blocks said of the run (``Block.summary``), per node, sent with ``done``."""
    wired: bool = False
    last_k: int = 0
    violations: dict[str, int] = field(default_factory=dict)
    since: float = 0.0  # when it was (re)started or started running: the clock of its windows
    beat_at: float = 0.0  # when its last heartbeat arrived
    beat: Beat | None = None  # its last heartbeat
    busy_since: float = 0.0  # since when its current step (same node, same step count) runs
    next_waiting: float = math.inf  # when to repeat that the run waits for it (another host)
    tick_rate: float = 0.0  # ticks per second lately (from heartbeats)
    silent_mark: tuple[float, float] | None = None  # (when, CPU seconds) as its heartbeats fell silent
    progress_at: float = 0.0  # when it last showed start-up progress
    progress: Any = None  # its last start-up progress report (or CPU seconds before its first message)
    phase: str = "starting its interpreter"  # its last reported start-up phase

    def describe(self) -> str:
        where = f" on {self.host}" if self.host else ""
        return f"process '{self.name}'{where} (nodes {', '.join(self.nodes)})"


def describe_failure(proc: Proc, report: ErrorReport) -> str:
    """``node 'sa1' (nlif) in process 'neurons' failed at t=1.234 s: ...`` or a dead process."""
    if report.node:
        return (
            f"node '{report.node}' ({report.block}) failed at t={report.now or 0.0:.3f} s "
            f"in process '{proc.name}': {report.message}"
        )
    return f"process '{proc.name}' (nodes {', '.join(proc.nodes)}) {report.message}"
