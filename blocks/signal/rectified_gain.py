"""Rectified gains on up to three aligned streams and one one-sample-ahead difference, with
optional noise and saturation: the input current of TouchSim's afferent models."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numba import njit

import flowtact.api as ft
from flowtact.blocks.spiking.normal_draws import fill_normal, seed_state, shard_noise_offset

__all__ = [
    "RectifiedGain",
    "RectifiedGainConfig",
    "fused_current",
    "rectified_current",
]

_INPUTS = ("x1", "x2", "x3")


@njit(cache=True)
def _rect(v: float, gp: float, gn: float) -> float:
    return gp * max(v, 0.0) - gn * min(v, 0.0)


@njit(cache=True)
def fused_current(
    y: np.ndarray,
    h1: np.ndarray,
    x1: np.ndarray,
    h2: np.ndarray,
    x2: np.ndarray,
    h3: np.ndarray,
    x3: np.ndarray,
    k: int,
    gains: np.ndarray,
    active: np.ndarray,
    ahead: int,
    xi: np.ndarray,
    sd: np.ndarray,
    sat: np.ndarray,
    noisy: bool,
) -> int:
    """The whole current in one pass: ``y[i]`` from rows ``[h[:k], x…]`` of each active input (gains
    rows 2j, 2j+1), the ahead difference of input ``ahead`` (gains rows 6, 7; −1: none), noise
    ``sd·ξ``, then saturation where ``sat`` > 0 (NaN → 0). The same sums in the same order as
    :func:`rectified_current`. Returns how many values are not finite (overflow)."""  # fmt: skip
    n, nc = y.shape
    a1, a2, a3 = active[0], active[1], active[2]
    bad = 0
    for i in range(n):
        r1 = h1[i] if i < k else x1[i - k]
        r2 = h2[i] if i < k else x2[i - k]
        r3 = h3[i] if i < k else x3[i - k]
        q, ra = r1, r1  # no ahead difference: never read
        if ahead == 0:
            q, ra = x1[i + 1 - k], r1
        elif ahead == 1:
            q, ra = x2[i + 1 - k], r2
        elif ahead == 2:
            q, ra = x3[i + 1 - k], r3
        for c in range(nc):
            acc = 0.0
            if a1:
                acc += _rect(r1[c], gains[0, c], gains[1, c])
            if a2:
                acc += _rect(r2[c], gains[2, c], gains[3, c])
            if a3:
                acc += _rect(r3[c], gains[4, c], gains[5, c])
            if ahead >= 0:
                acc += _rect(q[c] - ra[c], gains[6, c], gains[7, c])
            if noisy:
                acc = acc + sd[c] * xi[i * nc + c]
            p = sat[c]
            if p > 0.0:
                acc = p * acc / (p + abs(acc))
                if acc != acc:
                    acc = 0.0
            y[i, c] = acc
            if not math.isfinite(acc):
                bad += 1
    return bad


def rectified_current(
    terms: list[tuple[np.ndarray, np.ndarray, np.ndarray]],
    xi: np.ndarray | None,
    noise_sd: np.ndarray,
    saturation: np.ndarray,
) -> np.ndarray:
    """``Σ (g⁺·max(x,0) − g⁻·min(x,0))`` over ``terms`` (x (n, C), g⁺ (C,), g⁻ (C,)) in order, plus
    ``noise_sd·xi``, then ``p·I/(p+|I|)`` where ``saturation`` p > 0 (NaN → 0 there).

    The plain-numpy statement of what the kernels compute (the test reference): elementwise in a
    fixed order, so the result of a sample never depends on its neighbours.
    """
    with np.errstate(over="ignore", invalid="ignore"):  # overflow: ±inf (counted by the block)
        x0, gp, gn = terms[0]
        y = gp * np.maximum(x0, 0.0) - gn * np.minimum(x0, 0.0)
        for x, gp, gn in terms[1:]:
            y = y + (gp * np.maximum(x, 0.0) - gn * np.minimum(x, 0.0))
        if xi is not None:
            y = y + noise_sd * xi
        sat = saturation > 0
        if sat.any():
            p = np.where(sat, saturation, 1.0)
            ys = p * y / (p + np.abs(y))
            ys[np.isnan(ys)] = 0.0
            y = np.where(sat, ys, y)
    return y


#: Channels per noise stream: channel c draws from stream c // NOISE_GROUP, in (sample, channel)
#: order, so a population up to 4 096 channels is one flat stream and a shard cut at a multiple of
#: it draws every channel's normals as the whole population does (nlif's grouping, same size).
NOISE_GROUP = 4096
_PER_CHANNEL = (
    "pos1",
    "neg1",
    "pos2",
    "neg2",
    "pos3",
    "neg3",
    "ahead_pos",
    "ahead_neg",
    "noise_sd",
    "saturation",
)


@dataclass(frozen=True)
class RectifiedGainConfig(ft.BadDataConfig):
    """Parameters of :class:`RectifiedGain` (every gain list: one value for all channels, or one each)."""

    pos1: tuple[float, ...] = ft.param((1.0,), doc="gain on the positive part of x1, per channel", min_len=1)
    neg1: tuple[float, ...] = ft.param(
        (0.0,), doc="gain on the negative part of x1 (I −= g·min(x1,0))", min_len=1
    )
    pos2: tuple[float, ...] = ft.param((0.0,), doc="gain on the positive part of x2, per channel", min_len=1)
    neg2: tuple[float, ...] = ft.param((0.0,), doc="gain on the negative part of x2, per channel", min_len=1)
    pos3: tuple[float, ...] = ft.param((0.0,), doc="gain on the positive part of x3, per channel", min_len=1)
    neg3: tuple[float, ...] = ft.param((0.0,), doc="gain on the negative part of x3, per channel", min_len=1)
    ahead: Literal["none", "x1", "x2", "x3"] = ft.param(
        "none", doc="the input whose one-sample-ahead difference x[n+1] − x[n] gets ahead_pos/ahead_neg"
    )
    ahead_pos: tuple[float, ...] = ft.param(
        (0.0,), doc="gain on the positive part of the ahead difference", min_len=1
    )
    ahead_neg: tuple[float, ...] = ft.param(
        (0.0,), doc="gain on the negative part of the ahead difference", min_len=1
    )
    noise_sd: tuple[float, ...] = ft.param(
        (0.0,), doc="s.d. of the normal noise added per sample before saturation", min_len=1
    )
    saturation: tuple[float, ...] = ft.param(
        (0.0,), doc="p in I·p/(p+|I|) per channel; 0: no saturation", min_len=1
    )
    units: str = ft.param("1", doc="units of the output current")

    noise_offset: int = ft.param(
        0,
        doc="a shard's first channel in the whole population (set by shards: K): its noise streams are "
        "the whole population's from there on; a multiple of 4096 (one noise stream's channels)",
        ge=0,
    )

    def check(self) -> None:
        if self.noise_offset % NOISE_GROUP:
            raise self.error("noise_offset", f"must be a multiple of {NOISE_GROUP}; got {self.noise_offset}")
        if any(v < 0 for v in self.noise_sd):
            raise self.error("noise_sd", "must be >= 0")
        if any(v < 0 for v in self.saturation):
            raise self.error("saturation", "must be >= 0 (0: no saturation)")

    def gains(self) -> dict[str, tuple[tuple[float, ...], tuple[float, ...]]]:
        """(positive, negative) gains per input, and under ``"ahead"`` those of the difference."""
        return {
            "x1": (self.pos1, self.neg1),
            "x2": (self.pos2, self.neg2),
            "x3": (self.pos3, self.neg3),
            "ahead": (self.ahead_pos, self.ahead_neg),
        }


def _nonzero(g: tuple[tuple[float, ...], tuple[float, ...]]) -> bool:
    return any(v != 0 for v in g[0] + g[1])


class RectifiedGain(ft.Block):
    """Rectified gains on up to three streams and one's ahead difference; noise, then saturation.

    Config
    ------
    See :class:`RectifiedGainConfig`. TouchSim's afferent p (x1 = s, x2 = d, both prefiltered):
    ``pos1: p1, neg1: p2, pos2: p3, neg2: p4, ahead: x2, ahead_pos: p5, ahead_neg: p6,
    noise_sd: p8, saturation: p7``.

    Notes
    -----
    I[n] = Σ_k (g⁺_k·max(x_k[n], 0) − g⁻_k·min(x_k[n], 0)) + g⁺_Δ·max(Δ[n], 0) − g⁻_Δ·min(Δ[n], 0)
    with Δ[n] = a[n+1] − a[n] for the ``ahead`` input a (no 1/dt factor), then I += σ·ξ[n]
    (ξ ~ N(0, 1), one per sample and channel), then I = p·I/(p + |I|) where p > 0 (NaN → 0).
    Time stamps: output sample n carries input sample n's time — it describes that instant. With
    ``ahead`` set, sample n can be computed only once sample n+1 has arrived, so the block holds
    back one sample (latency one sample period, in arrival, not in stamps); at the end of the
    stream (flush) the held last sample is emitted with Δ = 0, as TouchSim does. Nothing is lost.
    Inputs are paired by arrival and must carry equal stamps (:class:`MisalignedError`);
    samples unpaired at the end are counted (``unpaired_at_end``). Inputs whose gains are all
    zero are not needed (x1 always is: it is the clock). The noise is exact N(0, 1) from
    the seeded xoshiro256++/ziggurat stream of the spiking family (:mod:`normal_draws`), drawn in
    sample-major order from one flat stream: chunking never changes a bit.

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.signal.rectified_gain import RectifiedGain
    >>> from flowtact.testing import run_offline
    >>> d = np.array([0.0, 1.0, 3.0, 2.0])
    >>> out = run_offline(RectifiedGain(pos1=[2.0], neg1=[1.0], ahead="x1", ahead_pos=[10.0]), x1=d)
    >>> out["y"].data.tolist()                            # 2·d + 10·max(d[n+1] − d[n], 0)
    [10.0, 22.0, 6.0, 4.0]
    """

    config_cls = RectifiedGainConfig
    shardable = True
    per_unit_params = _PER_CHANNEL
    inputs = {
        "x1": ft.Port(
            dtype="float64", ndim=(0, 1), require_rate=True, doc="first input (the output's clock)"
        ),
        "x2": ft.Port(dtype="float64", ndim=(0, 1), require_rate=True, optional=True, doc="second input"),
        "x3": ft.Port(dtype="float64", ndim=(0, 1), require_rate=True, optional=True, doc="third input"),
    }
    outputs = {"y": ft.Port(dtype="float64", doc="rectified weighted sum (a current), shape of x1")}
    counter_docs = {
        "nonfinite_drop": "instants where an input had NaN/inf, removed from every input (on_bad_data: "
        "drop): upstream sent bad data",
        "nonfinite_hold": "input samples (per input) with NaN/inf, held at the last finite value "
        "(on_bad_data: hold): upstream sent bad data",
        "overflow": "samples whose current of finite inputs overflowed float64 (no saturation on that "
        "channel): emitted as ±inf or NaN, so the consumer's on_bad_data applies; gains or inputs far off",
        "unpaired_at_end": "input samples with no partners on the other inputs when the stream ended: not "
        "used (the inputs delivered different numbers of samples)",
    }

    @classmethod
    def shard_units(cls, config: RectifiedGainConfig) -> int | None:
        """The channels its per-channel parameters give (None when every one is a single value)."""
        n = max(len(getattr(config, k)) for k in _PER_CHANNEL)
        return n if n > 1 else None

    @classmethod
    def shard_align(cls, config: RectifiedGainConfig) -> int:
        """Noisy: cut at the noise streams' boundaries (4 096 channels each)."""
        return NOISE_GROUP if any(config.noise_sd) else 1

    @classmethod
    def shard_params(cls, params: dict[str, Any], lo: int, hi: int, n: int) -> dict[str, Any]:
        out = super().shard_params(params, lo, hi, n)
        return shard_noise_offset(out, params, lo, NOISE_GROUP)

    def needs(self, connected: frozenset[str]) -> frozenset[str]:
        g, ahead = self.config.gains(), self.config.ahead
        return frozenset(
            p for p in connected if p == "x1" or _nonzero(g[p]) or (p == ahead and _nonzero(g["ahead"]))
        )

    def specs(self, inputs: Mapping[str, ft.StreamSpec]) -> dict[str, ft.StreamSpec]:
        cfg, g = self.config, self.config.gains()
        x1 = inputs["x1"]
        nc = x1.size
        for p in _INPUTS:
            if p not in inputs:
                if _nonzero(g[p]) or (cfg.ahead == p and _nonzero(g["ahead"])):
                    raise ft.SpecError(p, f"gains on '{p}' are not zero but '{p}' is not connected")
                continue
            spec = inputs[p]
            if spec.shape != x1.shape:
                raise ft.SpecError(
                    p, f"input '{p}' has shape {spec.shape} but x1 has {x1.shape} (one channel each)"
                )
            if not math.isclose(spec.rate_hz or 0.0, x1.rate_hz or 0.0, rel_tol=1e-9):
                raise ft.SpecError(p, f"input '{p}' is {spec.rate_hz:g} Hz but x1 is {x1.rate_hz:g} Hz")
        for name in _PER_CHANNEL:
            v = getattr(cfg, name)
            if len(v) not in (1, nc):
                raise ft.SpecError(
                    "x1", f"{name} has {len(v)} values but the inputs have {nc} channel(s) (give 1 or {nc})"
                )
        return {
            "y": ft.StreamSpec(
                dtype="float64", shape=x1.shape, units=cfg.units, rate_hz=x1.rate_hz, labels=x1.labels
            )
        }

    def reset(self) -> None:
        cfg = self.config
        spec = self.input_specs["x1"]
        self._shape, self._nc = spec.shape, spec.size
        full = lambda v: np.broadcast_to(np.asarray(v, np.float64), (self._nc,)).copy()  # noqa: E731
        g = cfg.gains()
        self._ports = [p for p in _INPUTS if p in self.needed]
        self._terms = [(p, full(g[p][0]), full(g[p][1])) for p in self._ports if _nonzero(g[p])]
        self._ahead = cfg.ahead if cfg.ahead in self._ports and _nonzero(g["ahead"]) else None
        self._gd = (full(g["ahead"][0]), full(g["ahead"][1]))
        used = {p for p, _, _ in self._terms}
        self._active = np.array([p in used for p in _INPUTS])
        self._ahead_i = _INPUTS.index(self._ahead) if self._ahead is not None else -1
        self._gains = np.zeros((8, self._nc))
        for j, p in enumerate(_INPUTS):
            if p in used:
                self._gains[2 * j], self._gains[2 * j + 1] = full(g[p][0]), full(g[p][1])
        self._gains[6], self._gains[7] = self._gd
        self._sd = full(cfg.noise_sd)
        self._sat = full(cfg.saturation)
        self._rng_state: list[np.ndarray] | None = None
        if self._sd.any():
            for _ in range(cfg.noise_offset // NOISE_GROUP):  # the streams of channels before the shard
                seed_state(self.rng)
            self._rng_state = [seed_state(self.rng) for _ in range(-(-self._nc // NOISE_GROUP))]
        rate = spec.rate_hz or 1.0
        self._align = ft.Aligner(self.node, self.input_specs, self._ports, tol_s=1e-6 / rate)
        self._last: dict[str, np.ndarray | None] = {p: None for p in self._ports}
        self._held_t = np.empty(0)
        self._held: dict[str, np.ndarray] = {p: np.empty((0, self._nc)) for p in self._ports}

    def _current(self, head: dict[str, np.ndarray], x: dict[str, np.ndarray], k: int, n: int) -> np.ndarray:
        """The current of ``n`` rows ``[head[:k], x…]`` of every input (the ahead difference looks one
        row further), noise and saturation included: one pass of :func:`fused_current`."""
        y = np.empty((n, self._nc))
        h0, x0 = head["x1"], x["x1"]  # stand-ins for inputs not used (never read: zero flags)
        hx = [(head.get(p, h0), x.get(p, x0)) for p in _INPUTS]
        noisy = self._rng_state is not None
        xi = np.empty(n * self._nc if noisy else 0)
        if noisy:
            self._draw(xi, n)
        bad = fused_current(
            y,
            *hx[0],
            *hx[1],
            *hx[2],
            k,
            self._gains,
            self._active,
            self._ahead_i,
            xi,
            self._sd,
            self._sat,
            noisy,
        )
        self.count("overflow", bad)
        return y

    def _draw(self, xi: np.ndarray, n: int) -> None:
        """``n`` samples' normals in (sample, channel) order, each group of channels from its stream."""
        states = self._rng_state or []
        if len(states) == 1:
            fill_normal(states[0], xi)
            return
        grid = xi.reshape(n, self._nc)
        for g, state in enumerate(states):
            lo, hi = g * NOISE_GROUP, min(self._nc, (g + 1) * NOISE_GROUP)
            part = np.empty(n * (hi - lo))
            fill_normal(state, part)
            grid[:, lo:hi] = part.reshape(n, hi - lo)

    def step(self, **inputs: ft.Chunk) -> dict[str, ft.Chunk]:
        t, data = self._align.push(inputs)
        if len(t):
            t, data = ft.screen_aligned(self, self.config.on_bad_data, t, data, self._last)
        m = len(t)
        data = {p: np.ascontiguousarray(d.reshape(m, self._nc), np.float64) for p, d in data.items()}
        if self._ahead is None:
            y = self._current(data, data, 0, m) if m else np.empty((0, self._nc))
            return {"y": ft.Chunk(t, y.reshape(m, *self._shape))}
        if not m:
            return {"y": ft.Chunk.empty(shape=self._shape)}
        k = len(self._held_t)  # 1 once a sample is held back, 0 at the start
        n = k + m - 1
        head = self._held if k else data
        t_out = np.concatenate([self._held_t, t[:-1]]) if k else t[:-1]
        y = self._current(head, data, k, n)
        self._held_t = t[-1:].copy()
        self._held = {p: d[-1:].copy() for p, d in data.items()}
        return {"y": ft.Chunk(t_out, y.reshape(n, *self._shape))}

    def flush(self) -> dict[str, ft.Chunk]:
        self.count("unpaired_at_end", sum(self._align.pending().values()))
        if self._ahead is None or not len(self._held_t):
            return {}
        t, held = self._held_t, self._held
        self._held_t = np.empty(0)
        y = self._current(held, held, 1, 1)  # Δ = held − held = 0: TouchSim's last sample
        return {"y": ft.Chunk(t, y.reshape(1, *self._shape))}

    @classmethod
    def example(cls) -> ft.Example:
        rng = np.random.default_rng(4)
        n = 600
        s = np.cumsum(rng.normal(0.0, 0.01, (n, 2)), axis=0)
        d = np.gradient(s, axis=0) * 50.0
        return ft.Example(
            params={
                "pos1": [30.0, 10.0],
                "neg1": [5.0],
                "pos2": [-250.0, 40.0],
                "neg2": [-180.0, 20.0],
                "ahead": "x2",
                "ahead_pos": [1400.0, 300.0],
                "ahead_neg": [600.0, 100.0],
                "noise_sd": [0.05],
                "saturation": [10.0, 0.0],
            },
            inputs={"x1": s, "x2": d},
            rate_hz=5000.0,
            units={"x1": "1", "x2": "1"},
        )
