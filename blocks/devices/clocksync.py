"""Online device-clock → host-clock alignment for cheap microcontrollers over a serial link.

A device (an Arduino, an ESP32, an emulator) puts its own tick counter in every packet; the host
knows only when it *read* each packet. Reads come late by a one-sided, variable delay (USB frames,
driver latency timers, the host's own polling tick), never early. :class:`ClockSync` turns the pairs
(device tick, host read time) into host-time stamps for the moments the device took its samples::

    t_host ≈ offset + (1 + drift) · t_dev

Method
------
*Drift* (slope): every ``drift_update_s`` of device time the points of the last ``drift_window_s``
(reduced to the lowest point of each ``bin_s`` bin) get their **lower convex hull**, and the slope
is the one of the hull edge above the window's mean device time — the linear-programming estimate
of Moon, Skelly & Towsley (1999, "Estimation and removal of clock skew from network delay
measurements"): the line that lies under every point and is as high as possible on average. One-
sided delays only ever lift points, so the hull is carried by the least-delayed packets. The slope
is clamped to ``±max_drift_ppm``; until ``min_span_s`` of data exist the previous estimate (0 at
start) is used. Its time constant is the window: a drift step is fully tracked ``drift_window_s``
later.

*Offset*: with that slope, each packet of the last ``offset_window_s`` is a candidate; the one
with the least ``u_i − (s + λ)·d_i`` wins, i.e. the least-delayed packet after an **age penalty**
``λ = age_penalty_ppm`` per second of age (NTP's "dispersion": an old packet must beat a recent
one by λ·age, because a slope error δ moves its projection by δ·age). The offset is that packet's
``u − s·d``. A monotone deque keeps this O(1) per packet (the ranking does not depend on the
current time). Time constants: the drift window (20 s) for the slope; for the offset, new
least-delayed packets take over at once and old ones fade after ``offset_window_s`` at the latest.

*Poll quantisation*: a host that reads on a fixed tick (every 5 ms) sees each packet only at the
first read after its arrival. When the device period is a multiple of the host tick, the phase
between them is locked and the lower envelope sits up to one tick late for ``tick / drift``
seconds (100 s at 50 ppm) — no estimator can see through that without more information. If the
caller also passes the time of the previous read that did *not* yet contain the packet
(``after``), each packet is bracketed in ``(after, arrival]``; the ``band_quantile`` quantile of
``after_i − line(d_i)`` over the offset window measures how far below the envelope the true line
may lie (≈ −tick when locked, ≈ 0 when the reads dither or the delays are long), and the stamp is
moved half-way into that band. That halves the worst case (tick/2) when the phase is locked and
costs ≤ (1 − band_quantile)·tick/2 when it is not. Without ``after`` no correction is made.

Every stamp is also clamped to be no later than its read time (a sample cannot be read before it
was taken). A constant delay between sampling and sending (firmware) is indistinguishable from a
clock offset: subtract it yourself if you know it.

Ticks wrap (``wrap_bits``, 32 for an Arduino ``micros()``: every 71.6 min) and are unwrapped with
modular arithmetic. A duplicate tick or a small step backwards (≤ ``max_backstep_s``) is a
reordered/duplicated packet: dropped and counted. A larger step backwards, or a packet whose
predicted host time is more than ``reset_jump_s`` away from its read time, means the device reset
(or the link was re-plugged): the estimator forgets its points and re-syncs, keeping its drift
estimate (the oscillator did not change).

``uncertainty_s`` is a scale, not a guaranteed bound: half the quantisation band when ``after`` is
given, or else the 10th percentile of the read delays above the fitted line in the offset window
(how thinly the envelope is supported), whichever is larger.
"""

from __future__ import annotations

import itertools
import math
from collections import deque
from dataclasses import dataclass

import numpy as np

__all__ = ["ClockSync", "SyncState", "lower_hull_slope"]


@dataclass(frozen=True)
class SyncState:
    """A snapshot of the estimate: ``t_host = offset_s + (1 + drift) · t_dev_s`` (device seconds since sync)."""

    offset_s: float
    drift_ppm: float
    band_s: float
    uncertainty_s: float
    n_points: int
    resyncs: int
    synced: bool


