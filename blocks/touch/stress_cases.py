"""Numerical stress cases for ``gauge_force`` (issue 12, item 4): 1e6 / 1e-12 / NaN / overflowing gauge readings."""

from __future__ import annotations

import math
from fractions import Fraction
from functools import partial

import numpy as np

import flowtact.api as ft
from flowtact.testing import run_offline
from flowtact.verify.stress import EPS, Outcome, StressCase

from .calibration import GaugeForce

__all__ = ["CASES"]


def gauge_scale(scale: float) -> Outcome:
    """ΔR/R readings ~ N(0, scale) through the reduced calibration, against the exact product."""
    r = np.random.default_rng(6).normal(0.0, 1.0, (400, 4)) * scale
    blk = GaugeForce()
    f = run_offline(blk, r=r)["f"].data
    a = blk.config.calibration_matrix()
    exact = np.array(
        [[float(sum(Fraction(a[i, j]) * Fraction(row[j]) for j in range(4))) for i in range(3)] for row in r]
    )
    cond = np.abs(r) @ np.abs(a).T  # Σ|a·r| per output: the product's conditioning
    err = np.abs(f - exact)
    worst = float((err / (EPS * cond)).max())
    ok = bool(np.isfinite(f).all() and (err <= 8 * EPS * cond).all())
    return Outcome(
        f"scale_{scale:g}", "gauge_force", f"ΔR/R ~ N(0, {scale:g}), reduced calibration",
        "plain float64 matrix product, element by element: scale-free", "|F − exact| ≤ 8ε·Σ|a·r|", ok,
        f"max error = {worst:.2f} ε·Σ|a·r|", {"worst_units": worst},
    )  # fmt: skip


def gauge_bad(policy: str) -> Outcome:
    """NaN on gauge 2 and −inf on the reference gauge, with a 20-sample tare, under ``policy``."""
    r = np.full((100, 4), 0.01)
    ref = np.zeros(100)
    r[5, 1] = math.nan  # inside the tare window
    ref[60] = -math.inf
    blk = GaugeForce(on_bad_data=policy, tare_samples=20)
    try:
        f = run_offline(blk, r=r, ref=ref, chunk=9)["f"].data
    except ft.BadDataError as e:
        return Outcome(
            f"nonfinite_{policy}", "gauge_force", "NaN on r (in the tare window), −inf on ref",
            f"stops: “{e}”", "raise: clean one-line error", policy == "raise" and "\n" not in str(e),
        )  # fmt: skip
    key = f"nonfinite_{policy}"
    ok = (
        bool(np.isfinite(f).all())
        and blk.counters.get(key) == 2
        and len(f) == (98 if policy == "drop" else 100)
    )
    return Outcome(
        f"nonfinite_{policy}", "gauge_force", "NaN on r (in the tare window), −inf on ref",
        f"{policy}s the instants (counted) before the tare: the offset stays finite", "counted; force finite", ok,
        f"counters {blk.counters}; max |F| {float(np.abs(f).max()):.1e} N",
    )  # fmt: skip


def gauge_overflow() -> Outcome:
    """Finite readings of 1e306 whose calibrated force overflows: a warning-crash, a silent inf, or counted?"""
    r = np.full((10, 4), 1e306)
    r[:, 0] = -1e306
    blk = GaugeForce(mode="general", matrix=((1e3, 1e3, 1e3, 1e3),) * 3)
    f = run_offline(blk, r=r)["f"].data
    n_bad = int((~np.isfinite(f)).any(axis=1).sum())
    ok = n_bad == 0 or blk.counters.get("overflow") == n_bad
    return Outcome(
        "overflow", "gauge_force", "finite readings of ±1e306 with a 1e3 N calibration (F overflows)",
        "emits ±inf/NaN and counts each such sample (overflow); the consumer's on_bad_data applies",
        "every non-finite output counted, no warning", ok, f"{n_bad} non-finite rows; counters {blk.counters}",
        {"bad_rows": n_bad, "counted": blk.counters.get("overflow", 0)},
    )  # fmt: skip


CASES: tuple[StressCase, ...] = (
    StressCase("scale_1e6", "gauge_force", partial(gauge_scale, 1e6)),
    StressCase("scale_1e-12", "gauge_force", partial(gauge_scale, 1e-12)),
    *(StressCase(f"nonfinite_{p}", "gauge_force", partial(gauge_bad, p)) for p in ("raise", "drop", "hold")),
    StressCase("overflow", "gauge_force", gauge_overflow),
)
