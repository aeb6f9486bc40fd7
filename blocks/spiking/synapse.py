"""``synapse``: spikes of a source population → synaptic currents of a target population through a
sparse weight matrix with exponential decay (dense weights or a seeded grid connectivity)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numba import njit

import flowtact.api as ft
from flowtact.blocks.spiking.event_bins import EventBins

__all__ = ["Synapse", "SynapseConfig", "grid_connectivity"]


def _neighbours(i: int, shape: tuple[int, int]) -> list[int]:
    r, c = divmod(i, shape[1])
    out = []
    for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        rr, cc = r + dr, c + dc
        if 0 <= rr < shape[0] and 0 <= cc < shape[1]:
            out.append(rr * shape[1] + cc)
    return out


def grid_connectivity(
    n_targets: int, grid: tuple[int, int], fan_in: tuple[int, int], seed: int
) -> list[list[int]]:
    """Receptive fields: for each target the sources it samples, adjacent on a row-major grid.

    Target i draws its size k uniformly in [fan_in[0], fan_in[1]], starts from a source (the first
    ``n_sources`` targets start from a shuffled list of all sources, so every source feeds at least
    one target when ``n_targets ≥ n_sources``; later ones from a uniform draw), then grows the field
    one random 4-neighbour of the field at a time. All draws come from ``numpy.random.default_rng(seed)``.
    """
    rng = np.random.default_rng(seed)
    n_src = grid[0] * grid[1]
    starts = list(rng.permutation(n_src))
    fields = []
    for i in range(n_targets):
        k = int(rng.integers(fan_in[0], fan_in[1] + 1))
        field = [int(starts[i]) if i < n_src else int(rng.integers(n_src))]
        while len(field) < k:
            border = sorted({nb for s in field for nb in _neighbours(s, grid)} - set(field))
            if not border:
                break
            field.append(int(border[int(rng.integers(len(border)))]))
        fields.append(sorted(field))
    return fields


@dataclass(frozen=True)
class SynapseConfig(ft.Config):
    """Parameters of :class:`Synapse`: the weights (dense, or a grid connectivity) and the decay."""

    rate_hz: float = ft.param(1000.0, doc="rate of the output currents (its bins: 1/rate_hz s)", gt=0)
    tau_s: float = ft.param(0.005, doc="decay time constant of the synaptic current, s", gt=0)
    weights: tuple[tuple[float, ...], ...] | None = ft.param(
        None, doc="dense weights, one row per target, one column per source (or use grid)"
    )
    grid: tuple[int, ...] | None = ft.param(
        None, doc="random connectivity: sources on a row-major grid [rows, cols]", ge=1, min_len=2, max_len=2
    )
    n_targets: int = ft.param(1, doc="random connectivity: number of targets", ge=1)
    fan_in: tuple[int, ...] = ft.param(
        (1, 3),
        doc="random connectivity: [least, most] adjacent sources per target",
        ge=1,
        min_len=2,
        max_len=2,
    )
    weight: float = ft.param(1.0, doc="random connectivity: the weight of every connection")
    connect_seed: int = ft.param(
        0, doc="random connectivity: seed of the draw (fixed: not the graph's seed)", ge=0
    )

    def check(self) -> None:
        if (self.weights is None) == (self.grid is None):
            raise self.error("weights", "give either weights (dense) or grid (random connectivity), not both")
        if self.weights is not None:
            if not self.weights or len({len(r) for r in self.weights}) != 1 or not self.weights[0]:
                raise self.error("weights", "must be a non-empty list of rows of equal, non-zero length")
            if not np.isfinite(np.asarray(self.weights, np.float64)).all():
                raise self.error("weights", "must be finite")
        if self.fan_in[0] > self.fan_in[1]:
            raise self.error("fan_in", f"must be [least, most] with least <= most; got {list(self.fan_in)}")
        if not math.isfinite(self.weight):
            raise self.error("weight", "must be finite")

    def matrix(self) -> np.ndarray:
        """The dense (n_targets, n_sources) weight matrix these parameters give."""
        if self.weights is not None:
            return np.asarray(self.weights, np.float64)
        g = (int(self.grid[0]), int(self.grid[1]))  # type: ignore[index]
        w = np.zeros((self.n_targets, g[0] * g[1]))
        for i, field in enumerate(grid_connectivity(self.n_targets, g, self.fan_in, self.connect_seed)):  # type: ignore[arg-type]
            w[i, field] = self.weight
        return w


@njit(cache=True)
def _integrate(
    counts: np.ndarray, ptr: np.ndarray, tgt: np.ndarray, val: np.ndarray, decay: float, y: np.ndarray
) -> np.ndarray:
    """y[k] = decay·y[k−1] + W·counts[k] bin by bin (W in compressed columns), from y; y is updated."""
    n_bins, n_src = counts.shape
    out = np.empty((n_bins, len(y)))
    for k in range(n_bins):
        for t in range(len(y)):
            y[t] = decay * y[t]
        for j in range(n_src):
            c = counts[k, j]
            if c != 0:
                for p in range(ptr[j], ptr[j + 1]):
                    y[tgt[p]] += val[p] * c
        out[k] = y
    return out


class Synapse(ft.Block):
    """Synaptic currents of a target population from a source population's spikes (sparse weights, exponential decay).

    Config
    ------
    Either ``weights`` (dense, n_targets × n_sources) or ``grid`` + ``n_targets`` + ``fan_in`` +
    ``weight`` + ``connect_seed``: each target samples 1–3 (``fan_in``) adjacent sources on a
    row-major grid of that shape (see :func:`grid_connectivity`). The draw has its own seed, so a
    population keeps its connectivity when the graph's seed changes (a trained decoder stays valid).

    Notes
    -----
    Only the non-zero weights are kept (compressed columns: a spike costs its fan-out). A bin is
    emitted once the input watermark (``Chunk.end``, else the last spike time) passes its end, so
    the latency is one bin plus the producer's; spikes of ``nlif`` stamped at the sample times of a
    stream at ``rate_hz`` land in the bin of that sample (times within 1e-9 bin of a boundary count
    in the later bin). ``flush`` emits the bins still open at end of stream. Spikes older than an
    emitted bin are counted (``late_events``) and ignored; an index outside 0..n_sources − 1 is an
    error. The sum per bin runs in a fixed order: chunking never changes a bit.

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.spiking.synapse import Synapse
    >>> from flowtact.testing import run_offline
    >>> spikes = (np.array([0.0, 0.002]), np.array([0, 1]))
    >>> out = run_offline(Synapse(weights=[[1.0, 0.5]], tau_s=0.01, rate_hz=1000.0), spikes=spikes)
    >>> np.round(out["y"].data[:3, 0], 4).tolist()
    [1.0, 0.9048, 1.3187]
    """

    config_cls = SynapseConfig
    inputs = {
        "spikes": ft.Port(
            dtype="int64",
            shape=(),
            events=True,
            doc="spike times and source indices (needs the stream's n_units = number of sources)",
        )
    }
    outputs = {
        "y": ft.Port(
            dtype="float64",
            units="1",
            doc=(
                "current of each target, shape (n_targets,), at rate_hz: sample k (stamped k/rate_hz) is "
                "the current after bin k = [k, k + 1)/rate_hz: y[k] = e^(−dt/τ)·y[k−1] + W·c[k] with c[k]"
                " the spike counts of each source in that bin: a spike adds its weight at once, then "
                "decays with tau_s"
            ),
        )
    }
    counter_docs = {
        "late_events": "spikes older than a bin already emitted (the producer broke its watermark): "
        "ignored, so those currents are too low; a fault upstream",
    }

    def specs(self, inputs: Mapping[str, ft.StreamSpec]) -> dict[str, ft.StreamSpec]:
        s = inputs["spikes"]
        w = self.config.matrix()
        if not s.n_units:
            raise ft.SpecError(
                "spikes", f"{self.node}: input 'spikes' must declare its number of units (n_units)"
            )
        if s.n_units != w.shape[1]:
            raise ft.SpecError(
                "spikes",
                f"{self.node}: the weights have {w.shape[1]} source columns but 'spikes' has "
                f"{s.n_units} units",
            )
        return {"y": ft.StreamSpec("float64", (w.shape[0],), "1", self.config.rate_hz)}

    def reset(self) -> None:
        w = self.config.matrix()
        self._n_tgt, self._n_src = w.shape
        cols = [np.flatnonzero(w[:, j]) for j in range(self._n_src)]
        self._ptr = np.concatenate([[0], np.cumsum([len(c) for c in cols])]).astype(np.int64)
        self._tgt = np.concatenate([*cols, np.zeros(0, np.int64)]).astype(np.int64)
        self._val = np.concatenate([*(w[c, j] for j, c in enumerate(cols)), np.zeros(0)])
        self._dt = 1.0 / self.config.rate_hz
        self._decay = math.exp(-self._dt / self.config.tau_s)
        self._y = np.zeros(self._n_tgt)
        self._bins = EventBins(self._n_src, self._dt, f"{self.node} ({self.name})", what="source")

    def step(self, spikes: ft.Chunk) -> dict[str, ft.Chunk]:
        late = self._bins.add(spikes)
        if late:
            self.count("late_events", late)
        return {"y": self._emit(self._bins.complete())}

    def _emit(self, n_bins: int) -> ft.Chunk:
        k, counts = self._bins.take(n_bins)
        y = _integrate(np.ascontiguousarray(counts), self._ptr, self._tgt, self._val, self._decay, self._y)
        return ft.Chunk(k * self._dt, y, (k[-1] + 1) * self._dt if len(k) else None)

    def flush(self) -> dict[str, ft.Chunk]:
        return {"y": self._emit(self._bins.pending())}

    @classmethod
    def example(cls) -> ft.Example:
        rng = np.random.default_rng(9)
        t = np.sort(rng.uniform(0.0, 1.0, 400))
        idx = rng.integers(0, 24, 400)
        params = {
            "grid": [6, 4],
            "n_targets": 49,
            "fan_in": [1, 3],
            "weight": 0.5,
            "tau_s": 0.01,
            "rate_hz": 250.0,
        }
        return ft.Example(params=params, inputs={"spikes": (t, idx)}, rate_hz=1000.0)
