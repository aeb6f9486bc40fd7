"""Filters: a streaming Savitzky–Golay smoother/differentiator, a weighted sum, a one-tick delay.

Also two helpers other blocks use: :func:`deriv_units` (``"N"`` → ``"N/s"`` → ``"N/s^2"``) and
:class:`Aligner`, which buffers several sample streams and releases their common, sample-aligned
prefix (inputs that reach a block with different delays).

:class:`Lowpass` is a first-order low-pass on the samples' own timestamps (the exoskeleton's FSRs).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from fractions import Fraction
from functools import lru_cache
from typing import Literal

import numpy as np
from numba import njit

from flowtact import (
    Block,
    Chunk,
    Config,
    Example,
    Port,
    SpecError,
    StreamSpec,
    nonfinite_counter_docs,
    param,
    screen_nonfinite,
)
from flowtact.align import Aligner, MisalignedError, screen_aligned

from .afferents import table_i_weights

__all__ = [
    "Aligner",
    "Delay",
    "DelayConfig",
    "Lowpass",
    "LowpassConfig",
    "MisalignedError",
    "SavGol",
    "SavGolConfig",
    "WeightedSum",
    "WeightedSumConfig",
    "deriv_units",
    "lowpass_apply",
    "lowpass_apply_python",
    "savgol_apply",
    "savgol_apply_numpy",
    "savgol_coeffs",
    "screen_aligned",
]

BadData = Literal["raise", "drop", "hold"]

#: The filter of Rager et al. (Fig. 3): Savitzky–Golay, polynomial order 4, frame of 5 samples.
RAGER_WINDOW, RAGER_ORDER = 5, 4


# -- helpers -------------------------------------------------------------------------------------


def deriv_units(units: str, deriv: int) -> str:
    """Units of the ``deriv``-th time derivative: ``"N"`` → ``"N/s"`` → ``"N/s^2"``.

    A trailing ``/s`` or ``/s^k`` is merged (``deriv_units("N/s", 1) == "N/s^2"``); ``deriv == 0``
    returns ``units`` unchanged.
    """
    if deriv == 0:
        return units
    m = re.fullmatch(r"(.*)/s(?:\^(\d+))?", units)
    base, k = (m.group(1), int(m.group(2) or 1)) if m else (units, 0)
    k += deriv
    return f"{base}/s" if k == 1 else f"{base}/s^{k}"


def _n_channels(spec: StreamSpec) -> int:
    return int(np.prod(spec.shape)) if spec.shape else 1


def _check_float_stream(port: str, spec: StreamSpec) -> None:
    if spec.events or spec.rate_hz is None:
        raise SpecError(port, f"input '{port}' must be a sampled stream with a rate, got {spec.describe()}")
    if spec.dtype != "float64":
        raise SpecError(port, f"input '{port}' must be float64, got {spec.dtype}")
    if len(spec.shape) > 1:
        raise SpecError(port, f"input '{port}' must have shape () or (channels,), got {spec.shape}")


# -- Savitzky–Golay coefficients ------------------------------------------------------------------


@lru_cache(maxsize=128)
def _exact_coeffs(window: int, order: int, deriv: int, pos: int) -> tuple[Fraction, ...]:
    """Least-squares SG weights per sample (no delta), exactly, as rationals (oldest sample first).

    Fit p(z) = Σ_j β_j z^j to the window at integer positions z_k = k − pos by least squares;
    the d-th derivative at z = 0 is d!·β_d = Σ_k c_k x_k with c = d!·(row d of (AᵀA)⁻¹)·Aᵀ,
    A the Vandermonde matrix. The normal equations are solved exactly in rational arithmetic, so
    each float coefficient is the correctly rounded true value (5/4, deriv 0 is exactly [0,0,1,0,0]).
    """
    z = [k - pos for k in range(window)]
    m = order + 1
    powers = [sum(Fraction(zk) ** e for zk in z) for e in range(2 * order + 1)]
    g = [[powers[i + j] for j in range(m)] + [Fraction(int(i == deriv))] for i in range(m)]
    for col in range(m):  # Gauss–Jordan on [G | e_d]; G is symmetric positive definite
        piv = next(r for r in range(col, m) if g[r][col] != 0)
        g[col], g[piv] = g[piv], g[col]
        p = g[col][col]
        g[col] = [v / p for v in g[col]]
        for r in range(m):
            if r != col and g[r][col] != 0:
                f = g[r][col]
                g[r] = [a - f * b for a, b in zip(g[r], g[col], strict=True)]
    u = [g[i][m] for i in range(m)]  # row `deriv` of G⁻¹ (G symmetric)
    fact = math.factorial(deriv)
    return tuple(fact * sum(u[j] * Fraction(zk) ** j for j in range(m)) for zk in z)


def savgol_coeffs(
    window: int, order: int, deriv: int = 0, *, pos: int | None = None, rate_hz: float = 1.0
) -> np.ndarray:
    """Savitzky–Golay weights ``c`` (oldest sample first): the estimate is ``c · x[n−N+1 .. n]``.

    ``pos`` is the window position of the estimate (None = centre, ``window − 1`` = newest
    sample); derivatives are per second for the given ``rate_hz`` (per sample with the default 1).
    Equal to ``scipy.signal.savgol_coeffs(window, order, deriv, delta=1/rate_hz, pos=pos,
    use='dot')`` up to rounding (these are the correctly rounded exact values).
    """
    if not (0 <= deriv <= order < window):
        raise ValueError(
            f"need 0 <= deriv <= order < window, got deriv={deriv}, order={order}, window={window}"
        )
    pos = (window - 1) // 2 if pos is None else pos
    if not 0 <= pos < window:
        raise ValueError(f"pos must be in [0, {window - 1}], got {pos}")
    scale = Fraction(rate_hz) ** deriv
    return np.array([float(c * scale) for c in _exact_coeffs(window, order, deriv, pos)], np.float64)


# -- streaming kernel (numba) and its numpy twin -------------------------------------------------


@njit(cache=True)
def savgol_apply(coef: np.ndarray, tail: np.ndarray, x: np.ndarray) -> np.ndarray:
    """FIR ``y[i] = Σ_k coef[k]·ext[i+k]`` over ``ext = tail ++ x``; updates ``tail`` in place.

    ``tail`` (N−1, C) holds the previous N−1 samples (zeros before the stream starts), ``x``
    (n, C). Each output is ``coef[0]·e[i]``, then ``+ coef[k]·e[i+k]`` for k = 1 … N−1 in that
    order, whatever the chunk boundaries (bit-for-bit chunking invariance). The loops run channel
    by channel over contiguous copies with the sample index innermost, so they vectorise without
    reordering any sum.
    """
    m = tail.shape[0]
    n, nc = x.shape
    nk = coef.shape[0]
    ext = np.empty((nc, m + n))
    for c in range(nc):
        for i in range(m):
            ext[c, i] = tail[i, c]
        for i in range(n):
            ext[c, m + i] = x[i, c]
    acc = np.empty(n)
    y = np.empty((n, nc))
    for c in range(nc):
        e = ext[c]
        c0 = coef[0]
        for i in range(n):
            acc[i] = c0 * e[i]
        for k in range(1, nk):
            ck = coef[k]
            for i in range(n):
                acc[i] += ck * e[i + k]
        for i in range(n):
            y[i, c] = acc[i]
    for c in range(nc):
        for i in range(m):
            tail[i, c] = ext[c, n + i]
    return y


def savgol_apply_numpy(coef: np.ndarray, tail: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Plain-numpy twin of :func:`savgol_apply` (same operations in the same order)."""
    m, n = tail.shape[0], x.shape[0]
    ext = np.concatenate([tail, x])
    y = coef[0] * ext[0:n]
    for k in range(1, coef.shape[0]):
        y = y + coef[k] * ext[k : k + n]
    tail[:] = ext[n : n + m]
    return y


