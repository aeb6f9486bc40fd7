"""A streaming Savitzky–Golay smoother/differentiator, in physical units per second.

Also :func:`deriv_units` (``"N"`` → ``"N/s"`` → ``"N/s^2"``), which other blocks use to name the
units of a derivative.
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

import flowtact.api as ft
from flowtact.finite import all_finite_kernel

__all__ = [
    "SavGol",
    "SavGolConfig",
    "deriv_units",
    "savgol_apply",
    "savgol_apply_numpy",
    "savgol_coeffs",
]

#: The defaults: Savitzky–Golay, polynomial order 4, frame of 5 samples (the filter of Rager et al.).
DEFAULT_WINDOW, DEFAULT_ORDER = 5, 4
#: A sample interval further than this fraction of the nominal period from it counts as irregular
#: (``irregular_dt``); one longer than 1.5 periods is a gap (``sample_gaps``): the fit assumes uniform sampling.
DT_TOL = 0.01


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


# -- Savitzky–Golay coefficients ------------------------------------------------------------------


MAX_WINDOW = 10_001
"""Longest window: the exact rational least-squares fit grows with it (about 1 s at this length)."""


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
def _timing_faults(t: np.ndarray, prev: float, period: float, tol: float) -> tuple[int, int]:
    """(gaps, irregular): intervals from ``prev`` (NaN: none) through ``t`` longer than 1.5 periods,
    and the others off the period by more than ``tol`` of it. One pass, no temporaries."""
    gaps = 0
    irregular = 0
    for i in range(len(t)):
        if i == 0 and prev != prev:
            prev = t[0]
            continue
        d = t[i] - prev
        prev = t[i]
        if d > 1.5 * period:
            gaps += 1
        elif abs(d / period - 1.0) > tol:
            irregular += 1
    return gaps, irregular


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


@njit(cache=True)
def _finite_step(
    coef: np.ndarray, tail: np.ndarray, x: np.ndarray, t: np.ndarray, prev: float, period: float, prime: bool
) -> tuple[bool, np.ndarray, int, int]:
    """A step on finite samples in one call (a real-time step pays per call, docs/writing-a-block.md).

    When every value of ``x`` (n, C) is finite: count the timing faults of ``t`` after ``prev``
    (:func:`_timing_faults`), fill the history with the first sample if ``prime`` (``padding:
    hold``), filter (:func:`savgol_apply`) and return (True, y, gaps, irregular). Otherwise return
    (False, an empty array, 0, 0) having changed nothing: the block screens the chunk first.
    """
    if not all_finite_kernel(x):
        return False, np.empty((0, x.shape[1])), 0, 0
    gaps, irregular = _timing_faults(t, prev, period, DT_TOL)
    if prime:
        for i in range(tail.shape[0]):
            tail[i, :] = x[0]
    return True, savgol_apply(coef, tail, x), gaps, irregular


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
class SavGolConfig(ft.BadDataConfig):
    """Parameters of :class:`SavGol`."""

    window: int = ft.param(
        DEFAULT_WINDOW,
        doc=f"frame length in samples (odd, > order; at most {MAX_WINDOW}: the exact fit takes ~1 s there)",
        ge=3,
        le=MAX_WINDOW,
        odd=True,
    )
    order: int = ft.param(DEFAULT_ORDER, doc="degree of the fitted polynomial", ge=0, le=10)
    deriv: int = ft.param(1, doc="derivative to estimate: 0 smooths, 1 = d/dt (units/s), 2 = d²/dt²", ge=0)
    mode: Literal["causal", "centred"] = ft.param(
        "centred",
        doc="centred: estimate at the window centre, stamped (window-1)/2 samples late; causal: at the newest sample",
    )
    rate_hz: float | None = ft.param(
        None, doc="sample rate the filter is designed for (null: the stream's rate)", gt=0
    )
    padding: Literal["zeros", "hold"] = ft.param(
        "zeros",
        doc="signal assumed outside the stream: zeros (the paper's zero padding) or hold (its first/last sample: no edge transients)",
    )

    def check(self) -> None:
        if self.order >= self.window:
            raise self.error("order", f"must be < window ({self.window}); got {self.order}")
        if self.deriv > self.order:
            raise self.error("deriv", f"must be <= order ({self.order}); got {self.deriv}")


class SavGol(ft.Block):
    """Streaming Savitzky–Golay smoother/differentiator, per channel, in physical units per second.

    Config
    ------
    See :class:`SavGolConfig`; defaults are window 5, order 4, centred, zero padded, first
    derivative (Rager et al.'s filter; ``preset: touch.rager`` says so in a graph). ``centred``
    is the offline fit; ``causal`` its zero-latency real-time variant, at ×5.9 the F' noise.

    Notes
    -----
    Coefficients: least squares on the Vandermonde of the window, solved exactly (rationals),
    scaled by ``rate_hz^deriv`` (delta = 1/rate_hz), so derivatives are per **second** — the
    convention Rager et al.'s Table I weights are read in (blocks/touch/presets.py). History before the first
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
    ``flowtact bench savgol`` reports the error-vs-latency table).

    Timing: the weights assume samples exactly one nominal period apart; the block does not
    resample. It checks the timestamps and counts what breaks that assumption: ``sample_gaps`` (an
    interval longer than 1.5 periods: samples missing, including those ``on_bad_data: drop``
    removed — the filter then treats their neighbours as adjacent) and ``irregular_dt`` (an
    interval off the period by more than :data:`DT_TOL`, 1 %: jitter). Estimates whose window spans
    such an interval are wrong (a 20 % jitter gives ~10 % RMS error on F'; a 5-sample gap, errors
    of several times the signal's derivative, docs/numerical-stress.md): resample upstream, or
    treat a non-zero count as a fault.

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.signal.savgol import SavGol
    >>> from flowtact.testing import run_offline
    >>> x = np.arange(10.0) / 1000.0                      # a 1 N/s ramp sampled at 1 kHz
    >>> out = run_offline(SavGol(deriv=1, mode="centred"), x=x, units={"x": "N"})
    >>> np.round(out["y"].data[2:-2], 9).tolist(), float(out["y"].t[0])
    ([1.0, 1.0, 1.0, 1.0, 1.0, 1.0], 0.0)
    """

    name = "savgol"
    config_cls = SavGolConfig
    inputs = {
        "x": ft.Port(
            dtype="float64",
            ndim=(0, 1),
            require_rate=True,
            doc="signal, shape () or (channels,)",
        )
    }
    outputs = {
        "y": ft.Port(
            dtype="float64",
            doc=(
                "the estimate of the deriv-th derivative: the shape, rate and labels of x; units u (deriv"
                " 0), u/s (1), u/s^2 (2) ... for x in u"
            ),
        )
    }
    counter_docs = {
        **ft.nonfinite_counter_docs("samples on 'x'"),
        "sample_gaps": "intervals between samples longer than 1.5 periods (missing or dropped samples): the "
        "estimates whose window spans one are wrong (the filter assumes uniform sampling)",
        "irregular_dt": "intervals off the nominal period by more than 1 % (timestamp jitter): the "
        "estimates whose window spans one are inexact (the filter assumes uniform sampling)",
    }

    def specs(self, inputs: Mapping[str, ft.StreamSpec]) -> dict[str, ft.StreamSpec]:
        x = inputs["x"]
        want = self.config.rate_hz
        if want is not None and not math.isclose(want, x.rate_hz, rel_tol=1e-9):
            raise ft.SpecError("x", f"expects {want:g} Hz (rate_hz) but the input stream is {x.rate_hz:g} Hz")
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
        self._nc = spec.size
        self._tail = np.zeros((cfg.window - 1, self._nc))
        self._h = self.latency_samples
        self._t_hist = np.empty(0)  # stamps of the last <= h samples (centred)
        self._last: np.ndarray | None = None
        self._started = False  # has a sample arrived (padding: hold primes the history with it)
        self._period = 1.0 / float(spec.rate_hz)  # type: ignore[arg-type]
        self._t_prev = math.nan  # time of the last sample filtered (timing checks; NaN: none yet)
        self._hold = cfg.on_bad_data == "hold"  # keep the last good sample to repeat

    def step(self, x: ft.Chunk) -> dict[str, ft.Chunk]:
        if not len(x.t):
            return {"y": ft.Chunk.empty(shape=self._shape)}
        ok, y, gaps, irregular = self._filter(x)  # the common case, finite samples: one compiled call
        if not ok:  # non-finite samples: the bad-data policy first, then the same call on what is left
            x, self._last = ft.screen_nonfinite(self, x, self.config.on_bad_data, "x", self._last)
            if not len(x.t):
                return {"y": ft.Chunk.empty(shape=self._shape)}
            _, y, gaps, irregular = self._filter(x)
        elif self._hold:
            self._last = x.data[-1].copy()
        self._started = True
        self._t_prev = x.t[-1]
        self.count("sample_gaps", gaps)
        self.count("irregular_dt", irregular)
        n = len(x.t)
        if self._h == 0:
            return {"y": ft.Chunk(x.t, y.reshape(n, *self._shape))}
        t_all = np.concatenate([self._t_hist, x.t])
        emit = len(t_all) - self._h
        self._t_hist = t_all[max(emit, 0) :].copy()
        if emit <= 0:
            return {"y": ft.Chunk.empty(shape=self._shape)}
        return {"y": ft.Chunk(t_all[:emit], y[n - emit :].reshape(emit, *self._shape))}

    def _filter(self, x: ft.Chunk) -> tuple[bool, np.ndarray, int, int]:
        """:func:`_finite_step` on ``x``: (all finite, estimates, gaps, irregular intervals)."""
        prime = not self._started and self.config.padding == "hold"
        d = x.data.reshape(len(x.t), self._nc)
        return _finite_step(self._coef, self._tail, d, x.t, self._t_prev, self._period, prime)

    def flush(self) -> dict[str, ft.Chunk]:
        k = len(self._t_hist) if self._h else 0
        if k == 0:
            return {}
        pad = np.zeros((self._h, self._nc))
        if self.config.padding == "hold" and self._started:
            pad[:] = self._tail[-1]
        y = savgol_apply(self._coef, self._tail, pad)
        t = self._t_hist
        self._t_hist = np.empty(0)
        return {"y": ft.Chunk(t, y[self._h - k :].reshape(k, *self._shape))}

    @classmethod
    def example(cls) -> ft.Example:
        rng = np.random.default_rng(1)
        n = 600
        force = np.cumsum(rng.normal(0.0, 0.01, (n, 3)), axis=0) + rng.normal(0.0, 0.002, (n, 3))
        return ft.Example(
            params={"window": 5, "order": 4, "deriv": 1, "mode": "centred"},
            inputs={"x": force},
            units={"x": "N"},
        )
