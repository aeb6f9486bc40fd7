"""Bounded-memory reads of a recording for plotting: block by block, never a whole stream at once.

Every reader here touches at most :data:`BLOCK_BYTES` of samples at a time and returns at most a
few thousand points per channel (min-max envelopes, change points, binned counts, or a handful
of frames), so plotting a recording takes the same memory whatever its size.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from flowtact.chunk import StreamSpec
from flowtact.errors import RecordingCorrupted
from flowtact.inputs.safe_text import shown
from flowtact.recording.hdf5 import open_verified, spec_from_attrs

__all__ = [
    "BLOCK_BYTES",
    "Envelope",
    "StreamSource",
    "binned_event_counts",
    "change_points",
    "event_points",
    "frames_at",
    "index_range",
    "label",
    "open_recording",
    "sample_envelope",
]

#: Most bytes of samples (as float64) held at once while reading a stream.
BLOCK_BYTES = 4 * 1024 * 1024


@dataclass(frozen=True)
class StreamSource:
    """One recorded stream, open for reading: its spec, sample count, end time and datasets."""

    name: str
    spec: StreamSpec
    n: int
    end_s: float | None
    t: h5py.Dataset
    data: h5py.Dataset

    @property
    def last_t(self) -> float | None:
        """The last sample's (or event's) time, if any."""
        return float(self.t[self.n - 1]) if self.n else None


#: Longest text from the file drawn in a title, label or tick (the rest is cut, its length said).
LABEL_CHARS = 80


def label(text: object) -> str:
    """Text from the file as matplotlib draws it, as data: control characters escaped (no glyph
    warnings carrying them to the terminal), cut to :data:`LABEL_CHARS`, ``$`` escaped (no mathtext)."""
    return shown(text, limit=LABEL_CHARS).replace("$", r"\$")


def _shown_spec(spec: StreamSpec) -> StreamSpec:
    """``spec`` with its texts (units, labels, categories) made safe to draw."""

    def names(values: tuple[object, ...] | None) -> tuple[str, ...] | None:
        return None if values is None else tuple(label(v) for v in values)

    return dataclasses.replace(
        spec, units=label(spec.units), labels=names(spec.labels), categories=names(spec.categories)
    )


def open_recording(path: str | Path) -> tuple[h5py.File, dict[str, StreamSource], dict[str, object]]:
    """The open file, its streams (in recorded order, keyed by their names as recorded) and its
    root attributes; every text a stream carries (name, units, labels) is made safe to draw
    (:func:`label`). The caller closes the file."""
    f = open_verified(path)
    try:
        out = {}
        for name, g in f["streams"].items():
            n = int(min(g["t"].shape[0], g["data"].shape[0]))
            end = g.attrs.get("end_s")
            end_s = None if end is None or not math.isfinite(float(end)) else float(end)
            spec = _shown_spec(spec_from_attrs(g.attrs, g["data"]))
            out[name] = StreamSource(label(name), spec, n, end_s, g["t"], g["data"])
        root = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()}
    except (ValueError, TypeError, KeyError, RecursionError) as e:
        f.close()
        raise RecordingCorrupted(
            path, "/streams", f"a stream cannot be described ({shown(e, limit=200)})"
        ) from None
    except BaseException:
        f.close()
        raise
    return f, out, root


def _bisect(t: h5py.Dataset, n: int, x: float, right: bool) -> int:
    """First index whose time is >= x (> x when ``right``), by binary search on the dataset."""
    lo, hi = 0, n
    while hi - lo > 4096:  # a few single reads, then one small block
        mid = (lo + hi) // 2
        v = float(t[mid])
        if v < x or (right and v == x):
            lo = mid + 1
        else:
            hi = mid
    return lo + int(np.searchsorted(t[lo:hi], x, side="right" if right else "left"))


def index_range(s: StreamSource, t0: float, t1: float) -> tuple[int, int]:
    """Indices ``[i, j)`` of the samples with ``t0 <= t <= t1`` (events: ``t0 <= t < t1``, as rate bins)."""
    return _bisect(s.t, s.n, t0, right=False), _bisect(s.t, s.n, t1, right=not s.spec.events)


def _blocks(s: StreamSource, i: int, j: int) -> Iterator[tuple[int, np.ndarray, np.ndarray]]:
    """``(start, t, values as float64 (rows, channels))`` over ``[i, j)``, block by block."""
    size = max(1, int(np.prod(s.data.shape[1:], dtype=np.int64)))
    rows = max(1, BLOCK_BYTES // (8 * size))
    for k in range(i, j, rows):
        m = min(k + rows, j)
        yield k, s.t[k:m], np.asarray(s.data[k:m], dtype=np.float64).reshape(m - k, size)


@dataclass(frozen=True)
class Envelope:
    """Lines of every channel: ``t`` (m,), ``y`` (m, channels), ``per_point`` samples per bucket.

    When ``per_point`` > 1 the line alternates each bucket's min and max (at its first and last
    sample times), so peaks stay visible; ``mean`` holds each bucket's mean (for heat maps);
    ``nonfinite`` counts the NaN/inf values per channel (left out of buckets, gaps in raw lines).
    """

    t: np.ndarray
    y: np.ndarray
    mean: np.ndarray
    t_mean: np.ndarray
    per_point: int
    n: int
    nonfinite: np.ndarray


def sample_envelope(s: StreamSource, i: int, j: int, buckets: int = 2000) -> Envelope:
    """The samples ``[i, j)`` of every channel, or a min-max envelope of ``buckets`` buckets."""
    n = j - i
    size = max(1, int(np.prod(s.data.shape[1:], dtype=np.int64)))
    if n <= 2 * buckets:
        t = np.asarray(s.t[i:j], np.float64)
        y = np.asarray(s.data[i:j], np.float64).reshape(n, size)
        return Envelope(t, y, y, t, 1, n, (~np.isfinite(y)).sum(axis=0))
    lo = np.full((buckets, size), np.nan)
    hi = np.full((buckets, size), np.nan)
    total = np.zeros((buckets, size))
    count = np.zeros((buckets, size))
    tb0 = np.full(buckets, np.inf)
    tb1 = np.full(buckets, -np.inf)
    for k, t, y in _blocks(s, i, j):
        b = ((np.arange(k, k + len(t)) - i) * buckets) // n
        starts = np.r_[0, np.flatnonzero(np.diff(b)) + 1]
        last = np.r_[starts[1:] - 1, len(b) - 1]
        ub = b[starts]
        lo[ub] = np.fmin(lo[ub], np.fmin.reduceat(y, starts, axis=0))
        hi[ub] = np.fmax(hi[ub], np.fmax.reduceat(y, starts, axis=0))
        finite = np.isfinite(y)
        total[ub] += np.add.reduceat(np.where(finite, y, 0.0), starts, axis=0)
        count[ub] += np.add.reduceat(finite, starts, axis=0)
        tb0[ub] = np.minimum(tb0[ub], t[starts])
        tb1[ub] = np.maximum(tb1[ub], t[last])
    tt = np.empty(2 * buckets)
    tt[0::2], tt[1::2] = tb0, tb1
    yy = np.empty((2 * buckets, size))
    yy[0::2], yy[1::2] = lo, hi
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = total / count
    return Envelope(
        tt, yy, mean, (tb0 + tb1) / 2, math.ceil(n / buckets), n, n - count.sum(axis=0).astype(int)
    )


def change_points(
    s: StreamSource, i: int, j: int, limit: int = 20_000
) -> tuple[np.ndarray, np.ndarray] | None:
    """Times and values where a scalar stream changes value (its first sample included), or None
    when it changes more than ``limit`` times (too often to draw as steps)."""
    ts: list[np.ndarray] = []
    vs: list[np.ndarray] = []
    prev: float | None = None
    count = 0
    for _, t, y in _blocks(s, i, j):
        v = y[:, 0]
        before = np.r_[np.nan if prev is None else prev, v[:-1]]
        changed = ~((v == before) | (np.isnan(v) & np.isnan(before)))
        count += int(changed.sum())
        if count > limit:
            return None
        ts.append(t[changed])
        vs.append(v[changed])
        prev = float(v[-1])
    if not ts:
        return np.empty(0), np.empty(0)
    return np.concatenate(ts), np.concatenate(vs)


def event_points(s: StreamSource, i: int, j: int) -> tuple[np.ndarray, np.ndarray]:
    """Times and data of the events ``[i, j)`` (the caller keeps ``j - i`` small)."""
    return np.asarray(s.t[i:j], np.float64), np.asarray(s.data[i:j])


def binned_event_counts(
    s: StreamSource, i: int, j: int, n_units: int, edges: np.ndarray, column: int | None = None
) -> np.ndarray:
    """Events per (bin, unit) over ``edges``; ``column`` picks the unit column of multi-column events."""
    counts = np.zeros((len(edges) - 1, n_units))
    for _, t, y in _blocks(s, i, j):
        unit = y[:, 0 if column is None else column].astype(np.int64)
        b = np.searchsorted(edges, t, side="right") - 1
        keep = (b >= 0) & (b < len(edges) - 1) & (unit >= 0) & (unit < n_units)
        np.add.at(counts, (b[keep], unit[keep]), 1.0)
    return counts


def frames_at(s: StreamSource, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The frames nearest to (at or after) each time, reading only those: (their times, frames)."""
    idx = [min(_bisect(s.t, s.n, float(x), right=False), s.n - 1) for x in times]
    idx = sorted(set(idx))
    return np.array([float(s.t[k]) for k in idx]), np.stack([np.asarray(s.data[k]) for k in idx])