# -- savgol ----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SavGolConfig(Config):
    """Parameters of :class:`SavGol`."""

    window: int = param(RAGER_WINDOW, doc="frame length in samples (odd, > order)", ge=3, odd=True)
    order: int = param(RAGER_ORDER, doc="degree of the fitted polynomial", ge=0, le=10)
    deriv: int = param(1, doc="derivative to estimate: 0 smooths, 1 = d/dt (units/s), 2 = d²/dt²", ge=0)
    mode: Literal["causal", "centred"] = param(
        "centred",
        doc="centred: estimate at the window centre, stamped (window-1)/2 samples late; causal: at the newest sample",
    )
    rate_hz: float | None = param(
        None, doc="sample rate the filter is designed for (null: the stream's rate)", gt=0
    )
    preset: Literal["none", "rager"] = param(
        "none", doc="rager: assert the paper's filter (window 5, order 4; mode stays free); none: free"
    )
    padding: Literal["zeros", "hold"] = param(
        "zeros",
        doc="signal assumed outside the stream: zeros (the paper's zero padding) or hold (its first/last sample: no edge transients)",
    )
    on_bad_data: Literal["raise", "drop", "hold"] = param(
        "raise", doc="non-finite samples: raise, drop them, or hold the last good value"
    )

    def check(self) -> None:
        if self.order >= self.window:
            raise self.error("order", f"must be < window ({self.window}); got {self.order}")
        if self.deriv > self.order:
            raise self.error("deriv", f"must be <= order ({self.order}); got {self.deriv}")
        if self.preset == "rager":
            for name, value in (("window", RAGER_WINDOW), ("order", RAGER_ORDER)):
                if getattr(self, name) != value:
                    raise self.error(
                        name,
                        f"must be {value!r} with preset 'rager' (Rager et al.: window 5, order 4); "
                        f"got {getattr(self, name)!r} (set preset: none to choose your own filter)",
                    )


