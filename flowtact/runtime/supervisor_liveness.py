"""The supervisor's liveness checks: heartbeats, exits, stalls (a hung process told from a busy one), overload.

Part of :class:`flowtact.runtime.supervisor.ProcessExecutor` (which holds the state these methods share).
"""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

from flowtact.errors import ProcessFailure
from flowtact.runtime.clock import LAG_WARN_S
from flowtact.runtime.protocol import Beat, ErrorReport
from flowtact.runtime.stats import format_factor
from flowtact.runtime.supervisor_procs import (
    IDLE_CPU,
    LAST_WORDS_S,
    SILENT_PROBE_S,
    Proc,
)

__all__ = ["SupervisorLiveness", "proc_stat", "tick_rate"]


class SupervisorLiveness:
    """Liveness of a :class:`~flowtact.runtime.supervisor.ProcessExecutor`'s workers."""

    def _on_beat(self, proc: Proc, beat: Beat) -> None:
        now = time.monotonic()
        old = proc.beat
        if beat.node is None or old is None or beat.node != old.node or beat.steps != old.steps:
            proc.busy_since = now  # waiting, or a new step: progress
            proc.silent_mark = None
        if old is not None:  # ticks per second, for where a stop can reach it
            proc.tick_rate = max(tick_rate(old, beat), 0.5 * proc.tick_rate)  # slow to forget a fast spell
        proc.beat, proc.beat_at = beat, now
        if proc.state != "running":
            proc.phase = beat.phase or proc.phase
            if beat.progress != proc.progress:  # start-up advances: its window restarts
                proc.progress, proc.progress_at = beat.progress, now
        self.compiles.on_beat(proc.name, proc.describe(), proc.state == "running", beat)
        proc.last_k = max(proc.last_k, beat.k)

    def _watch(self) -> None:
        """Notice a worker process that exited without saying done (after its last words)."""
        for p in self.procs.values():
            if p.popen is None or p.done:
                continue
            code = p.popen.poll()
            if code is None:
                continue
            deadline = time.monotonic() + LAST_WORDS_S  # an error report may still be in flight
            while not p.done and time.monotonic() < deadline:
                self._poll(20)
            if p.done:
                continue
            cause = f"killed by {signal.Signals(-code).name}" if code < 0 else f"exited with status {code}"
            raise ProcessFailure(p, ErrorReport(cause))

    def _check_liveness(self) -> None:
        """A running worker that shows no progress for ``stall_s`` has stalled.

        No progress: its heartbeats stopped, or the node it steps has not returned. A worker on
        this host is then asked of the kernel: stopped (``kill -STOP``) or idle (blocked in a call)
        is a stall; burning CPU (a long computation, or kernels loading while they hold the
        interpreter so the heartbeat thread cannot run) is given the start-up window first. A worker
        on another host is judged by its heartbeats alone.
        """
        now = time.monotonic()
        for p in self.procs.values():
            if p.state != "running" or p.done:
                continue
            window = p.startup_s if p.beat is None or p.beat.first else p.stall_s
            node = p.beat.node if p.beat is not None else None
            quiet = now - p.beat_at
            stuck = now - p.busy_since if node else 0.0
            if max(quiet, stuck) <= window:
                continue
            why = self._why_stalled(p, now, max(quiet, stuck))
            if why is None:
                continue
            what = (
                f"no heartbeat for {quiet:.1f} s" + (f" inside node '{node}'" if node else "")
                if quiet > window
                else f"node '{node}' has not returned from its step for {stuck:.1f} s"
            )
            raise ProcessFailure(
                p,
                ErrorReport(
                    f"stalled at tick {p.last_k} (t={p.last_k * self.tick_s:.3f} s): {what}, {why} "
                    f"(stall_s {window:g} s)"
                ),
                stalled=True,
            )

    def _why_stalled(self, p: Proc, now: float, idle_for: float) -> str | None:
        """Why a worker without progress counts as stalled now, or None while it may be working."""
        seen = proc_stat(p.pid) if p.host is None and p.pid is not None else None
        if seen is None:  # another host, or no /proc
            return "stopped, hung or starved"
        state, cpu_s = seen
        if state == "T":
            return "its process is stopped (SIGSTOP)"
        if p.silent_mark is None:
            p.silent_mark = (now, cpu_s)
            return None
        t_mark, cpu_mark = p.silent_mark
        if now - t_mark < SILENT_PROBE_S:
            return None
        if (cpu_s - cpu_mark) / (now - t_mark) < IDLE_CPU:
            return "and its process is idle (blocked in a call, or waiting on something that never comes)"
        if idle_for > p.startup_s:
            return f"while computing (longer than startup_s, {p.startup_s:g} s)"
        return None

    def _check_overload(self) -> None:
        """Warn once when a real-time run falls behind its clock, naming the busiest nodes."""
        if self.fast or self.late:
            return
        lagging = [p for p in self.procs.values() if p.stats.max_lag_s > LAG_WARN_S]
        if not lagging:
            return
        worst = max(lagging, key=lambda p: p.stats.max_lag_s)
        wall = max((worst.stats.wall_ns - self.t0_ns) / 1e9, 1e-9)
        share = {n: ns / 1e9 / wall for p in self.procs.values() for n, ns in p.stats.node_ns.items()}
        self.late = sorted(share, key=share.get, reverse=True)[:3]  # type: ignore[arg-type]
        busiest = ", ".join(f"{n} {100 * share[n]:.0f} %" for n in self.late)
        self.warn(
            f"falling behind real time: {worst.describe()} ran {worst.stats.max_lag_s:.2f} s late by "
            f"t={worst.stats.now:.2f} s (real-time factor {format_factor(worst.stats.now / wall)}); "
            f"busiest nodes (share of wall time in their steps): {busiest}"
        )


def proc_stat(pid: int) -> tuple[str, float] | None:
    """Linux: a process' state letter and CPU seconds (user + system), or None where unknown."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None
    return fields[0], (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def tick_rate(old: Beat, beat: Beat) -> float:
    """Ticks per second between two heartbeats, timed by the worker that sent them: on a loaded
    machine beats queue and arrive together, and their arrival times would make a rate of
    millions of ticks per second (and a stop tick minutes ahead of every worker)."""
    dt = (beat.sent_ns - old.sent_ns) / 1e9
    return max(beat.k - old.k, 0) / dt if dt > 0 else 0.0
