"""Spike events counted per unit into fixed time bins, each released once the watermark has passed
its end: the streaming core that turns events into a sample stream (rate, synapse)."""

from __future__ import annotations

import math

import numpy as np

import flowtact.api as ft

__all__ = ["EventBins"]


class EventBins:
    """Counts of events per bin ``[k·width, (k+1)·width)`` and unit, from bin ``next`` on.

    Times within 1e-9 of a bin's width below a boundary snap to the later bin, so ``i / rate`` on a
    boundary lands there despite rounding. ``label`` and ``what`` name the block and its index in
    the error for an index out of range.
    """

    def __init__(self, units: int, width_s: float, label: str, what: str = "unit") -> None:
        self.units, self.width, self._label, self._what = units, width_s, label, what
        self.next = 0
        """First bin not taken yet."""
        self.wm = -math.inf
        """Watermark: every event before it has arrived."""
        self._counts = np.zeros((0, units), np.int64)

    def bin_of(self, t: np.ndarray | list[float]) -> np.ndarray:
        return np.floor(np.asarray(t, np.float64) / self.width + 1e-9).astype(np.int64)

    def add(self, spikes: ft.Chunk) -> int:
        """Count a chunk of events and move the watermark; returns how many events fell in bins
        already taken (they are ignored: the producer broke its watermark)."""
        late_n = 0
        if len(spikes):
            idx = np.asarray(spikes.data, np.int64)
            if idx.min() < 0 or idx.max() >= self.units:
                raise ValueError(
                    f"{self._label}: {self._what} index out of range 0..{self.units - 1} "
                    f"(got {idx.min()}..{idx.max()})"
                )
            k = self.bin_of(spikes.t)
            late = k < self.next
            if late.any():
                late_n = int(late.sum())
                k, idx = k[~late], idx[~late]
            if len(k):
                self._grow(int(k.max()) - self.next + 1)
                np.add.at(self._counts, (k - self.next, idx), 1)
            self.wm = max(self.wm, float(spikes.t[-1]))
        if spikes.end is not None:
            self.wm = max(self.wm, float(spikes.end))
        return late_n

    def complete(self) -> int:
        """Bins not taken yet whose end is at or before the watermark."""
        return max(int(self.bin_of([self.wm])[0]) - self.next, 0) if math.isfinite(self.wm) else 0

    def pending(self) -> int:
        """Bins not taken yet that hold an event or lie before the watermark (a partial one too):
        what a flush releases."""
        n = len(self._counts)
        if math.isfinite(self.wm):
            k = int(self.bin_of([self.wm])[0])
            if self.wm > k * self.width:  # a partial bin [k·width, watermark) is open
                n = max(n, k + 1 - self.next)
        return n

    def take(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """The next ``n`` bins: their indices k and counts (shape (n, units)); they are released."""
        n = max(n, 0)
        self._grow(n)
        counts, self._counts = self._counts[:n], self._counts[n:]
        k = self.next + np.arange(n)
        self.next += n
        return k, counts

    def _grow(self, n_bins: int) -> None:
        if n_bins > len(self._counts):
            more = np.zeros((n_bins - len(self._counts), self.units), np.int64)
            self._counts = np.vstack([self._counts, more])