class SavGol(Block):
    """Streaming Savitzky–Golay smoother/differentiator, per channel, in physical units per second.

    Ports
    -----
    x : float64, shape () or (C,), any units, sampled
        Signal; channels are filtered independently along time.
    y : float64, same shape as ``x``; units ``u`` (deriv 0), ``u/s`` (1), ``u/s^2`` (2) ...
        The estimate of the ``deriv``-th derivative. Same rate and labels as ``x``.

    Config
    ------
    See :class:`SavGolConfig`; defaults are the paper's filter (window 5, order 4, centred, zero
    padded) and the first derivative. ``preset: rager`` asserts window 5 / order 4 (any other
    value is an error), so a graph can say that it means the paper's filter; ``deriv`` and
    ``mode`` stay free. The paper filtered offline, which is ``centred``; ``causal`` is the
    zero-latency real-time variant of the same fit, at ×5.9 the F' noise (see below).

    Notes
    -----
    Coefficients: least squares on the Vandermonde of the window, solved exactly (rationals),
    scaled by ``rate_hz^deriv`` (delta = 1/rate_hz), so derivatives are per **second** — the
    convention Table I's weights are read in (blocks/afferents.py). History before the first
    sample is zero (the paper's zero padding). A force sensor that starts under load (Rager's
    120 mN baseline) then sees a step at t = 0 and a huge spurious derivative there; ``padding:
    hold`` assumes the signal held its first value before the stream (and its last value after it,
    for the centred flush), so derivatives start at 0 — what the graphs use.

    *causal*: ``y[n]`` is the estimate at the newest sample, ``c · x[n−N+1..n]``, stamped ``t[n]``;
    latency 0 samples (as stamped; order-2 F'' is nevertheless the centre estimate in disguise and
    lags (N−1)/2 samples, see NUMERICS §1.3).
    *centred*: the output emitted when sample n arrives is the estimate for sample n−(N−1)/2 and is
    stamped with **that sample's time**: the (N−1)/2-sample delay shows in the timestamps. The first
    (N−1)/2 arrivals emit nothing; ``flush()`` emits the last (N−1)/2 estimates with zero padding,
    so a whole run equals ``savgol_filter(x, N, p, deriv, delta=dt, mode='constant')``.
    State: the last N−1 samples (and, centred, the last (N−1)/2 timestamps).

    Window 5 / order 4 is exact interpolation: deriv 0 is the identity (no smoothing at all) and
    the derivatives are the 5-point finite-difference stencils. Output noise is σ·‖c‖₂: at 1 kHz,
    σ = 0.01 N gives F' noise 9.5 N/s centred and 56 N/s causal (×5.9), F'' 3.1e4 / 1.4e5 N/s²,
    against true values of a few N/s and ~200 N/s² for tactile forces: **F' is noise-dominated
    and F'' pure noise** (consistent with the zero F'' weights of Table I). For cleaner
    derivatives use a longer window and a lower order (e.g. 21/2: 0.38 N/s at 10 samples latency;
    ``python bench/savgol.py`` prints the error-vs-latency table).

    ``on_bad_data: drop`` removes samples; the filter then treats their neighbours as adjacent.

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.filters import SavGol
    >>> from flowtact.testing import run_offline
    >>> x = np.arange(10.0) / 1000.0                      # a 1 N/s ramp sampled at 1 kHz
    >>> out = run_offline(SavGol(deriv=1, mode="centred"), x=x, units={"x": "N"})
    >>> np.round(out["y"].data[2:-2], 9).tolist(), float(out["y"].t[0])
    ([1.0, 1.0, 1.0, 1.0, 1.0, 1.0], 0.0)
    """

    name = "savgol"
    config_cls = SavGolConfig
    inputs = {"x": Port(dtype="float64", doc="signal, shape () or (channels,)")}
    outputs = {"y": Port(dtype="float64", doc="smoothed signal or its derivative, per second")}
    counter_docs = nonfinite_counter_docs("samples on 'x'")

    def specs(self, inputs: Mapping[str, StreamSpec]) -> dict[str, StreamSpec]:
        x = inputs["x"]
        _check_float_stream("x", x)
        want = self.config.rate_hz
        assert x.rate_hz is not None
        if want is not None and not math.isclose(want, x.rate_hz, rel_tol=1e-9):
            raise SpecError("x", f"expects {want:g} Hz (rate_hz) but the input stream is {x.rate_hz:g} Hz")
        return {"y": x.with_(units=deriv_units(x.units, self.config.deriv))}

    @property
    def latency_samples(self) -> int:
        """How many samples later than its input sample an estimate is emitted (and stamped)."""
        return 0 if self.config.mode == "causal" else (self.config.window - 1) // 2

    def reset(self) -> None:
        cfg = self.config
        spec = self.input_specs["x"]
        rate = cfg.rate_hz if cfg.rate_hz is not None else spec.rate_hz
        pos = cfg.window - 1 if cfg.mode == "causal" else (cfg.window - 1) // 2
        self._coef = savgol_coeffs(cfg.window, cfg.order, cfg.deriv, pos=pos, rate_hz=float(rate))
        self._shape = spec.shape
        self._nc = _n_channels(spec)
        self._tail = np.zeros((cfg.window - 1, self._nc))
        self._h = self.latency_samples
        self._t_hist = np.empty(0)  # stamps of the last <= h samples (centred)
        self._last: np.ndarray | None = None
        self._started = False  # has a sample arrived (padding: hold primes the history with it)

    def step(self, x: Chunk | None = None, **_: Chunk) -> dict[str, Chunk]:
        if x is None or len(x) == 0:
            return {"y": Chunk(np.empty(0), np.empty((0, *self._shape)))}
        d = x.data
        if not np.isfinite(np.add.reduce(d, axis=None)):  # cheap screen; exact check only on suspicion
            x, self._last = screen_nonfinite(self, x, self.config.on_bad_data, "x", self._last)
            d = x.data
            if len(x) == 0:
                return {"y": Chunk(np.empty(0), np.empty((0, *self._shape)))}
        elif self.config.on_bad_data == "hold":
            self._last = d[-1].copy()
        n = len(x)
        if not self._started:
            self._started = True
            if self.config.padding == "hold":
                self._tail[:] = d.reshape(n, self._nc)[0]
        y = savgol_apply(self._coef, self._tail, d.reshape(n, self._nc))
        if self._h == 0:
            return {"y": Chunk(x.t, y.reshape(n, *self._shape))}
        t_all = np.concatenate([self._t_hist, x.t])
        emit = len(t_all) - self._h
        self._t_hist = t_all[max(emit, 0) :].copy()
        if emit <= 0:
            return {"y": Chunk(np.empty(0), np.empty((0, *self._shape)))}
        return {"y": Chunk(t_all[:emit], y[n - emit :].reshape(emit, *self._shape))}

    def flush(self) -> dict[str, Chunk]:
        k = len(self._t_hist) if self._h else 0
        if k == 0:
            return {}
        pad = np.zeros((self._h, self._nc))
        if self.config.padding == "hold" and self._started:
            pad[:] = self._tail[-1]
        y = savgol_apply(self._coef, self._tail, pad)
        t = self._t_hist
        self._t_hist = np.empty(0)
        return {"y": Chunk(t, y[self._h - k :].reshape(k, *self._shape))}

    @classmethod
    def example(cls) -> Example:
        rng = np.random.default_rng(1)
        n = 600
        force = np.cumsum(rng.normal(0.0, 0.01, (n, 3)), axis=0) + rng.normal(0.0, 0.002, (n, 3))
        return Example(
            params={"window": 5, "order": 4, "deriv": 1, "mode": "centred"},
            inputs={"x": force},
            units={"x": "N"},
        )


