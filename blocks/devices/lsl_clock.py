"""LSL time ↔ graph time, for the LSL blocks of one process.

Two steps map an LSL timestamp (stamped on the sending machine's ``lsl_local_clock``) onto the
graph clock:

1. *Remote → local LSL clock*: add the clock offset LSL measures (``inlet.time_correction()``, an
   NTP-like probe liblsl repeats every few seconds). :class:`OffsetFit` fits a line through the
   readings (least squares over the last ``window`` ones), so the offset at any instant is
   predicted with the *drift* (slope, reported in ppm) between the two clocks, not just the last
   reading. One machine: offset and drift are ~0 (the same clock), as the tests check.
2. *Local LSL clock → graph time*: ``t = local − anchor``. The anchor is graph time 0 on the LSL
   clock, shared by the LSL blocks of one process during a run (:class:`Anchor`). A step runs at
   or after its graph time, so every step gives an upper bound ``local_clock() − now``; the
   anchor is the least of them seen so far (as ``serial_io``'s clock): a first step that came
   seconds late (a loaded worker catching up with merged ticks) no longer shifts the whole run,
   the anchor comes down at the first step that runs on time. What remains is the least
   lateness, bounded by the time from the last ``open`` to that step (the summary reports both).

   Samples mapped before the anchor came down keep the older anchor: an inlet's samples already
   emitted stay stamped early by the move (an inlet re-maps the ones it still holds), later ones
   carry the settled anchor, so emitted times stay increasing (the move only raises them). A
   sample read by an inlet and republished by an outlet of the same process leaves with exactly
   its incoming LSL time once the anchor has settled; one mapped before a move and published
   after it leaves early by that move (at most the first step's excess lateness, reported).
"""

from __future__ import annotations

import math
import threading
from collections import deque
from collections.abc import Callable

import numpy as np

__all__ = ["Anchor", "OffsetFit", "anchor"]


class OffsetFit:
    """Offset of a remote clock (seconds to add to its stamps) as a line over local time."""

    def __init__(self, window: int = 64) -> None:
        self._pts: deque[tuple[float, float]] = deque(maxlen=window)
        self._slope = 0.0
        self._at = 0.0
        self._value = 0.0

    def add(self, local_t: float, offset: float) -> None:
        """A reading: at local time ``local_t`` the remote clock was ``offset`` behind."""
        if not (math.isfinite(local_t) and math.isfinite(offset)):
            return
        self._pts.append((local_t, offset))
        ts = np.array([p[0] for p in self._pts])
        cs = np.array([p[1] for p in self._pts])
        self._at = float(ts.mean())
        self._value = float(cs.mean())
        span = float(ts[-1] - ts[0])
        if len(ts) >= 3 and span > 0:
            dt = ts - self._at
            self._slope = float((dt * (cs - self._value)).sum() / (dt * dt).sum())
        else:
            self._slope = 0.0

    @property
    def readings(self) -> int:
        return len(self._pts)

    @property
    def drift_ppm(self) -> float:
        """The remote clock's rate error against ours (ppm; positive: it runs fast, so the offset
        to add to its stamps falls)."""
        return -self._slope * 1e6

    def offset(self, local_t: float | np.ndarray) -> float | np.ndarray:
        """The offset predicted at local time ``local_t`` (0 before any reading)."""
        return self._value + self._slope * (local_t - self._at)

    def to_local(self, remote_t: np.ndarray) -> np.ndarray:
        """Remote stamps on the local clock: the line is over local time, so it is read where the
        stamp lands (the mean offset first; the two clocks may be hours apart, the drift tiny)."""
        return remote_t + self.offset(remote_t + self._value)


class Anchor:
    """Graph time 0 on the LSL clock, shared by the LSL blocks of this process during one run.

    Blocks ``acquire`` it in ``open`` and ``release`` it in ``close``; every ``at(now)`` lowers it
    to the least ``local_clock() − now`` seen (a step is never early, so that is the best
    estimate), and it is forgotten when the last holder releases it (the next run in the same
    process measures its own).
    """

    def __init__(self, clock: Callable[[], float]) -> None:
        self._clock = clock
        self._lock = threading.Lock()
        self._holders = 0
        self._value: float | None = None
        self._first = math.nan
        self._opened = -math.inf

    def acquire(self) -> None:
        """A block opened: graph time 0 comes after this (it bounds the anchor's error)."""
        local = self._clock()
        with self._lock:
            self._holders += 1
            self._opened = max(self._opened, local)

    def release(self) -> None:
        with self._lock:
            self._holders = max(0, self._holders - 1)
            if self._holders == 0:
                self._value = None
                self._first = math.nan
                self._opened = -math.inf

    def at(self, now: float) -> float:
        """The anchor after this step: the least ``local_clock() − now`` of the run so far."""
        local = self._clock()
        with self._lock:
            if self._value is None:
                self._value = self._first = local - now
            else:
                self._value = min(self._value, local - now)
            return self._value

    @property
    def moved(self) -> float:
        """How far the anchor came down after the first step (s): how much later than the best
        step the first one ran (0 before any step)."""
        with self._lock:
            return 0.0 if self._value is None else self._first - self._value

    @property
    def late_at_most(self) -> float:
        """A bound on the anchor's remaining error, the best step's lateness (s): graph time 0
        comes after every ``open``, so that is at most the anchor minus the LSL clock at the last
        ``open`` (inf before any step)."""
        with self._lock:
            if self._value is None or not math.isfinite(self._opened):
                return math.inf
            return max(0.0, self._value - self._opened)


def _local_clock() -> float:
    import pylsl

    return float(pylsl.local_clock())


#: This process's anchor on the LSL clock.
anchor = Anchor(_local_clock)