def lower_hull_slope(d: np.ndarray, u: np.ndarray, lo: float, hi: float) -> float:
    """Slope of the highest line under every point (d, u), measured at the mean of ``d``.

    ``d`` must be increasing. The lower convex hull is built (monotone chain) and the slope of its
    edge spanning ``mean(d)`` is returned, clamped to [lo, hi] (the LP skew estimate).
    """
    n = len(d)
    if n < 2:
        return min(max(1.0, lo), hi)
    hull: list[int] = []
    for i in range(n):
        while len(hull) >= 2:
            a, b = hull[-2], hull[-1]
            # keep b only if it lies strictly below the chord a→i (a left turn)
            cross = (d[b] - d[a]) * (u[i] - u[a]) - (u[b] - u[a]) * (d[i] - d[a])
            if cross <= 0:
                hull.pop()
            else:
                break
        hull.append(i)
    xm = float(np.mean(d))
    for a, b in itertools.pairwise(hull):
        if d[b] >= xm:
            slope = (u[b] - u[a]) / (d[b] - d[a])
            return min(max(float(slope), lo), hi)
    a, b = hull[-2], hull[-1]
    return min(max(float((u[b] - u[a]) / (d[b] - d[a])), lo), hi)


class ClockSync:
    """Map a device's wrapping tick counter to host time, robust to one-sided read delays.

    Parameters
    ----------
    tick_hz : ticks per device second (1e6 for a µs counter).
    wrap_bits : the counter wraps at 2**wrap_bits (None: never).
    offset_window_s, drift_window_s, drift_update_s, bin_s, min_span_s : see the module notes.
    max_drift_ppm : the largest |drift| believed (a crystal: 50; a ceramic resonator: 5000).
    max_backstep_s : a step back up to this much is a reordered packet (dropped), beyond it a reset.
    reset_jump_s : a packet predicted this far from its read time means the device clock jumped.
    band_quantile : quantile of the lower-bound residuals that sets the quantisation band.
    age_penalty_ppm : λ, seconds of presumed extra delay per second of a packet's age.

    Use :meth:`add` for each packet in arrival order; it returns the host-time stamp of the
    sample, or None for a dropped packet. Counters: ``resyncs``, ``dropped``.
    """

    def __init__(
        self,
        *,
        tick_hz: float = 1e6,
        wrap_bits: int | None = 32,
        offset_window_s: float = 10.0,
        drift_window_s: float = 20.0,
        drift_update_s: float = 0.5,
        bin_s: float = 0.1,
        min_span_s: float = 2.0,
        max_drift_ppm: float = 2000.0,
        max_backstep_s: float = 0.05,
        reset_jump_s: float = 1.0,
        band_quantile: float = 0.9,
        age_penalty_ppm: float = 30.0,
    ) -> None:
        if not (tick_hz > 0 and offset_window_s > 0 and drift_window_s > 0 and bin_s > 0):
            raise ValueError("tick_hz, windows and bin_s must be > 0")
        self.tick_hz = float(tick_hz)
        self.wrap = None if wrap_bits is None else 1 << int(wrap_bits)
        self.offset_window_s = float(offset_window_s)
        self.drift_window_s = float(drift_window_s)
        self.drift_update_s = float(drift_update_s)
        self.bin_s = float(bin_s)
        self.min_span_s = float(min_span_s)
        self.max_drift = float(max_drift_ppm) * 1e-6
        self.max_backstep = round(max_backstep_s * tick_hz)
        self.reset_jump_s = float(reset_jump_s)
        self.band_quantile = float(band_quantile)
        self.age_penalty = float(age_penalty_ppm) * 1e-6
        self.slope = 1.0  # host seconds per device second; kept across re-syncs
        self.resyncs = 0
        self.dropped = 0
        self._restart()
        self.resyncs = 0

    # -- state ------------------------------------------------------------------------------------
    def _restart(self) -> None:
        self._raw: int | None = None  # last raw tick
        self._ticks = 0  # unwrapped ticks since the sync epoch
        self.epoch_tick = 0  # the raw tick at the sync epoch (the first packet after a sync)
        self._recent: deque[tuple[float, float, float]] = deque()  # (d, u, after) in the offset window
        self._mins: deque[tuple[float, float, float]] = deque()  # monotone deque of (d, rank, u)
        self._bins: deque[list[float]] = deque()  # [bin index, d, u] lowest point per bin
        self._next_update = self.drift_update_s
        self.band_s = 0.0
        self.spread_s = 0.0
        self.resyncs += 1

    def resync(self) -> None:
        """Forget every point (a reconnect, a device reset); the drift estimate is kept."""
        self._restart()

    @property
    def synced(self) -> bool:
        """True once at least one packet was added since the last (re-)sync."""
        return self._raw is not None

    @property
    def offset_s(self) -> float:
        """Host time of the sync epoch (device time 0) as currently estimated."""
        if not self._mins:
            return math.nan
        d, _, u = self._mins[0]
        return u - self.slope * d

    @property
    def ticks(self) -> int:
        """Unwrapped ticks of the last accepted packet since the sync epoch."""
        return self._ticks

    @property
    def drift_ppm(self) -> float:
        return (self.slope - 1.0) * 1e6

    @property
    def uncertainty_s(self) -> float:
        return max(-self.band_s / 2.0, self.spread_s)

    def state(self) -> SyncState:
        """The current estimate, for logs and tests."""
        return SyncState(
            offset_s=self.offset_s,
            drift_ppm=self.drift_ppm,
            band_s=self.band_s,
            uncertainty_s=self.uncertainty_s,
            n_points=len(self._recent),
            resyncs=self.resyncs,
            synced=self.synced,
        )

    # -- the estimator ------------------------------------------------------------------------
    def unwrap(self, tick: int) -> int | None:
        """Ticks since the sync epoch for this raw tick, or None if it is a duplicate/reordered one.

        Resets (and re-syncs) on a large step backwards. Does not add a point.
        """
        tick = int(tick)
        if self._raw is None:
            return 0
        delta = tick - self._raw
        if self.wrap is not None:
            delta %= self.wrap
            if delta >= self.wrap // 2:
                delta -= self.wrap
        if delta <= 0:
            if -delta <= self.max_backstep:
                return None
            return -1  # a reset
        return self._ticks + delta

    def to_host(self, d_s: float) -> float:
        """Host time of device time ``d_s`` (seconds since the sync epoch), with the band correction."""
        return self.offset_s + self.slope * d_s + self.band_s / 2.0

    def add(self, tick: int, arrival: float, after: float | None = None) -> float | None:
        """Add a packet read at host time ``arrival`` (not yet there at host time ``after``).

        Returns the host-time stamp of its sample, or None if it was dropped as a duplicate or
        reordered packet (counted in ``dropped``).
        """
        ticks = self.unwrap(tick)
        if ticks is None:
            self.dropped += 1
            return None
        if ticks < 0 or (
            self._mins
            and abs(arrival - (self.offset_s + self.slope * ticks / self.tick_hz)) > self.reset_jump_s
        ):
            self._restart()
            ticks = 0
        self._raw = int(tick)
        self._ticks = ticks
        d = ticks / self.tick_hz
        u = float(arrival)
        a = float("nan") if after is None else float(after)
        self._recent.append((d, u, a))
        while self._recent[0][0] < d - self.offset_window_s:
            self._recent.popleft()
        self._push_min(d, u)
        self._push_bin(d, u)
        if d >= self._next_update:
            self._update(d)
        return min(self.to_host(d), u)

    def _push_min(self, d: float, u: float) -> None:
        v = u - (self.slope + self.age_penalty) * d
        mins = self._mins
        while mins and mins[-1][1] >= v:
            mins.pop()
        mins.append((d, v, u))
        while mins[0][0] < d - self.offset_window_s:
            mins.popleft()

    def _push_bin(self, d: float, u: float) -> None:
        k = math.floor(d / self.bin_s)
        bins = self._bins
        if bins and bins[-1][0] == k:
            if u - d < bins[-1][2] - bins[-1][1]:
                bins[-1][1], bins[-1][2] = d, u
        else:
            bins.append([k, d, u])
        while bins[0][1] < d - self.drift_window_s:
            bins.popleft()

    def _update(self, d_now: float) -> None:
        """Re-estimate the slope (hull), rebuild the offset minimum, update band and spread."""
        self._next_update = d_now + self.drift_update_s
        if len(self._bins) >= 3 and self._bins[-1][1] - self._bins[0][1] >= self.min_span_s:
            bd = np.array([b[1] for b in self._bins])
            bu = np.array([b[2] for b in self._bins])
            self.slope = lower_hull_slope(bd, bu, 1.0 - self.max_drift, 1.0 + self.max_drift)
        self._mins.clear()
        for d, u, _ in self._recent:
            self._push_min(d, u)
        rec = np.array(self._recent)
        line = self.offset_s + self.slope * rec[:, 0]
        self.spread_s = float(np.quantile(rec[:, 1] - line, 0.1))
        has = np.isfinite(rec[:, 2])
        if has.sum() >= 20:
            gap = float(np.median(rec[has, 1] - rec[has, 2]))
            g = float(np.quantile(rec[has, 2] - line[has], self.band_quantile))
            self.band_s = min(0.0, max(g, -gap))
        else:
            self.band_s = 0.0