# -- weighted_sum -----------------------------------------------------------------------------------

_PRESET_UNITS = {"x1": "N", "x2": deriv_units("N", 1), "x3": deriv_units("N", 2)}
_PRESET_WHAT = {"x1": "forces [Fx, Fy, Fz]", "x2": "first derivatives F'", "x3": "second derivatives F''"}
_INPUTS = ("x1", "x2", "x3", "x4")


@dataclass(frozen=True)
class WeightedSumConfig(Config):
    """Parameters of :class:`WeightedSum`."""

    w1: tuple[float, ...] | None = param(None, doc="weights on x1, one per channel", min_len=1)
    w2: tuple[float, ...] | None = param(None, doc="weights on x2, one per channel", min_len=1)
    w3: tuple[float, ...] | None = param(None, doc="weights on x3, one per channel", min_len=1)
    w4: tuple[float, ...] | None = param(None, doc="weights on x4, one per channel", min_len=1)
    bias: float = param(0.0, doc="constant added to every output sample")
    units: str = param("1", doc="units of the output")
    preset: Literal["none", "SA1", "FA1"] = param(
        "none", doc="Table I weights of Rager et al. (x1 = F in N, x2 = F' in N/s, x3 = F'' in N/s^2)"
    )
    on_bad_data: Literal["raise", "drop", "hold"] = param(
        "raise", doc="non-finite samples: raise, drop the instant, or hold the last good value"
    )

    def check(self) -> None:
        given = [f"w{i}" for i in range(1, 5) if getattr(self, f"w{i}") is not None]
        if self.preset != "none" and given:
            raise self.error(
                given[0],
                f"cannot be set with preset '{self.preset}' (the preset takes w1..w3 from Table I); "
                "set preset: none to give your own weights",
            )
        if self.preset == "none" and self.w1 is None:
            raise self.error("w1", "is required (one weight per channel of x1) unless a preset is chosen")

    def weights(self) -> dict[str, tuple[float, ...] | None]:
        """The effective weights per input (the preset's, or w1..w4)."""
        if self.preset != "none":
            w1, w2, w3 = table_i_weights(self.preset)
            return {"x1": w1, "x2": w2, "x3": w3, "x4": None}
        return {f"x{i}": getattr(self, f"w{i}") for i in range(1, 5)}


