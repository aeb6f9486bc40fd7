"""LSL time ↔ graph time, for the LSL blocks of one process.

Two steps map an LSL timestamp (stamped on the sending machine's ``lsl_local_clock``) onto the
graph clock:

1. *Remote → local LSL clock*: add the clock offset LSL measures (``inlet.time_correction()``, an
   NTP-like probe liblsl repeats every few seconds). :class:`OffsetFit` fits a line through the
   readings (least squares over the last ``window`` ones), so the offset at any instant is
   predicted with the *drift* (slope, reported in ppm) between the two clocks, not just the last
   reading. One machine: offset and drift are ~0 (the same clock), as the tests check.
2. *Local LSL clock → graph time*: ``t = local − anchor``. The anchor is graph time 0 on the LSL
   clock, measured once per run and process as ``local_clock() − now`` at the first step of any
   LSL block (:class:`Anchor`): a step runs at or after its graph time, so the anchor is late by
   that first step's lateness (typically well under a tick; reported). Every LSL block of the
   process uses the same anchor, so a sample read by an inlet and republished by an outlet of the
   same process leaves with exactly its incoming LSL time.
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

    Blocks ``acquire`` it in ``open`` and ``release`` it in ``close``; the first ``at(now)`` after
    the first acquire measures it, and it is forgotten when the last holder releases it (the next
    run in the same process measures its own).
    """

    def __init__(self, clock: Callable[[], float]) -> None:
        self._clock = clock
        self._lock = threading.Lock()
        self._holders = 0
        self._value: float | None = None
        self.lateness = math.inf  # least (local − now − anchor) seen: how late steps run at best

    def acquire(self) -> None:
        with self._lock:
            self._holders += 1

    def release(self) -> None:
        with self._lock:
            self._holders = max(0, self._holders - 1)
            if self._holders == 0:
                self._value = None
                self.lateness = math.inf

    def at(self, now: float) -> float:
        """The anchor (measured at the first call of the run); also tracks the steps' lateness."""
        local = self._clock()
        with self._lock:
            if self._value is None:
                self._value = local - now
            self.lateness = min(self.lateness, local - now - self._value)
            return self._value


def _local_clock() -> float:
    import pylsl

    return float(pylsl.local_clock())


#: This process's anchor on the LSL clock.
anchor = Anchor(_local_clock)
