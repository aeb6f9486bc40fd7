"""``rate``: spikes of a population → its firing rate in bins (per unit or pooled)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

import numpy as np

from flowtact.block import Block, Example, Port, SpecError
from flowtact.chunk import Chunk, StreamSpec
from flowtact.params import Config, param

__all__ = ["Rate", "RateConfig"]


@dataclass(frozen=True)
class RateConfig(Config):
    """Parameters of :class:`Rate`."""

    bin_s: float = param(0.02, doc="bin width in s (output rate 1/bin_s Hz)", gt=0)
    mode: Literal["unit", "population"] = param(
        "unit", doc="unit: one rate per unit, shape (n_units,); population: mean rate per unit, shape ()"
    )


class Rate(Block):
    """Firing rate of a spike stream in fixed time bins (spikes/s).

    Ports
    -----
    spikes : events, int64 unit index (needs the stream's n_units)
        The spike stream, e.g. ``nlif.spikes``.
    y : float64, shape (n_units,) (mode unit) or () (mode population), spikes/s, at 1/bin_s Hz
        Bin ``k`` covers ``[k·bin_s, (k+1)·bin_s)`` and is stamped at its start ``k·bin_s``.

    Config
    ------
    ``bin_s`` (default 20 ms, the paper's rate checks) and ``mode``; see the field docs.

    Notes
    -----
    Bins start at graph time 0. A bin is emitted once the input watermark (``Chunk.end``, or
    the last spike time when the producer sets no watermark) reaches its end, so the latency is
    up to one bin plus the producer's. An event whose time lies on a boundary (within 1e-9 bin,
    to absorb the rounding of ``i / rate``) belongs to the later bin. ``flush`` emits the bins still open at end of stream, the last one partial:
    its rate is the count divided by the time it covered (up to the final watermark), not by
    ``bin_s``. Events older than an emitted bin (a producer breaking its watermark) are counted
    as ``late_events`` and ignored. Chunking-invariant: only the counts per bin are kept.

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.spiking.rate import Rate
    >>> from flowtact.testing import run_offline
    >>> spikes = (np.array([0.001, 0.005, 0.021, 0.039]), np.array([0, 1, 0, 0]))
    >>> out = run_offline(Rate(bin_s=0.02), spikes=spikes, rate_hz=1000.0)  # watermark ends at 0.04 s
    >>> out["y"].data.tolist()
    [[50.0, 50.0], [100.0, 0.0]]
    """

    config_cls = RateConfig
    inputs = {"spikes": Port(dtype="int64", shape=(), events=True, doc="spike times and unit indices")}
    outputs = {"y": Port(dtype="float64", units="spikes/s", doc="rate per bin, stamped at the bin start")}
    counter_docs = {
        "late_events": "spikes older than a bin already emitted (the producer broke its watermark): "
        "ignored, so those rates are too low; a fault upstream",
    }

    def specs(self, inputs: Mapping[str, StreamSpec]) -> dict[str, StreamSpec]:
        s = inputs["spikes"]
        if not s.n_units or s.n_units < 1:
            raise SpecError(
                "spikes", f"{self.node}: input 'spikes' must declare its number of units (n_units)"
            )
        shape = (s.n_units,) if self.config.mode == "unit" else ()
        return {
            "y": StreamSpec(dtype="float64", shape=shape, units="spikes/s", rate_hz=1.0 / self.config.bin_s)
        }

    def reset(self) -> None:
        self._units = int(self.input_specs["spikes"].n_units)  # type: ignore[arg-type]
        self._next = 0  # first bin not emitted yet
        self._counts = np.zeros((0, self._units))  # counts of bins _next, _next + 1, ...
        self._wm = -math.inf  # watermark: every event before it has arrived

    def _bin_of(self, t: np.ndarray) -> np.ndarray:
        """Index k of the bin [k·bin, (k+1)·bin) holding t, snapping times within 1e-9 bin of a
        boundary to the later bin (so i / rate on a boundary lands there despite rounding)."""
        return np.floor(np.asarray(t, np.float64) / self.config.bin_s + 1e-9).astype(np.int64)

    def _complete(self, wm: float) -> int:
        """Number of bins whose end is at or before the watermark."""
        if not math.isfinite(wm):
            return 0
        return int(self._bin_of(np.array([wm]))[0])

    def step(self, spikes: Chunk) -> dict[str, Chunk]:
        if len(spikes):
            idx = np.asarray(spikes.data, dtype=np.int64)
            if idx.min() < 0 or idx.max() >= self._units:
                raise ValueError(
                    f"{self.node} ({self.name}): unit index out of range 0..{self._units - 1} "
                    f"(got {idx.min()}..{idx.max()})"
                )
            k = self._bin_of(spikes.t)
            late = k < self._next
            if late.any():
                self.count("late_events", int(late.sum()))
                k, idx = k[~late], idx[~late]
            if len(k):
                need = int(k.max()) - self._next + 1
                if need > len(self._counts):
                    self._counts = np.vstack(
                        [self._counts, np.zeros((need - len(self._counts), self._units))]
                    )
                flat = (k - self._next) * self._units + idx
                self._counts += np.bincount(flat, minlength=self._counts.size).reshape(self._counts.shape)
            self._wm = max(self._wm, float(spikes.t[-1]))
        if spikes.end is not None:
            self._wm = max(self._wm, float(spikes.end))
        return {"y": self._emit(self._complete(self._wm) - self._next, partial=False)}

    def _emit(self, n_bins: int, partial: bool) -> Chunk:
        n_bins = max(n_bins, 0)
        w = self.config.bin_s
        if len(self._counts) < n_bins:
            self._counts = np.vstack([self._counts, np.zeros((n_bins - len(self._counts), self._units))])
        counts, self._counts = self._counts[:n_bins], self._counts[n_bins:]
        k = self._next + np.arange(n_bins)
        widths = np.full(n_bins, w)
        if partial and n_bins:
            covered = self._wm - k[-1] * w
            if 0 < covered < w:
                widths[-1] = covered
        rates = counts / widths[:, None]
        if self.config.mode == "population":
            rates = rates.mean(axis=1)
        self._next += n_bins
        return Chunk(k * w, rates, k[-1] * w + w if n_bins else None)

    def flush(self) -> dict[str, Chunk]:
        n_bins = len(self._counts)
        if math.isfinite(self._wm):
            k = self._complete(self._wm)
            if self._wm > k * self.config.bin_s:  # a partial bin [k·bin, watermark) is open
                n_bins = max(n_bins, k + 1 - self._next)
        return {"y": self._emit(n_bins, partial=True)}

    @classmethod
    def example(cls) -> Example:
        rng = np.random.default_rng(5)
        t = np.sort(rng.uniform(0.0, 1.0, 300))
        idx = rng.integers(0, 4, 300)
        return Example(params={"bin_s": 0.02}, inputs={"spikes": (t, idx)}, rate_hz=1000.0)
