"""Latency histograms that every worker keeps cheaply and sends in its heartbeats.

:class:`LatencyHistogram` counts latencies (ns in, µs out) in fixed log-spaced buckets from 1 µs
to 100 s, each at most 1 % wide, so that p50/p99 come out within 1 % of the exact values at a
fixed memory cost, histograms from several workers or heartbeats merge by adding counts, and a
heartbeat carries only the non-zero buckets. ``add`` runs once per message: it costs one
``math.log`` and one increment of a plain ``array.array`` (the numpy ``counts`` array is a view
of the same memory), with no numpy call per sample.
(CPU per process comes from each worker's own ``time.process_time()`` in its heartbeats.)
"""

from __future__ import annotations

import array
import math
from typing import Any

import numpy as np

__all__ = ["BUCKETS", "LatencyHistogram", "format_factor"]

_LO_NS = 1_000.0
"""Lower edge of the first bucket: 1 µs."""
_HI_NS = 100e9
"""Upper edge of the last bucket: 100 s."""
BUCKETS = math.ceil(math.log(_HI_NS / _LO_NS) / math.log(1.01))
"""Number of buckets: each spans a ratio of ``(HI/LO) ** (1/BUCKETS)`` <= 1.01."""
_LOG_LO = math.log(_LO_NS)
_STEP = math.log(_HI_NS / _LO_NS) / BUCKETS
"""Width of one bucket in natural-log units."""
_SCALE = 1.0 / _STEP
_LAST = BUCKETS - 1
_NO_MIN = 1 << 62
_NO_MAX = -(1 << 62)
"""Sentinels for the min/max of an empty histogram (so ``add`` needs no None test)."""


def _centre_us(index: int | np.ndarray) -> Any:
    """Geometric centre of bucket ``index``, in µs."""
    return _LO_NS * np.exp((np.asarray(index) + 0.5) * _STEP) / 1e3


