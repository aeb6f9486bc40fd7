"""``touchsim_chain``: TouchSim's whole per-afferent model (prefilter, rectified gains, noise,
saturation, membrane) in one block, one pass over memory per sample — the chain
``iir → iir → rectified_gain → nlif`` of graphs/touchsim_afferents.yaml, fused for speed.

Why: the chain of generic blocks writes and reads a (samples × afferents) float64 array per stage
and tick, fresh each time (chunks are sealed and shared, so no stage may reuse its output); for the
whole hand (8 450 afferents a shard, 25-sample ticks) that is 1.7 MB a stage a tick, and most of the
CPU went to memory traffic and to the kernel's zero-filling of fresh pages. Here the prefilters and
the current are computed a sample at a time into buffers the block owns (nothing leaves it but the
spikes), s is filtered only where a model weighs it (TouchSim filters s for SA1 only; RA and PC
have p1 = p2 = 0), and the membranes run on nlif's own kernel.

The arithmetic is the generic blocks', term for term and in the same order (:func:`chain_rows`
against ``iir.sos_apply`` and ``rectified_gain.fused_current``), so spikes and current are
bit-identical to the chain bound with the same seeds (tests/blocks/touch/test_touchsim_chain.py).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

import flowtact.api as ft
from flowtact.blocks.signal.iir import design_sos
from flowtact.blocks.signal.rectified_gain import NOISE_GROUP
from flowtact.blocks.spiking.nlif import Nlif
from flowtact.blocks.spiking.normal_draws import fill_normal, seed_state
from flowtact.blocks.touch.touchsim import touchsim_models

__all__ = ["TouchsimChain", "TouchsimChainConfig", "chain_rows"]

_EMPTY = np.empty(0, np.int64)


@njit(cache=True)
def _filter_row(x, i, units, sos, zi, v):  # type: ignore[no-untyped-def]
    """Sample ``i`` of ``x`` through the sections of channels ``units`` (``iir.sos_apply``'s update
    in its order); the output in ``v``."""
    nu = units.shape[0]
    for j in range(nu):
        c = units[j]
        v[c] = x[i, c]
    for s in range(sos.shape[0]):
        b0, b1, b2, a1, a2 = sos[s, 0], sos[s, 1], sos[s, 2], sos[s, 4], sos[s, 5]
        z0, z1 = zi[s, 0], zi[s, 1]
        for j in range(nu):
            c = units[j]
            out = b0[c] * v[c] + z0[c]
            z0[c] = b1[c] * v[c] - a1[c] * out + z1[c]
            z1[c] = b2[c] * v[c] - a2[c] * out
            v[c] = out


@njit(cache=True)
def _filter_row_all(x, i, sos, zi, v):  # type: ignore[no-untyped-def]
    """:func:`_filter_row` over every channel (contiguous: the loops vectorise)."""
    nc = v.shape[0]
    for c in range(nc):
        v[c] = x[i, c]
    for s in range(sos.shape[0]):
        b0, b1, b2, a1, a2 = sos[s, 0], sos[s, 1], sos[s, 2], sos[s, 4], sos[s, 5]
        z0, z1 = zi[s, 0], zi[s, 1]
        for c in range(nc):
            out = b0[c] * v[c] + z0[c]
            z0[c] = b1[c] * v[c] - a1[c] * out + z1[c]
            z1[c] = b2[c] * v[c] - a2[c] * out
            v[c] = out


@njit(cache=True)
def _current_row(hs, hd, qd, g, sd, sat, noisy, xi, y):  # type: ignore[no-untyped-def]
    """One sample's current from the held filtered s, d and the next d (``rectified_gain``'s
    ``fused_current``, term for term): ``y``. Returns the values that are not finite."""
    bad = 0
    for c in range(y.shape[0]):
        acc = 0.0
        v = hs[c]
        acc += g[0, c] * max(v, 0.0) - g[1, c] * min(v, 0.0)
        v = hd[c]
        acc += g[2, c] * max(v, 0.0) - g[3, c] * min(v, 0.0)
        v = qd[c] - hd[c]
        acc += g[4, c] * max(v, 0.0) - g[5, c] * min(v, 0.0)
        if noisy:
            acc = acc + sd[c] * xi[c]
        p = sat[c]
        if p > 0.0:
            acc = p * acc / (p + abs(acc))
            if acc != acc:
                acc = 0.0
        y[c] = acc
        if not math.isfinite(acc):
            bad += 1
    return bad


@njit(cache=True)
def chain_rows(  # type: ignore[no-untyped-def]
    s, d, s_units, sos_s, zi_s, sos_d, zi_d, held, has_held, last, g, sd, sat, noisy, rng, xi, cur
):
    """Prefilter the rows of ``s`` (channels ``s_units`` only) and ``d`` (every channel) and make the
    current of each held sample once the next has come (its Δd = d[n+1] − d[n]); with ``last`` the
    held sample's own current (Δd = 0, the stream's end) after them. ``held`` (2, C): the held
    filtered s and d (s is 0 where not filtered: those channels' s gains are 0). Writes the current
    rows into ``cur`` and returns (rows, whether a sample is held, values not finite). The noise
    ``xi`` (C) of a row is drawn per group of :data:`NOISE_GROUP` channels from its stream
    ``rng[g]`` (``rectified_gain``'s draw order: a stream continues whatever the chunking)."""
    n, nc = s.shape[0], held.shape[1]
    vs = np.zeros(nc)
    vd = np.empty(nc)
    rows = 0
    bad = 0
    total = n + (1 if last and (has_held or n > 0) else 0)
    for i in range(total):
        if i < n:
            _filter_row(s, i, s_units, sos_s, zi_s, vs)
            _filter_row_all(d, i, sos_d, zi_d, vd)
        else:
            vd[:] = held[1]  # the end: Δd = held − held = 0
        if has_held:
            if noisy:
                for q in range(rng.shape[0]):
                    fill_normal(rng[q], xi[q * NOISE_GROUP : min(nc, (q + 1) * NOISE_GROUP)])
            bad += _current_row(held[0], held[1], vd, g, sd, sat, noisy, xi, cur[rows])
            rows += 1
        if i < n:
            for j in range(s_units.shape[0]):
                c = s_units[j]
                held[0, c] = vs[c]
            held[1, :] = vd
            has_held = True
        else:
            has_held = False
    return rows, has_held, bad


@dataclass(frozen=True)
class TouchsimChainConfig(ft.BadDataConfig):
    """Parameters of :class:`TouchsimChain`."""

    models: tuple[str, ...] = ft.param(
        ("SA1.0",), doc="TouchSim model per afferent (column), SA1.0-3, RA.0-8, PC.0-3", min_len=1
    )
    noise_scale: float = ft.param(1.0, doc="multiplies each model's noise s.d. p8 (0: noise off)", ge=0)
    noise_offset: int = ft.param(
        0,
        doc="a shard's first afferent in the whole population (set by shards: K): its noise streams are "
        "the whole population's from there on; a multiple of 4096 (one noise stream's afferents)",
        ge=0,
    )

    def check(self) -> None:
        known = touchsim_models()
        for m in self.models:
            if m not in known:
                raise self.error("models", f"unknown TouchSim model {m!r} (known: {', '.join(known)})")
        if self.noise_offset % NOISE_GROUP:
            raise self.error("noise_offset", f"must be a multiple of {NOISE_GROUP}; got {self.noise_offset}")


class TouchsimChain(ft.Block):
    """TouchSim's per-afferent model from s and d to spikes in one block (one model per column).

    Config
    ------
    See :class:`TouchsimChainConfig`.

    Notes
    -----
    The same computation as graphs/touchsim_afferents.yaml's chain, bit for bit (the same seed:
    the same noise): ``iir`` (butter, order 3, 10·p0 Hz) on s and d, ``rectified_gain`` (p1–p6,
    Δd one sample ahead, noise p8·ξ before saturation p7; noise from one stream per 4 096 afferents
    in (sample, afferent) order), ``nlif`` with ``models:`` (TouchSim's membrane, last-spike history,
    threshold block). Spikes are stamped with their input sample's time (TouchSim's (n + 1)/fs is one
    sample later). It holds back one sample, as rectified_gain does (Δd needs the next one), and
    emits it at the end with Δd = 0. s is filtered only for afferents whose model weighs it (SA1):
    the others' s terms are 0 in the chain too. Inputs are paired by arrival (equal stamps);
    ``current`` (optional) is the input current of the membranes.

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.touch.touchsim_chain import TouchsimChain
    >>> from flowtact.testing import run_offline
    >>> t = np.arange(4000) / 5000.0
    >>> s = np.tile(0.0128 * np.clip(t / 0.05, 0, 1)[:, None], (1, 2))
    >>> d = np.tile((4.0 * (t < 0.05))[:, None], (1, 2))
    >>> out = run_offline(TouchsimChain(models=["SA1.0", "RA.3"], noise_scale=0.0), s=s, d=d, rate_hz=5000.0)
    >>> np.bincount(out["spikes"].data, minlength=2).tolist()     # spikes per afferent
    [28, 1]
    """

    config_cls = TouchsimChainConfig
    shardable = True
    per_unit_params = ("models",)
    inputs = {
        "s": ft.Port(dtype="float64", ndim=(1,), require_rate=True, doc="static term per afferent"),
        "d": ft.Port(dtype="float64", ndim=(1,), require_rate=True, doc="dynamic term per afferent"),
    }
    outputs = {
        "spikes": ft.Port(dtype="int64", events=True, doc="spike events, data = afferent index"),
        "current": ft.Port(dtype="float64", optional=True, doc="the membranes' input current"),
    }
    counter_docs = {
        "nonfinite_drop": "instants where s or d had NaN/inf, removed from both (on_bad_data: drop)",
        "nonfinite_hold": "samples (per input) with NaN/inf, held at the last finite value (on_bad_data: hold)",
        "overflow": "current values that overflowed float64 (inputs far off)",
        "unpaired_at_end": "input samples with no partner on the other input when the stream ended",
    }

    @classmethod
    def shard_units(cls, config: TouchsimChainConfig) -> int | None:
        """One unit per model."""
        return len(config.models) if len(config.models) > 1 else None

    @classmethod
    def shard_align(cls, config: TouchsimChainConfig) -> int:
        """Noisy: cut at the noise streams' boundaries (4 096 afferents each)."""
        return NOISE_GROUP if config.noise_scale > 0 else 1

    @classmethod
    def shard_params(cls, params: dict[str, Any], lo: int, hi: int, n: int) -> dict[str, Any]:
        out = super().shard_params(params, lo, hi, n)
        offset = int(params.get("noise_offset", 0)) + lo
        if offset % NOISE_GROUP == 0:  # always so with noise (shard_align); without, it changes nothing
            out["noise_offset"] = offset
        return out

    def specs(self, inputs: Mapping[str, ft.StreamSpec]) -> dict[str, ft.StreamSpec]:
        s = inputs["s"]
        n = len(self.config.models)
        for p in ("s", "d"):
            spec = inputs[p]
            if spec.shape != (n,):
                raise ft.SpecError(p, f"input '{p}' has shape {spec.shape} but models lists {n} afferents")
            if not math.isclose(spec.rate_hz or 0.0, s.rate_hz or 0.0, rel_tol=1e-9):
                raise ft.SpecError(p, f"input '{p}' is {spec.rate_hz:g} Hz but s is {s.rate_hz:g} Hz")
        for m in self.config.models:
            if 10.0 * touchsim_models()[m][0] >= 0.5 * float(s.rate_hz or 0.0):
                raise ft.SpecError("s", f"model {m}'s prefilter cut-off must be below half the rate")
        return {
            "spikes": ft.StreamSpec(dtype="int64", shape=(), units="1", events=True, n_units=n),
            "current": ft.StreamSpec(dtype="float64", shape=(n,), units="1", rate_hz=s.rate_hz),
        }

    def reset(self) -> None:
        cfg = self.config
        spec = self.input_specs["s"]
        n = self._n = len(cfg.models)
        rate = float(spec.rate_hz or 0.0)
        self._dt = 1.0 / rate
        p = np.array([touchsim_models()[m] for m in cfg.models], np.float64)
        nyq = 0.5 * rate
        sos = [design_sos("butter", 3, "lowpass", f / nyq) for f in (10.0 * p[:, 0]).tolist()]
        self._sos = np.ascontiguousarray(np.stack(sos, axis=-1), np.float64)  # (S, 6, C), as iir
        self._zi_s = np.zeros((self._sos.shape[0], 2, n))
        self._zi_d = np.zeros((self._sos.shape[0], 2, n))
        self._s_units = np.flatnonzero((p[:, 1] != 0) | (p[:, 2] != 0)).astype(np.int64)
        self._g = np.ascontiguousarray(p[:, 1:7].T)  # rows p1 … p6
        self._sd = cfg.noise_scale * p[:, 8]
        self._sat = p[:, 7].copy()
        self._noisy = bool(self._sd.any())
        self._rng = np.zeros((0, 1), np.uint64)
        if self._noisy:
            for _ in range(cfg.noise_offset // NOISE_GROUP):  # the streams of afferents before the shard
                seed_state(self.rng)
            self._rng = np.stack([seed_state(self.rng) for _ in range(-(-n // NOISE_GROUP))])
        self._xi = np.zeros(n)
        self._held = np.zeros((2, n))
        self._has_held = False
        self._held_t = np.empty(0)
        self._cur = np.empty((0, n))
        self._neurons = Nlif(models=list(cfg.models))
        self._neurons.bind(
            {"x": ft.StreamSpec(dtype="float64", shape=(n,), rate_hz=rate)},
            seed=self.seed,
            demanded=frozenset({"spikes"}),
        )
        self._align = ft.Aligner(self.node, self.input_specs, ["s", "d"], tol_s=1e-6 / rate)
        self._last: dict[str, np.ndarray | None] = {"s": None, "d": None}
        self._end: float | None = None
        self._want_current = "current" in self.demanded

    def _run(self, t: np.ndarray, s: np.ndarray, d: np.ndarray, last: bool) -> dict[str, ft.Chunk]:
        """The rows of s, d (and with ``last`` the held sample) through the whole model."""
        m = len(t)
        if self._cur.shape[0] < m + 1:  # the block's own scratch: reused, never handed out
            self._cur = np.empty((m + 1, self._n))
        had = self._has_held
        rows, self._has_held, bad = chain_rows(
            s, d, self._s_units, self._sos, self._zi_s, self._sos, self._zi_d, self._held, had, last,
            self._g, self._sd, self._sat, self._noisy, self._rng, self._xi, self._cur,
        )  # fmt: skip
        self.count("overflow", bad)
        t_out = np.concatenate([self._held_t, t])[:rows] if had else t[:rows]
        if m:
            self._held_t = t[-1:].copy()
        out: dict[str, ft.Chunk] = {}
        if not rows:
            out["spikes"] = ft.Chunk.empty(dtype="int64", end=self._end)
            if self._want_current:
                out["current"] = ft.Chunk.empty(shape=(self._n,))
            return out
        cur = self._cur[:rows]
        steps, _, idx = self._neurons.integrate(cur)
        self._end = t_out[-1].item() + self._dt
        out["spikes"] = ft.Chunk(t_out[steps], idx.copy() if len(idx) else _EMPTY, self._end)
        if self._want_current:
            out["current"] = ft.Chunk(t_out, cur.copy())
        return out

    def step(self, s: ft.Chunk, d: ft.Chunk) -> dict[str, ft.Chunk]:
        t, data = self._align.push({"s": s, "d": d})
        if len(t):
            t, data = ft.screen_aligned(self, self.config.on_bad_data, t, data, self._last)
        m = len(t)
        sd = [np.ascontiguousarray(data[p].reshape(m, self._n), np.float64) for p in ("s", "d")]
        return self._run(t, sd[0], sd[1], False)

    def flush(self) -> dict[str, ft.Chunk]:
        self.count("unpaired_at_end", sum(self._align.pending().values()))
        if not self._has_held:
            return {}
        none = np.empty((0, self._n))
        return self._run(np.empty(0), none, none, True)

    @classmethod
    def example(cls) -> ft.Example:
        t = np.arange(2500) / 5000.0
        ramp = np.clip((t - 0.05) / 0.05, 0.0, 1.0)[:, None]
        s = ramp * np.array([0.0128, 0.0029, 0.0019])
        d = np.gradient(ramp, axis=0)[:, :1] * 5000.0 * 0.05 * np.array([4.0, 0.14, 0.09])
        return ft.Example(
            params={"models": ["SA1.0", "RA.3", "PC.1"]},
            inputs={"s": s, "d": d},
            rate_hz=5000.0,
            units={"s": "1", "d": "1"},
        )
