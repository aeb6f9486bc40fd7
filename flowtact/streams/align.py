"""Pairing several sample streams by arrival order, and bad-data policies over paired samples.

Multi-input blocks (a weighted sum of a force and its derivatives, gauges with a reference) get
streams that left one source together but went through different delays; they must combine
sample *n* of every input, whatever the chunk boundaries. :class:`Aligner` does that.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np

from flowtact.block import BadDataPolicy, Block, screen_nonfinite
from flowtact.chunk import Chunk, StreamSpec
from flowtact.errors import MisalignedError
from flowtact.finite import all_finite

__all__ = ["Aligner", "screen_aligned"]


class Aligner:
    """Buffers several sample streams and releases their common prefix, sample by sample.

    Streams from one source that went through different delays (a centred derivative is emitted
    (N−1)/2 samples after the raw force, with the same timestamps) are paired by arrival order;
    paired samples must carry the same time (within ``tol_s``), else :class:`MisalignedError`.
    Chunking-invariant: what is released depends only on the samples, never on chunk boundaries.
    """

    def __init__(
        self, owner: str, specs: Mapping[str, StreamSpec], ports: Iterable[str], tol_s: float
    ) -> None:
        self.owner, self.tol_s = owner, tol_s
        self.ports = list(ports)
        self._t = {p: np.empty(0) for p in self.ports}
        self._d = {p: np.empty((0, *specs[p].shape), np.float64) for p in self.ports}
        self._solo = self.ports[0] if len(self.ports) == 1 else None  # aligned with itself

    def push(self, chunks: Mapping[str, Chunk | None]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Add what arrived; return (t, {port: data}) of the newly aligned samples (maybe none).

        Chunks that came together with nothing held back (the common case) are handed on as they
        are: no joining and no copies. One stream is aligned with itself: it passes straight through.
        """
        p = self._solo
        if p is not None:
            c = chunks.get(p)
            return (self._t[p], {p: self._d[p]}) if c is None else (c.t, {p: c.data})
        ts, ds = {}, {}
        for p in self.ports:
            c = chunks.get(p)
            held = self._t[p]
            if c is None or not len(c.t):
                ts[p], ds[p] = held, self._d[p]
            elif len(held):
                ts[p] = np.concatenate([held, c.t])
                ds[p] = np.concatenate([self._d[p], c.data])
            else:
                ts[p], ds[p] = c.t, c.data
        k = min(len(v) for v in ts.values())
        ref = self.ports[0]
        t = ts[ref][:k]
        for p in self.ports[1:]:
            bad = np.abs(ts[p][:k] - t) > self.tol_s
            if bad.any():
                i = int(np.argmax(bad))
                raise MisalignedError(
                    f"{self.owner}: inputs '{ref}' and '{p}' are not sample-aligned: paired samples "
                    f"carry t={t[i]:.9f} s and t={ts[p][i]:.9f} s (feed streams of one source and rate)"
                )
        out = {p: ds[p][:k] for p in self.ports}
        for p in self.ports:  # keep only the unpaired rest, as owned copies
            if len(ts[p]) > k or len(self._t[p]):
                self._t[p] = ts[p][k:].copy()
                self._d[p] = ds[p][k:].copy()
        return t, out

    def pending(self) -> dict[str, int]:
        """Samples held back per port (waiting for their partners)."""
        return {p: len(v) for p, v in self._t.items()}


def screen_aligned(
    block: Block,
    policy: BadDataPolicy,
    t: np.ndarray,
    data: dict[str, np.ndarray],
    last: dict[str, np.ndarray | None],
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """A bad-data policy over aligned inputs: ``drop`` removes the instant from every input.

    ``raise`` names the first bad port; ``hold`` repeats each port's last good sample (``last``
    holds them and is updated). Counts ``nonfinite_<policy>`` like :func:`screen_nonfinite`.
    """
    for d in data.values():  # the cheap test of screen_nonfinite
        if not all_finite(d):
            break
    else:
        if policy == "hold" and len(t):
            last.update({p: d[-1].copy() for p, d in data.items()})
        return t, data
    if policy == "drop":
        good = np.ones(len(t), bool)
        for d in data.values():
            good &= np.isfinite(d.reshape(len(t), -1)).all(axis=1)
        block.count("nonfinite_drop", int((~good).sum()))
        return t[good], {p: d[good] for p, d in data.items()}
    out = {}
    for p, d in data.items():
        c, last[p] = screen_nonfinite(block, Chunk(t, d), policy, p, last[p])
        out[p] = c.data
    return t, out