class LatencyHistogram:
    """Latencies in fixed log-spaced buckets (1 µs .. 100 s, <= 1 % wide) with exact n/min/max/sum.

    Samples are integers in **nanoseconds**; results are in **microseconds**. Samples below 1 µs
    (including zero and negative ones, e.g. from clock skew between hosts) count in the first
    bucket, samples above 100 s in the last; percentiles are clamped to the exact ``[min, max]``.
    """

    __slots__ = ("_buf", "_max", "_min", "counts", "n", "sum")

    def __init__(self) -> None:
        self._buf = array.array("q", bytes(8 * BUCKETS))
        self.counts: np.ndarray = np.frombuffer(self._buf, dtype=np.int64)
        """Count per bucket (a writable view of the buffer ``add`` increments)."""
        self.n = 0
        """Number of samples."""
        self.sum = 0
        """Exact sum of the samples (ns)."""
        self._min = _NO_MIN
        self._max = _NO_MAX

    @property
    def min(self) -> int | None:
        """Smallest sample (ns), None when empty."""
        return self._min if self.n else None

    @property
    def max(self) -> int | None:
        """Largest sample (ns), None when empty."""
        return self._max if self.n else None

    def add(self, ns: int) -> None:
        """Count one latency of ``ns`` nanoseconds."""
        if ns < _LO_NS:
            i = 0
        else:
            i = int((math.log(ns) - _LOG_LO) * _SCALE)
            if i > _LAST:
                i = _LAST
        self._buf[i] += 1
        self.n += 1
        self.sum += ns
        if ns < self._min:
            self._min = ns
        if ns > self._max:
            self._max = ns

    def add_many(self, ns: np.ndarray) -> None:
        """Count every latency (ns) in ``ns`` (any shape; integers, or floats in ns)."""
        a = np.asarray(ns).ravel()
        if a.size == 0:
            return
        f = a.astype(np.float64)
        idx = np.zeros(a.size, np.intp)
        above = f >= _LO_NS
        idx[above] = np.minimum(((np.log(f[above]) - _LOG_LO) * _SCALE).astype(np.intp), _LAST)
        self.counts += np.bincount(idx, minlength=BUCKETS)
        self._merge_exact(int(a.size), int(a.sum()), int(a.min()), int(a.max()))

    def _merge_exact(self, n: int, total: int, lo: int | None, hi: int | None) -> None:
        if n == 0:
            return
        if lo is None or hi is None:
            raise ValueError("a non-empty latency histogram needs its min and max")
        self.n += n
        self.sum += total
        self._min = min(self._min, lo)
        self._max = max(self._max, hi)

    def merge(self, other: LatencyHistogram) -> None:
        """Add ``other``'s samples to this histogram (``other`` is unchanged)."""
        self.counts += other.counts
        self._merge_exact(other.n, other.sum, other.min, other.max)

    def reset(self) -> None:
        """Forget every sample (e.g. at the start of a new reporting window)."""
        self.counts[:] = 0
        self.n = 0
        self.sum = 0
        self._min = _NO_MIN
        self._max = _NO_MAX

    def percentile(self, q: float) -> float | None:
        """The ``q``-th percentile (0..100) in µs, or None when empty.

        The value is the geometric centre of the bucket holding the sample of rank
        ``q/100 * (n-1)`` (within 0.5 % of it), clamped to the exact min and max; ``q <= 0`` gives
        the min and ``q >= 100`` the max.
        """
        if self.n == 0:
            return None
        if q <= 0:
            return self._min / 1e3
        if q >= 100:
            return self._max / 1e3
        rank = math.floor(q / 100.0 * (self.n - 1))
        i = int(np.searchsorted(np.cumsum(self.counts), rank, side="right"))
        centre = float(_centre_us(min(i, _LAST)))
        return min(max(centre, self._min / 1e3), self._max / 1e3)

    def summary(self) -> dict[str, float | int | None]:
        """``{"p50", "p99", "max", "mean"}`` in µs (None when empty) and the count ``n``."""
        if self.n == 0:
            return {"p50": None, "p99": None, "max": None, "mean": None, "n": 0}
        return {
            "p50": self.percentile(50),
            "p99": self.percentile(99),
            "max": self._max / 1e3,
            "mean": self.sum / self.n / 1e3,
            "n": self.n,
        }

    def to_wire(self) -> list:
        """A compact msgpack-friendly form: ``[n, sum, min, max, [index, count, index, count, ...]]``.

        Only non-zero buckets are listed; every value is a plain Python int (or None).
        """
        nz = np.flatnonzero(self.counts)
        pairs = np.empty(2 * nz.size, np.int64)
        pairs[0::2] = nz
        pairs[1::2] = self.counts[nz]
        return [self.n, self.sum, self.min, self.max, pairs.tolist()]

    @classmethod
    def from_wire(cls, obj: list | tuple) -> LatencyHistogram:
        """Rebuild a histogram from :meth:`to_wire`'s output (raises ValueError when malformed)."""
        try:
            n, total, lo, hi, pairs = obj
            flat = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
        except (TypeError, ValueError) as e:
            raise ValueError(f"not a latency histogram: {obj!r:.80}") from e
        if flat.size and (flat[:, 0].min() < 0 or flat[:, 0].max() > _LAST or flat[:, 1].min() < 0):
            raise ValueError("latency histogram bucket index or count out of range")
        if int(flat[:, 1].sum()) != n:
            raise ValueError(f"latency histogram counts sum to {int(flat[:, 1].sum())}, not n={n}")
        h = cls()
        np.add.at(h.counts, flat[:, 0], flat[:, 1])
        h._merge_exact(int(n), int(total), lo, hi)
        return h

    def __repr__(self) -> str:
        s = self.summary()
        return f"LatencyHistogram(n={s['n']}, p50={s['p50']}, p99={s['p99']}, max={s['max']} µs)"


def format_factor(factor: float) -> str:
    """A real-time factor with two significant digits and a ×: ``0.13×``, ``1.0×``, ``25×``, ``1,200×``.

    Every place that shows a run's speed (summary, live view, the overload warning) uses this, so a
    0.13× run never reads "0x".
    """
    if math.isnan(factor):
        return "?×"
    if math.isinf(factor):
        return "∞×"
    if factor <= 0:
        return "0×"
    r = float(f"{factor:.2g}")  # two significant digits, rounded once (9.96 -> 10)
    if r >= 10:
        return f"{r:,.0f}×"
    return f"{r:.{1 - math.floor(math.log10(r))}f}×"
