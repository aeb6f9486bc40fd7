"""Numerical stress cases for ``savgol`` and ``weighted_sum`` (issue 12, item 4).

Scale (1e6, 1e-12) against scipy's Savitzky–Golay (a test dependency, imported only when a case
runs), NaN/inf under each ``on_bad_data`` policy, jittered and gapped timestamps into the
differentiator, extreme inputs into the weighted sum. Used by tests/blocks/signal/, by
scripts/stress_outcomes.py and by the benchmark suite.
"""

from __future__ import annotations

import math
from functools import partial

import numpy as np

import flowtact.api as ft
from flowtact.testing import run_offline
from flowtact.verify.stress import EPS, Outcome, StressCase

from .savgol import SavGol, savgol_coeffs
from .weighted_sum import WeightedSum

__all__ = ["CASES"]

RATE = 1000.0
#: (window, order, deriv) settings every savgol case runs: the paper's 5/4 F' and F'', a smoother 21/2 F'.
SETTINGS = ((5, 4, 1), (5, 4, 2), (21, 2, 1))


def _walk(n: int, seed: int = 5) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.cumsum(rng.normal(0.0, 1.0, n)) + rng.normal(0.0, 0.1, n)


def _scipy_reference(x: np.ndarray, window: int, order: int, deriv: int, mode: str) -> np.ndarray:
    from scipy.signal import lfilter, savgol_filter
    from scipy.signal import savgol_coeffs as sp_coeffs

    if mode == "causal":
        c = sp_coeffs(window, order, deriv=deriv, delta=1 / RATE, pos=window - 1, use="conv")
        return lfilter(c, [1.0], x)
    return savgol_filter(x, window, order, deriv=deriv, delta=1 / RATE, mode="constant", cval=0.0)


def savgol_scale(scale: float) -> Outcome:
    """A random walk scaled to ``scale`` through each setting, causal and centred, against scipy."""
    x = _walk(20_000) * scale
    worst = 0.0
    ok = True
    for window, order, deriv in SETTINGS:
        for mode in ("causal", "centred"):
            y = run_offline(SavGol(window=window, order=order, deriv=deriv, mode=mode), x=x, chunk=1000)["y"]
            ref = _scipy_reference(x, window, order, deriv, mode)
            pos = window - 1 if mode == "causal" else None
            c = savgol_coeffs(window, order, deriv, pos=pos, rate_hz=RATE)
            # rounding of a sum of N products, and of scipy's own weights: conditioning, not output size
            unit = window * EPS * float(np.abs(c).sum()) * float(np.abs(x).max())
            err = np.abs(y.data - ref)
            ok &= bool(np.isfinite(y.data).all() and (err <= 4 * unit + 1e-12 * np.abs(ref)).all())
            worst = max(worst, float(err.max()) / unit)
    return Outcome(
        f"scale_{scale:g}", "savgol", f"random walk × {scale:g} (20 000 samples), 5/4 F' F'', 21/2 F', causal + centred",
        "linear FIR: scales exactly; no underflow at 1e-12 (weights ~1e6/s², products ≫ 1e-308)",
        "|y − scipy| ≤ 4·N·ε·Σ|c|·max|x| + 1e-12·|y| (NUMERICS §1.4)", ok,
        f"max error = {worst:.2f} × N·ε·Σ|c|·max|x|", {"worst_units": worst},
    )  # fmt: skip


def savgol_bad(policy: str) -> Outcome:
    """NaN, +inf, −inf samples into the differentiator under ``policy``."""
    x = _walk(300) * 1e-3
    x[[50, 51, 200]] = [math.nan, math.inf, -math.inf]
    blk = SavGol(on_bad_data=policy)
    try:
        y = run_offline(blk, x=x, chunk=7)["y"]
    except ft.BadDataError as e:
        ok = policy == "raise" and "non-finite" in str(e) and "\n" not in str(e)
        return Outcome(
            f"nonfinite_{policy}", "savgol", "NaN, +inf, −inf samples", f"stops: “{e}”",
            "raise: clean one-line error", ok,
        )  # fmt: skip
    finite = bool(np.isfinite(y.data).all())
    n_ok = len(y) == (297 if policy == "drop" else 300)
    ok = finite and n_ok and blk.counters.get(f"nonfinite_{policy}") == 3
    if policy == "drop":
        ok &= blk.counters.get("sample_gaps") == 2  # 50–51 and 200: the filter bridges two gaps
    return Outcome(
        f"nonfinite_{policy}", "savgol", "NaN, +inf, −inf samples",
        {"drop": "removes them (counted), and counts the 2 gaps the filter then bridges (sample_gaps)",
         "hold": "repeats the last finite sample (counted)"}.get(policy, "?"),
        "counted; output finite; no sample lost beyond the dropped ones", ok, f"counters {blk.counters}",
    )  # fmt: skip


