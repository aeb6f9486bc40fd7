"""Joining streams of different rates by time: each sample of one stream with the latest of the others.

A controller that acts on every 100 Hz exoskeleton packet but also needs the latest 40 Hz camera
force must not depend on which chunk the camera's sample happened to arrive in. :class:`LatestMerger`
releases a sample of the *driving* stream only once every other stream is known up to its time
(its watermark passed), so the pairing depends on timestamps alone: chunking-invariant.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from flowtact.chunk import Chunk

__all__ = ["LatestMerger"]


class _Held:
    """One non-driving stream: samples not yet superseded, and how far in time it is known."""

    def __init__(self, initial: np.ndarray) -> None:
        self.t = np.empty(0, np.float64)
        self.data = np.asarray(initial, np.float64)[None].copy()[:0]
        self.before = np.asarray(initial, np.float64).copy()  # value in force before self.t[0]
        self.last_t = -np.inf
        self.end = -np.inf

    def push(self, c: Chunk) -> None:
        if len(c):
            self.t = np.concatenate([self.t, c.t])
            self.data = np.concatenate([self.data, np.asarray(c.data, np.float64)])
            self.last_t = float(c.t[-1])
        if c.end is not None:
            self.end = max(self.end, float(c.end))

    def known(self, t: np.ndarray) -> np.ndarray:
        """Which times this stream is complete up to (a later sample came, or its watermark passed)."""
        return (t <= self.last_t) | (t < self.end)

    def at(self, t: np.ndarray) -> np.ndarray:
        """The latest sample with time ≤ each of ``t`` (``before`` if none)."""
        i = np.searchsorted(self.t, t, side="right") - 1
        vals = np.concatenate([self.before[None], self.data])
        return vals[i + 1]

    def drop_before(self, t: float) -> None:
        """Forget samples superseded at time ``t`` (keep the one in force at ``t`` as ``before``)."""
        i = int(np.searchsorted(self.t, t, side="right")) - 1
        if i >= 0:
            self.before = self.data[i].copy()
            self.t, self.data = self.t[i + 1 :], self.data[i + 1 :]


class LatestMerger:
    """Pairs each sample of the ``drive`` stream with the latest sample (t' ≤ t) of every other stream.

    ``others`` maps each other stream to the value it holds before its first sample. A driving
    sample at time t is released once every other stream is complete up to t: it has a sample at or
    after t, or its watermark (``Chunk.end``) is later than t. ``flush()`` releases the rest with
    what is known. Every stream is read as float64.
    """

    def __init__(
        self, drive: str, others: Mapping[str, np.ndarray | float], drive_shape: tuple[int, ...] = ()
    ) -> None:
        self.drive = drive
        self.others = {k: _Held(np.asarray(v, np.float64)) for k, v in others.items()}
        self._t = np.empty(0, np.float64)
        self._data = np.empty((0, *drive_shape), np.float64)
        self._end = -np.inf

    def push(self, chunks: Mapping[str, Chunk]) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """Add what arrived; return (t, driving samples, {other: its latest value at each t}) released now."""
        for name, held in self.others.items():
            c = chunks.get(name)
            if c is not None:
                held.push(c)
        c = chunks.get(self.drive)
        if c is not None:
            if len(c):
                self._t = np.concatenate([self._t, c.t])
                self._data = np.concatenate([self._data, np.asarray(c.data, np.float64)])
            if c.end is not None:
                self._end = max(self._end, float(c.end))
        ok = np.ones(len(self._t), bool)
        for held in self.others.values():
            ok &= held.known(self._t)
        n = int(np.argmin(ok)) if not ok.all() else len(ok)  # release the complete prefix only
        return self._release(n)

    def held_times(self) -> np.ndarray:
        """Times of the driving samples held back, waiting for the other streams."""
        return self._t

    def release_through(self, t: float) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """Release the held driving samples with time ≤ ``t`` now, with the values known so far
        (for a consumer that must not wait on a dead stream)."""
        return self._release(int(np.searchsorted(self._t, t, side="right")))

    def flush(self) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """End of stream: release every held driving sample with the latest values known."""
        return self._release(len(self._t))

    def end(self) -> float | None:
        """Watermark of the merged output: nothing more will be released before this time."""
        pending = float(self._t[0]) if len(self._t) else np.inf
        known = min([self._end, *(max(h.last_t, h.end) for h in self.others.values())], default=self._end)
        e = min(pending, known)
        return None if not np.isfinite(e) else e

    def _release(self, n: int) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        t = self._t[:n]
        data = self._data[:n]
        vals = {k: h.at(t) for k, h in self.others.items()}
        if n:
            for h in self.others.values():
                h.drop_before(float(t[-1]))
            self._t = self._t[n:]
            self._data = self._data[n:]
        return t, data, vals