class WeightedSum(Block):
    """Weighted sum of up to four sampled inputs: the drive of an afferent population.

    Ports
    -----
    x1 : float64, shape () or (C1,), sampled — required (with a preset: [Fx, Fy, Fz] in N)
    x2, x3, x4 : float64, shape () or (Ck,), optional (preset: x2 = F' in N/s, x3 = F'' in N/s^2)
    y : float64, shape (), units ``units`` — ``bias + Σ_k w_k · x_k`` per sample, stamped like x1

    Config
    ------
    See :class:`WeightedSumConfig`. ``preset: SA1|FA1`` takes w1..w3 from Table I
    (blocks/afferents.py) and then checks the input units (feeding ``mN`` or ``N/s`` where ``N`` is
    expected is an error naming the port); giving w1..w4 together with a preset is a config error.

    Notes
    -----
    Demand: only inputs with at least one non-zero weight are needed (x1 always, it is the clock),
    so with Table I the zero F'' weights make x3 unneeded and the compiler prunes the F'' filter.
    Wiring rules (checked when specs are resolved): a connected input without weights is an error
    (its data would be silently ignored); an unconnected input with a non-zero weight is an error
    (its term would be silently missing); zero weights may be left unconnected.

    Alignment: inputs may arrive with different delays (a centred derivative comes (N−1)/2
    samples after the raw force, with equal timestamps). Each input is buffered and the common
    prefix is emitted; paired samples must carry equal timestamps (to 1e-6 of a period), else
    :class:`MisalignedError`. Latency: that of the slowest input; samples still unpaired at the
    end of the stream are dropped and counted (``unpaired_at_end``).
    ``on_bad_data: drop`` drops the whole instant (every input) so that the streams stay aligned.
    The sum is elementwise in a fixed order (bias, then x1..x4 channel by channel): chunking
    never changes a bit.

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.filters import WeightedSum
    >>> from flowtact.testing import run_offline
    >>> f = np.tile([0.0, 0.1, 0.12], (4, 1))             # N
    >>> out = run_offline(WeightedSum(preset="SA1"), x1=f, x2=np.zeros((4, 3)),
    ...                   units={"x1": "N", "x2": "N/s"})
    >>> round(float(out["y"].data[0]), 6)                 # 8.908·0.1 + 0.382·0.12
    0.93664
    """

    config_cls = WeightedSumConfig
    inputs = {
        "x1": Port(dtype="float64", doc="first input (preset: forces [Fx, Fy, Fz] in N)"),
        "x2": Port(dtype="float64", optional=True, doc="second input (preset: first derivatives in N/s)"),
        "x3": Port(dtype="float64", optional=True, doc="third input (preset: second derivatives in N/s^2)"),
        "x4": Port(dtype="float64", optional=True, doc="fourth input (no preset weights)"),
    }
    outputs = {"y": Port(dtype="float64", shape=(), doc="weighted sum, one value per sample")}
    counter_docs = {
        "nonfinite_drop": "instants where an input had NaN/inf, removed from every input (on_bad_data: "
        "drop): upstream sent bad data",
        "nonfinite_hold": "input samples (per input) with NaN/inf, held at the last finite value "
        "(on_bad_data: hold): upstream sent bad data",
        "unpaired_at_end": "input samples with no partners on the other inputs when the stream ended: not "
        "summed (the inputs delivered different numbers of samples)",
    }

    def needs(self, connected: frozenset[str]) -> frozenset[str]:
        w = self.config.weights()
        return frozenset(
            p for p in connected if p == "x1" or (w[p] is not None and any(v != 0 for v in w[p]))
        )

    def specs(self, inputs: Mapping[str, StreamSpec]) -> dict[str, StreamSpec]:
        cfg, w = self.config, self.config.weights()
        if "x1" not in inputs:
            raise SpecError("x1", "input 'x1' must be connected")
        for p in _INPUTS:
            wp = w[p]
            if p not in inputs:
                if wp is not None and any(v != 0 for v in wp):
                    src = f"preset {cfg.preset}" if cfg.preset != "none" else f"w{p[1]}"
                    raise SpecError(p, f"{src} gives non-zero weights to '{p}' but '{p}' is not connected")
                continue
            spec = inputs[p]
            _check_float_stream(p, spec)
            if wp is None:
                raise SpecError(
                    p, f"input '{p}' is connected but has no weights (set w{p[1]}, or disconnect it)"
                )
            if len(wp) != _n_channels(spec):
                raise SpecError(
                    p,
                    f"w{p[1]} has {len(wp)} weights but input '{p}' has {_n_channels(spec)} channel(s)",
                )
            if cfg.preset != "none" and spec.units != _PRESET_UNITS[p]:
                raise SpecError(
                    p,
                    f"preset {cfg.preset} expects {_PRESET_WHAT[p]} in {_PRESET_UNITS[p]} on '{p}' "
                    f"(Table I weights are per {_PRESET_UNITS[p]}) but got {spec.units}",
                )
            if not math.isclose(spec.rate_hz or 0.0, inputs["x1"].rate_hz or 0.0, rel_tol=1e-9):
                raise SpecError(
                    p, f"input '{p}' is {spec.rate_hz:g} Hz but x1 is {inputs['x1'].rate_hz:g} Hz"
                )
        return {"y": StreamSpec(dtype="float64", shape=(), units=cfg.units, rate_hz=inputs["x1"].rate_hz)}

    def reset(self) -> None:
        w = self.config.weights()
        used = self.needs(frozenset(self.input_specs))
        self._ports = [p for p in _INPUTS if p in used]
        self._w = {p: np.asarray(w[p], np.float64) for p in self._ports}
        self._nc = {p: _n_channels(self.input_specs[p]) for p in self._ports}
        rate = self.input_specs["x1"].rate_hz or 1.0
        self._align = Aligner(self.node, self.input_specs, self._ports, tol_s=1e-6 / rate)
        self._last: dict[str, np.ndarray | None] = {p: None for p in self._ports}

    def step(self, **chunks: Chunk) -> dict[str, Chunk]:
        t, data = self._align.push(chunks)
        n = len(t)
        if n:
            t, data = screen_aligned(self, self.config.on_bad_data, t, data, self._last)
            n = len(t)
        y = np.full(n, self.config.bias)
        for p in self._ports:
            x = data[p].reshape(n, self._nc[p])
            for c, wc in enumerate(self._w[p]):
                if wc != 0.0:
                    y += wc * x[:, c]
        return {"y": Chunk(t, y)}

    def flush(self) -> dict[str, Chunk]:
        left = sum(self._align.pending().values())
        self.count("unpaired_at_end", left)
        return {}

    @classmethod
    def example(cls) -> Example:
        rng = np.random.default_rng(2)
        n = 500
        f = np.abs(np.cumsum(rng.normal(0.0, 0.01, (n, 3)), axis=0))
        df = np.gradient(f, 1e-3, axis=0)
        return Example(
            params={"preset": "FA1"},
            inputs={"x1": f, "x2": df, "x3": np.gradient(df, 1e-3, axis=0)},
            units={"x1": "N", "x2": "N/s", "x3": "N/s^2"},
        )