def _derivative_error(t: np.ndarray, window: int = 5, order: int = 4) -> tuple[np.ndarray, dict[str, int]]:
    """|F' error| of a 5 Hz sine sampled at times ``t`` (true derivative at the stamped times)."""
    w = 2 * np.pi * 5
    blk = SavGol(window=window, order=order, deriv=1, mode="centred")
    y = run_offline(blk, x=np.sin(w * t), t=t, chunk=250)["y"]
    err = np.abs(y.data - w * np.cos(w * y.t))[window:-window]
    return err, dict(blk.counters)


def savgol_jitter() -> Outcome:
    """Timestamps jittered by ±20 % of the period (uniform): the fit assumes uniform sampling."""
    n = 5000
    rng = np.random.default_rng(11)
    grid = np.arange(n) / RATE
    jittered = grid + rng.uniform(-0.2, 0.2, n) / RATE
    err, counters = _derivative_error(jittered)
    base, base_counters = _derivative_error(grid)
    rms = float(np.sqrt(np.mean(err**2))) / (2 * np.pi * 5 / math.sqrt(2))
    n_irregular = int((np.abs(np.diff(jittered) * RATE - 1) > 0.01).sum())
    ok = counters.get("irregular_dt") == n_irregular and not base_counters
    return Outcome(
        "jitter", "savgol", "5 Hz sine, timestamps jittered ±20 % of dt, 5/4 centred F'",
        "assumes uniform sampling (no resampling) and flags every interval off by > 1 % (irregular_dt)",
        "every irregular interval counted; a uniform stream counts nothing", ok,
        f"F' RMS error {rms:.1%} of the true RMS (uniform: {float(np.sqrt(np.mean(base**2))):.1e} N/s); "
        f"irregular_dt = {counters.get('irregular_dt', 0)} of {n - 1} intervals",
        {"rel_rms": rms, "irregular_dt": counters.get("irregular_dt", 0), "expected": n_irregular},
    )  # fmt: skip


def savgol_gaps() -> Outcome:
    """Five missing samples every 500 (timestamps skip): the filter bridges the gap as if adjacent."""
    n = 5000
    keep = np.ones(n, bool)
    for k in range(100, n, 500):
        keep[k : k + 5] = False
    t = np.arange(n)[keep] / RATE
    err, counters = _derivative_error(t)
    amp = 2 * np.pi * 5
    ok = counters.get("sample_gaps") == 10 and "irregular_dt" not in counters
    return Outcome(
        "gaps", "savgol", "5 Hz sine (F' amplitude 31 N/s), 5 samples missing every 500, 5/4 centred F'",
        "treats the samples across a gap as adjacent (wrong F' there) and counts each gap (sample_gaps)",
        "all 10 gaps counted", ok,
        f"max F' error near gaps {float(err.max()):.0f} N/s = {float(err.max()) / amp:.1f}× amplitude; "
        f"sample_gaps = {counters.get('sample_gaps', 0)}",
        {"max_err": float(err.max()), "sample_gaps": counters.get("sample_gaps", 0)},
    )  # fmt: skip


# -- weighted_sum ----------------------------------------------------------------------------------------

_W1, _W2 = (0.405, 8.908, 0.382), (-1e-3, 1e-3, 5.4e-4)


