"""``rate``: spikes of a population → its firing rate in bins (per unit or pooled)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

import numpy as np

from flowtact.block import Block, Example, Port
from flowtact.blocks.spiking.event_bins import EventBins
from flowtact.chunk import Chunk, StreamSpec
from flowtact.errors import SpecError
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
        units = int(self.input_specs["spikes"].n_units)  # type: ignore[arg-type]
        self._bins = EventBins(units, self.config.bin_s, f"{self.node} ({self.name})")

    def step(self, spikes: Chunk) -> dict[str, Chunk]:
        late = self._bins.add(spikes)
        if late:
            self.count("late_events", late)
        return {"y": self._emit(self._bins.complete(), partial=False)}

    def _emit(self, n_bins: int, partial: bool) -> Chunk:
        w = self.config.bin_s
        k, counts = self._bins.take(n_bins)
        widths = np.full(len(k), w)
        if partial and len(k):
            covered = self._bins.wm - k[-1] * w
            if 0 < covered < w:
                widths[-1] = covered
        rates = counts / widths[:, None]
        if self.config.mode == "population":
            rates = rates.mean(axis=1)
        return Chunk(k * w, rates, k[-1] * w + w if len(k) else None)

    def flush(self) -> dict[str, Chunk]:
        return {"y": self._emit(self._bins.pending(), partial=True)}

    @classmethod
    def example(cls) -> Example:
        rng = np.random.default_rng(5)
        t = np.sort(rng.uniform(0.0, 1.0, 300))
        idx = rng.integers(0, 4, 300)
        return Example(params={"bin_s": 0.02}, inputs={"spikes": (t, idx)}, rate_hz=1000.0)