# -- delay ------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class DelayConfig(Config):
    """What the fed-back stream carries: in a loop the compiler needs it before the loop is resolved."""

    dtype: str = param("float64", doc="dtype of the fed-back stream")
    shape: tuple[int, ...] = param((), doc="sample shape of the fed-back stream", ge=1)
    units: str = param("1", doc="units of the fed-back stream")
    rate_hz: float | None = param(None, doc="rate of the fed-back stream (None: an event stream)", gt=0)


class Delay(Block):
    """One-tick delay: passes its input through unchanged so a graph can close a feedback loop.

    Ports
    -----
    x : any dtype and shape (declared ``delay=True``: it receives data one executor tick late)
    y : the same samples with the same timestamps, dtype, shape, units and rate as ``x``

    Config
    ------
    dtype, shape, units, rate_hz: what the fed-back stream carries. Inside a loop the compiler
    resolves this block before the stream that feeds it, so it takes the output spec from these
    parameters, then checks that the stream that arrives matches them. Outside a loop they are
    not needed (the input's spec is passed on).

    Notes
    -----
    The compiler accepts a cycle only if it passes through a delay port; this block is the
    standard way to put one in a loop (e.g. a controller's command fed back to a planner). The
    delay is the executor's: the block itself adds no latency, holds no state and never alters
    data (no bad-data policy: it computes nothing; the consumer's policy applies).

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.filters import Delay
    >>> from flowtact.testing import run_offline
    >>> run_offline(Delay(), x=np.arange(3.0))["y"].data.tolist()
    [0.0, 1.0, 2.0]
    """

    config_cls = DelayConfig
    inputs = {"x": Port(dtype=None, delay=True, doc="samples to pass on (one tick late)")}
    outputs = {"y": Port(dtype=None, doc="the same samples, unchanged")}

    def specs(self, inputs: Mapping[str, StreamSpec]) -> dict[str, StreamSpec]:
        if "x" in inputs:
            return {"y": inputs["x"]}
        c = self.config  # inside a loop: the fed-back stream is not resolved yet
        return {
            "y": StreamSpec(
                dtype=c.dtype,
                shape=tuple(c.shape),
                units=c.units,
                rate_hz=c.rate_hz,
                events=c.rate_hz is None,
            )
        }

    def reset(self) -> None:
        self._empty = Chunk.empty(self.input_specs["x"])

    def step(self, x: Chunk | None = None, **_: Chunk) -> dict[str, Chunk]:
        return {"y": self._empty if x is None else x}

    @classmethod
    def example(cls) -> Example:
        rng = np.random.default_rng(3)
        return Example(inputs={"x": rng.normal(size=(200, 2))}, units={"x": "N"})


