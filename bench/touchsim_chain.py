"""TouchSim's per-afferent model as flowtact's chain (iir → rectified_gain → nlif), run in process.

The same blocks and wiring as graphs/touchsim_afferents.yaml, for any number of afferents, each with
its own model: s and d (samples × afferents, 5 kHz) through the Butterworth prefilters at 10·p0 Hz,
the rectified gains p1–p6 with noise p8 before saturation p7, and nlif's TouchSim neuron
(``models:``). Used by `flowtact bench touchsim` and by tests/blocks/touch/test_touchsim_noise.py; the dev set
and TouchSim's parameters come from the caller.
"""

from __future__ import annotations

import numpy as np

from flowtact.blocks.signal.iir import Iir
from flowtact.blocks.signal.rectified_gain import RectifiedGain
from flowtact.blocks.spiking.nlif import Nlif
from flowtact.blocks.touch.touchsim import TOUCHSIM_RATE_HZ, touchsim_models
from flowtact.blocks.touch.touchsim_chain import TouchsimChain
from flowtact.chunk import Chunk, StreamSpec

__all__ = ["CLASSES", "TouchSimChain", "model_params"]

CLASSES = ("SA1", "RA", "PC")
"""TouchSim's class order (its ``gid``): 0 SA1, 1 RA, 2 PC."""


def model_params(models: list[str]) -> np.ndarray:
    """The 13 parameters of each named model (``"SA1.0"`` … ``"PC.3"``), one row per afferent."""
    table = touchsim_models()
    return np.array([table[m] for m in models], np.float64)


class TouchSimChain:
    """The three blocks for afferents ``models`` (one per column), bound and seeded; ``run`` feeds
    whole arrays in ``chunk``-sample chunks and returns each afferent's spikes as sample indices.
    ``noise_scale`` multiplies TouchSim's noise s.d. p8 (1: TouchSim's model; else a wrong one, to
    show that a comparison notices)."""

    def __init__(
        self,
        models: list[str],
        *,
        noise: bool = True,
        seed: int = 0,
        noise_scale: float = 1.0,
        fused: bool = False,
    ) -> None:
        p = model_params(models)
        self.fused: TouchsimChain | None = None
        if fused:  # the one block: the same computation, bit for bit with these seeds
            self.fused = TouchsimChain(models=list(models), noise_scale=noise_scale if noise else 0.0)
            self._fused_seed = seed + 2
            self._fused_demand = frozenset({"spikes"})
            self._bind_fused(self._fused_demand)
        n = len(models)
        cut = (10.0 * p[:, 0]).tolist()
        self.prefilter_s = Iir(family="butter", order=3, cutoff_hz=cut)
        self.prefilter_d = Iir(family="butter", order=3, cutoff_hz=cut)
        col = lambda k: p[:, k].tolist()  # noqa: E731
        self.current = RectifiedGain(
            pos1=col(1), neg1=col(2), pos2=col(3), neg2=col(4), ahead="x2", ahead_pos=col(5),
            ahead_neg=col(6), saturation=col(7), noise_sd=(noise_scale * p[:, 8]).tolist() if noise else [0.0],
        )  # fmt: skip
        self.afferents = Nlif(models=list(models))
        spec = StreamSpec(dtype="float64", shape=(n,), rate_hz=TOUCHSIM_RATE_HZ)
        self.prefilter_s.bind({"x": spec}, seed=seed)
        self.prefilter_d.bind({"x": spec}, seed=seed + 1)
        self.current.bind({"x1": spec, "x2": spec}, seed=seed + 2)
        self.afferents.bind({"x": spec}, seed=seed + 3, demanded=frozenset({"spikes"}))
        self.n = n

    def run(
        self, s: np.ndarray, d: np.ndarray, chunk: int = 50, keep_current: bool = False
    ) -> list[np.ndarray]:
        """Spikes of each afferent (sample indices: nlif stamps sample n at n/fs) for s, d from rest;
        with ``keep_current`` the current (samples × afferents) is left in ``self.current_out``."""
        return self._by_unit(self.spike_chunks(s, d, chunk, keep_current))

    def spike_chunks(
        self, s: np.ndarray, d: np.ndarray, chunk: int = 50, keep_current: bool = False
    ) -> list[Chunk]:
        """:meth:`run` up to the spike stream the blocks emit (what a graph runs), before it is
        sorted out by afferent."""
        t_all = np.arange(len(s)) / TOUCHSIM_RATE_HZ
        if self.fused is not None:
            return self._run_fused(s, d, t_all, chunk, keep_current)
        parts, currents = [], []
        for i in range(0, len(s), chunk):
            t = t_all[i : i + chunk]
            ys = self.prefilter_s(x=Chunk(t, s[i : i + chunk]))["y"]
            yd = self.prefilter_d(x=Chunk(t, d[i : i + chunk]))["y"]
            cur = self.current(x1=ys, x2=yd)["y"]
            if keep_current:
                currents.append(cur.data)
            parts.append(self.afferents(x=cur)["spikes"])
        last = self.current.flush().get("y")  # the held last sample (Δd = 0)
        if last is not None:
            parts.append(self.afferents(x=last)["spikes"])
            if keep_current:
                currents.append(last.data)
        if keep_current:
            self.current_out = np.concatenate(currents)
        tail = self.afferents.flush().get("spikes")
        if tail is not None:
            parts.append(tail)
        return parts

    def _run_fused(
        self, s: np.ndarray, d: np.ndarray, t_all: np.ndarray, chunk: int, keep_current: bool
    ) -> list[Chunk]:
        """:meth:`run` through the fused block (``touchsim_chain``)."""
        block = self.fused
        assert block is not None
        want = frozenset({"spikes", "current"} if keep_current else {"spikes"})
        if want != self._fused_demand or self._fused_ran:  # from rest (bound in __init__: not timed)
            self._bind_fused(want)
        self._fused_ran = True
        parts, currents = [], []
        for i in range(0, len(s), chunk):
            t = t_all[i : i + chunk]
            out = block(s=Chunk(t, s[i : i + chunk]), d=Chunk(t, d[i : i + chunk]))
            parts.append(out["spikes"])
            currents.append(out.get("current"))
        out = block.flush()
        if out:
            parts.append(out["spikes"])
            currents.append(out.get("current"))
        if keep_current:
            self.current_out = np.concatenate([c.data for c in currents])
        return parts

    def _bind_fused(self, demanded: frozenset[str]) -> None:
        """Bind the fused block from rest (filter design included: seconds for 17 000 afferents)."""
        assert self.fused is not None
        spec = StreamSpec(dtype="float64", shape=(len(self.fused.config.models),), rate_hz=TOUCHSIM_RATE_HZ)
        self.fused.bind({"s": spec, "d": spec}, seed=self._fused_seed, demanded=demanded)
        self._fused_demand, self._fused_ran = demanded, False

    def _by_unit(self, parts: list[Chunk]) -> list[np.ndarray]:
        """Each afferent's spikes (sample indices) from the spike chunks."""
        t = np.concatenate([c.t for c in parts])
        unit = np.concatenate([c.data for c in parts]).astype(np.int64)
        idx = np.rint(t * TOUCHSIM_RATE_HZ).astype(np.int64)
        order = np.argsort(unit, kind="stable")  # by unit, each unit's spikes in time order
        ends = np.cumsum(np.bincount(unit, minlength=self.n)).tolist()
        by_unit = idx[order]
        return [by_unit[lo:hi] for lo, hi in zip([0, *ends[:-1]], ends, strict=True)]  # np.split: 3x slower
