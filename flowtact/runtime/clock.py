"""Graph clocks: the runtime, never a block, decides when graph time advances.

Graph time is seconds since the run started, advanced in ticks ``now = k * tick_s`` from an
integer counter. ``fast`` runs ticks back to back; ``realtime`` waits until the wall clock
reaches each tick.
"""

from __future__ import annotations

import os
import time

__all__ = [
    "DEFAULT_TICK_FAST_S",
    "DEFAULT_TICK_REALTIME_S",
    "LAG_WARN_S",
    "Clock",
    "FastClock",
    "RealtimeClock",
    "process_started_at",
    "tick_for",
]

DEFAULT_TICK_FAST_S = 1.0
DEFAULT_TICK_REALTIME_S = 0.005
LAG_WARN_S = 0.1
"""A real-time run whose ticks ran this late (or later) was not real time: warned, and said so."""


def process_started_at() -> float | None:
    """When this process started, on :func:`time.monotonic`'s clock: the launch a start-up is
    counted from. From /proc (Linux, 10 ms resolution); None where that cannot be read."""
    try:
        with open("/proc/self/stat", "rb") as f:
            fields = f.read().rsplit(b")", 1)[1].split()
        started = int(fields[19]) / os.sysconf("SC_CLK_TCK")  # starttime: field 22, since boot
        age = time.clock_gettime(time.CLOCK_BOOTTIME) - started
    except (OSError, ValueError, IndexError, AttributeError):
        return None
    return time.monotonic() - age if 0 <= age < 86_400 * 365 else None


def tick_for(fast: bool, tick_s: float | None) -> float:
    """The tick a run uses: ``tick_s`` when given, else 1 s on the virtual clock, 5 ms in real time."""
    tick = tick_s or (DEFAULT_TICK_FAST_S if fast else DEFAULT_TICK_REALTIME_S)
    if not tick > 0:
        raise ValueError("tick_s must be > 0")
    return tick


class Clock:
    """Paces ticks; ``wait_until(now)`` returns when graph time ``now`` may be processed."""

    def __init__(self) -> None:
        self._t0 = time.perf_counter()

    def start(self) -> None:
        """Graph time 0 is now."""
        self._t0 = time.perf_counter()

    def wait_until(self, now: float) -> float:
        """Wait for graph time ``now``; how late it came (s, 0 when on time)."""
        raise NotImplementedError

    def elapsed(self) -> float:
        """Wall seconds since start."""
        return time.perf_counter() - self._t0


class FastClock(Clock):
    """As fast as possible: a tick is processed as soon as the previous one is done."""

    def wait_until(self, now: float) -> float:  # noqa: ARG002 — a virtual clock never waits
        return 0.0


class RealtimeClock(Clock):
    """Ticks follow the wall clock (a tick that runs late is processed at once, never skipped)."""

    def wait_until(self, now: float) -> float:
        delay = now - self.elapsed()
        if delay > 0:
            time.sleep(delay)
            return 0.0
        return -delay