# -- lowpass ------------------------------------------------------------------------------------------


@njit(cache=True)
def lowpass_apply(
    t: np.ndarray,
    x: np.ndarray,
    state: np.ndarray,
    prev_t: float,
    started: bool,
    w: float,
    alpha_nominal: float,
    use_t: bool,
    init_first: bool,
) -> tuple[np.ndarray, float, bool, int]:
    """First-order low-pass ``s += a·(x − s)`` sample by sample; updates ``state`` (C,) in place.

    ``a = 1 − exp(−w·dt)`` (computed as ``−expm1(−w·dt)``) with ``dt`` the time since the previous
    sample when ``use_t``, else the constant ``alpha_nominal``. A sample whose ``dt <= 0`` leaves the
    state unchanged (counted in the last result). The first sample of the stream sets the state
    (``init_first``) or is filtered from zero with ``alpha_nominal``. Returns (y (n, C), prev_t,
    started, n_nonincreasing). Strictly sequential: chunk boundaries never change a bit.
    """
    n, nc = x.shape
    y = np.empty((n, nc))
    bad = 0
    for i in range(n):
        if not started:
            started = True
            prev_t = t[i]
            if init_first:
                for c in range(nc):
                    state[c] = x[i, c]
            else:
                for c in range(nc):
                    state[c] = state[c] + alpha_nominal * (x[i, c] - state[c])
        else:
            a = alpha_nominal
            if use_t:
                dt = t[i] - prev_t
                if dt > 0.0:
                    a = -math.expm1(-w * dt)
                    prev_t = t[i]
                else:
                    a = 0.0
                    bad += 1
            else:
                prev_t = t[i]
            for c in range(nc):
                state[c] = state[c] + a * (x[i, c] - state[c])
        for c in range(nc):
            y[i, c] = state[c]
    return y, prev_t, started, bad


def lowpass_apply_python(
    t: np.ndarray,
    x: np.ndarray,
    state: np.ndarray,
    prev_t: float,
    started: bool,
    w: float,
    alpha_nominal: float,
    use_t: bool,
    init_first: bool,
) -> tuple[np.ndarray, float, bool, int]:
    """Plain-Python twin of :func:`lowpass_apply` (the same operations in the same order)."""
    n, nc = x.shape
    y = np.empty((n, nc))
    bad = 0
    for i in range(n):
        if not started:
            started = True
            prev_t = float(t[i])
            for c in range(nc):
                xi = float(x[i, c])
                state[c] = xi if init_first else float(state[c]) + alpha_nominal * (xi - float(state[c]))
        else:
            a = alpha_nominal
            if use_t:
                dt = float(t[i]) - prev_t
                if dt > 0.0:
                    a = -math.expm1(-w * dt)
                    prev_t = float(t[i])
                else:
                    a, bad = 0.0, bad + 1
            else:
                prev_t = float(t[i])
            for c in range(nc):
                state[c] = float(state[c]) + a * (float(x[i, c]) - float(state[c]))
        y[i] = state
    return y, prev_t, started, bad


@dataclass(frozen=True)
class LowpassConfig(Config):
    """Parameters of :class:`Lowpass`."""

    cutoff_hz: float = param(10.0, doc="-3 dB cut-off frequency of the first-order low-pass, Hz", gt=0)
    time_base: Literal["timestamps", "nominal"] = param(
        "timestamps",
        doc="timestamps: each step uses the time since the previous sample; nominal: a fixed 1/rate step",
    )
    initial: Literal["first", "zero"] = param(
        "first", doc="state before the stream: its first sample (no start transient) or zero"
    )
    on_bad_data: Literal["raise", "drop", "hold"] = param(
        "raise", doc="non-finite samples: raise, drop them, or hold the last good value"
    )


