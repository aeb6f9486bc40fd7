"""Numerical stress cases for ``naive_bayes``: huge spike counts and broken window values.

Listed in :data:`flowtact.blocks.spiking.stress_cases.CASES` (the room's one list).
"""

from __future__ import annotations

import numpy as np

import flowtact.api as ft
from flowtact.testing import run_offline
from flowtact.verify.stress import Outcome, StressCase

from .naive_bayes import NaiveBayes, example_model_path

__all__ = ["CASES"]

SPECS = {
    "spikes": ft.StreamSpec(dtype="int64", events=True, n_units=4),
    "window": ft.StreamSpec(dtype="float64", rate_hz=250.0),
}


def huge_counts() -> Outcome:
    """10⁶ spikes of one unit in one window: log-domain scores stay finite, the posterior is a
    distribution (one class at 1, the rest underflow to 0, never NaN)."""
    window = np.r_[np.full(5, -1.0), np.full(50, 0.0), np.full(5, -1.0)]
    t = np.sort(np.random.default_rng(1).uniform(0.02, 0.22, 10**6))
    out = run_offline(NaiveBayes(model=str(example_model_path())), spikes=(t, np.zeros(len(t), np.int64)),
                      window=window, rate_hz=250.0, specs=SPECS)  # fmt: skip
    p, run = out["posterior"].data, out["running"].data
    ok = bool(len(p) == 1 and np.isfinite(p).all() and np.isfinite(run).all())
    ok = ok and abs(p.sum() - 1.0) <= 1e-12 and (p >= 0).all()
    return Outcome("huge_counts", "naive_bayes", "10⁶ spikes of one unit in one 0.2 s window",
                   f"posterior {np.round(p[0], 3).tolist()}, running finite", "finite, sums to 1", ok)  # fmt: skip


def broken_window_values() -> Outcome:
    """Window samples NaN, ±inf, 2.5 and 1e300 inside a window: counted as no category, treated as gap."""
    window = np.r_[
        np.full(5, -1.0), np.full(20, 1.0), [np.nan, np.inf, -np.inf, 2.5, 1e300], np.full(20, 1.0), -1.0
    ]
    blk = NaiveBayes(model=str(example_model_path()))
    out = run_offline(
        blk, spikes=(np.array([0.05, 0.15]), np.array([1, 2])), window=window, rate_hz=250.0, specs=SPECS
    )
    n = blk.counters.get("unknown_window_values", 0)
    ok = n == 5 and len(out["decision"]) == 2 and bool(np.isfinite(out["running"].data).all())
    return Outcome("window_broken", "naive_bayes", "window values NaN, ±inf, 2.5, 1e300 inside a window",
                   f"{len(out['decision'])} windows decoded, {n} samples counted unknown",
                   "treated as gap (the window splits in two), counted, outputs finite", ok)  # fmt: skip


CASES: tuple[StressCase, ...] = (
    StressCase("huge_counts", "naive_bayes", huge_counts),
    StressCase("window_broken", "naive_bayes", broken_window_values),
)