def wsum_scale(scale: float) -> Outcome:
    """Forces and derivatives scaled to ``scale`` through Table-I-like weights, against an exact sum."""
    rng = np.random.default_rng(3)
    x1, x2 = rng.normal(0, 1, (500, 3)) * scale, rng.normal(0, 100, (500, 3)) * scale
    y = run_offline(WeightedSum(w1=list(_W1), w2=list(_W2)), x1=x1, x2=x2, units={"x1": "N", "x2": "N/s"})[
        "y"
    ]
    exact = np.array([math.fsum([*(w * v for w, v in zip(_W1, a, strict=True)),
                                 *(w * v for w, v in zip(_W2, b, strict=True))]) for a, b in zip(x1, x2, strict=True)])  # fmt: skip
    cond = np.abs(x1) @ np.abs(_W1) + np.abs(x2) @ np.abs(_W2)  # Σ|w·x|: the sum's conditioning
    err = np.abs(y.data - exact)
    ok = bool((err <= 8 * EPS * cond).all())  # 6 products + 6 additions, each ≤ ε relative
    worst = float((err / (EPS * cond)).max())
    return Outcome(
        f"scale_{scale:g}", "weighted_sum", f"x1 ~ N(0, {scale:g}), x2 ~ N(0, 100·{scale:g}), Table I-like weights",
        "plain float64 sum; scale-free", "|y − exact| ≤ 8ε·Σ|w·x|", ok,
        f"max error = {worst:.2f} ε·Σ|w·x|", {"worst_units": worst},
    )  # fmt: skip


def wsum_bad(policy: str) -> Outcome:
    """NaN on x1 and +inf on x2 at different instants, under ``policy``."""
    x1, x2 = np.ones((100, 3)), np.zeros((100, 3))
    x1[30, 1] = math.nan
    x2[60, 2] = math.inf
    blk = WeightedSum(w1=list(_W1), w2=list(_W2), on_bad_data=policy)
    try:
        y = run_offline(blk, x1=x1, x2=x2, units={"x1": "N", "x2": "N/s"}, chunk=9)["y"]
    except ft.BadDataError as e:
        return Outcome(
            f"nonfinite_{policy}", "weighted_sum", "NaN on x1, +inf on x2", f"stops: “{e}”",
            "raise: clean one-line error", policy == "raise" and "\n" not in str(e),
        )  # fmt: skip
    want = {"drop": {"nonfinite_drop": 2}, "hold": {"nonfinite_hold": 2}}[policy]
    ok = (
        bool(np.isfinite(y.data).all())
        and blk.counters == want
        and len(y) == (98 if policy == "drop" else 100)
    )
    return Outcome(
        f"nonfinite_{policy}", "weighted_sum", "NaN on x1, +inf on x2",
        f"{policy}s the instant (counted); sum finite", "counted once per instant; output finite", ok,
        f"counters {blk.counters}",
    )  # fmt: skip


def wsum_overflow() -> Outcome:
    """Finite but huge inputs (1e308) whose weighted sum overflows: the output is inf — flagged?"""
    x1 = np.full((10, 3), 1e308)
    blk = WeightedSum(w1=list(_W1))
    y = run_offline(blk, x1=x1, units={"x1": "N"})["y"]
    n_bad = int((~np.isfinite(y.data)).sum())
    ok = n_bad == 0 or blk.counters.get("overflow") == n_bad
    return Outcome(
        "overflow", "weighted_sum", "finite inputs of 1e308 (the sum overflows float64)",
        "emits ±inf (the honest value) and counts each such sample (overflow); the consumer's "
        "on_bad_data then applies (nlif raises by default)",
        "every non-finite output counted", ok, f"{n_bad} inf outputs; counters {blk.counters}",
        {"inf_outputs": n_bad, "counted": blk.counters.get("overflow", 0)},
    )  # fmt: skip


CASES: tuple[StressCase, ...] = (
    StressCase("scale_1e6", "savgol", partial(savgol_scale, 1e6)),
    StressCase("scale_1e-12", "savgol", partial(savgol_scale, 1e-12)),
    *(StressCase(f"nonfinite_{p}", "savgol", partial(savgol_bad, p)) for p in ("raise", "drop", "hold")),
    StressCase("jitter", "savgol", savgol_jitter),
    StressCase("gaps", "savgol", savgol_gaps),
    StressCase("scale_1e6", "weighted_sum", partial(wsum_scale, 1e6)),
    StressCase("scale_1e-12", "weighted_sum", partial(wsum_scale, 1e-12)),
    *(StressCase(f"nonfinite_{p}", "weighted_sum", partial(wsum_bad, p)) for p in ("raise", "drop", "hold")),
    StressCase("overflow", "weighted_sum", wsum_overflow),
)