class Lowpass(Block):
    """First-order (one-pole) low-pass per channel, stepped on the samples' own timestamps.

    Ports
    -----
    x : float64, any shape, any units, sampled — e.g. the three FSR forces in N
    y : float64, same shape, units, rate and labels as ``x``

    Config
    ------
    See :class:`LowpassConfig`.

    Notes
    -----
    y[n] = y[n−1] + a·(x[n] − y[n−1]), a = 1 − exp(−2π·f_c·Δt): the exact discretisation of
    τ·y' = x − y (τ = 1/(2π·f_c)) for an input held between samples. With ``time_base:
    timestamps`` (default) Δt is the time since the previous sample, so a stream stamped
    irregularly (the exoskeleton's samples, stamped by a clock estimator; dropped packets) is
    filtered as what happened in time: a gap lets the output move further, jitter does not
    change the cut-off. ``nominal`` uses Δt = 1/rate for every sample (a fixed IIR). A sample
    stamped at or before its predecessor does not move the state (counted ``nonincreasing_t``).
    One pole, not a 2nd-order Butterworth: no overshoot on a force step (a servo controller
    downstream must not see a filter ringing), −20 dB/decade, and exact on irregular steps; its
    step response lag is τ (16 ms at 10 Hz). The thesis low-passes the FSR without giving a
    cut-off; 10 Hz keeps its 0.25–0.6 s force step responses intact. The state starts at the
    first sample (``initial: first``) or at zero. Latency 0 (the lag is in the values);
    state: one value per channel and the last timestamp. Strictly sequential (numba kernel
    :func:`lowpass_apply`, Python twin :func:`lowpass_apply_python`): chunk boundaries never
    change a bit. The cut-off must lie below half the nominal rate. ``end`` is passed on.

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.filters import Lowpass
    >>> from flowtact.testing import run_offline
    >>> x = np.r_[0.0, np.ones(3)]                        # a unit step at 100 Hz
    >>> y = run_offline(Lowpass(cutoff_hz=10.0), x=x, rate_hz=100.0)["y"].data
    >>> np.round(y, 4).tolist()                           # 1 − e^(−2π·10·0.01·k)
    [0.0, 0.4665, 0.7154, 0.8482]
    """

    config_cls = LowpassConfig
    inputs = {"x": Port(dtype="float64", doc="signal, any shape")}
    outputs = {"y": Port(dtype="float64", doc="low-passed signal, same shape and units")}
    counter_docs = {
        "nonincreasing_t": "samples stamped at or before the previous one: they did not move the filter "
        "(the output repeats); timestamps went wrong upstream",
        **nonfinite_counter_docs("samples on 'x'"),
    }

    def specs(self, inputs: Mapping[str, StreamSpec]) -> dict[str, StreamSpec]:
        if "x" not in inputs:
            raise SpecError("x", "input 'x' must be connected")
        x = inputs["x"]
        if x.events or x.rate_hz is None:
            raise SpecError("x", f"input 'x' must be a sampled stream with a rate, got {x.describe()}")
        if x.dtype != "float64":
            raise SpecError("x", f"input 'x' must be float64, got {x.dtype}")
        if self.config.cutoff_hz >= 0.5 * x.rate_hz:
            raise SpecError(
                "x",
                f"cutoff_hz {self.config.cutoff_hz:g} must be below half the stream's rate "
                f"({x.rate_hz:g} Hz)",
            )
        return {"y": x}

    def reset(self) -> None:
        cfg = self.config
        spec = self.input_specs["x"]
        self._shape = spec.shape
        self._nc = _n_channels(spec)
        self._w = 2.0 * math.pi * cfg.cutoff_hz
        self._alpha = -math.expm1(-self._w / float(spec.rate_hz or 1.0))
        self._state = np.zeros(self._nc)
        self._prev_t = 0.0
        self._started = False
        self._last: np.ndarray | None = None

    def step(self, x: Chunk | None = None, **_: Chunk) -> dict[str, Chunk]:
        if x is None:
            return {"y": Chunk(np.empty(0), np.empty((0, *self._shape)))}
        cfg = self.config
        if len(x) and not np.isfinite(np.add.reduce(x.data, axis=None)):
            x, self._last = screen_nonfinite(self, x, cfg.on_bad_data, "x", self._last)
        elif len(x) and cfg.on_bad_data == "hold":
            self._last = x.data[-1].copy()
        n = len(x)
        if n == 0:
            return {"y": Chunk(np.empty(0), np.empty((0, *self._shape)), x.end)}
        y, self._prev_t, self._started, bad = lowpass_apply(
            np.ascontiguousarray(x.t, np.float64),
            np.ascontiguousarray(x.data.reshape(n, self._nc), np.float64),
            self._state,
            self._prev_t,
            self._started,
            self._w,
            self._alpha,
            cfg.time_base == "timestamps",
            cfg.initial == "first",
        )
        self.count("nonincreasing_t", bad)
        return {"y": Chunk(x.t, y.reshape(n, *self._shape), x.end)}

    @classmethod
    def example(cls) -> Example:
        rng = np.random.default_rng(11)
        n = 200
        t = np.arange(n) / 100.0
        f = np.outer((t > 0.5) * 1.5, [1.0, 0.8, 1.2]) + rng.normal(0, 0.1, (n, 3))
        return Example(params={"cutoff_hz": 5.0}, inputs={"x": f}, rate_hz=100.0, units={"x": "N"})
