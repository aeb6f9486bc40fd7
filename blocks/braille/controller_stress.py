"""Numerical stress cases for ``speed_controller``: hostile posteriors and lateral errors.

Listed in :data:`flowtact.blocks.braille.stress_cases.CASES` (the room's one list).
"""

from __future__ import annotations

import numpy as np

from flowtact.testing import run_offline
from flowtact.verify.stress import Outcome, StressCase

from .speed_controller import SpeedController

__all__ = ["CASES"]

N = 1000


def hostile_posteriors() -> Outcome:
    """Posteriors with NaN, ±inf, negative, all-zero and 1e300 entries among good ones: the speed stays
    finite and within bounds, every broken row commands the minimum and is counted."""
    rng = np.random.default_rng(4)
    p = rng.dirichlet(np.full(26, 0.1), N)
    bad = rng.choice(N, 200, replace=False)
    kinds = [np.nan, np.inf, -np.inf, -1.0, 0.0]
    for k, row in enumerate(bad):
        p[row] = 0.0 if kinds[k % 5] == 0.0 else p[row]
        p[row, k % 26] = kinds[k % 5] if kinds[k % 5] != 0.0 else 0.0
    p[rng.choice(np.setdiff1d(np.arange(N), bad), 50, replace=False), 0] = 1e300  # huge but a distribution
    blk = SpeedController(min_speed_mm_s=100.0, max_speed_mm_s=300.0, start_speed_mm_s=300.0)
    v = run_offline(blk, posterior=p, rate_hz=250.0)["speed"].data
    ok = bool(np.isfinite(v).all() and v.min() >= 100.0 and v.max() <= 300.0 and (v[bad] == 100.0).all())
    ok = ok and blk.counters.get("fail_safe") == 200
    return Outcome(
        "posterior_hostile", "speed_controller", "200 of 1000 posteriors with NaN, ±inf, −1 or all zeros; 50 with 1e300",
        f"speed {v.min():g}..{v.max():g} mm/s, broken rows at {np.unique(v[bad])} mm/s, fail_safe {blk.counters.get('fail_safe')}",
        "speed finite in [100, 300]; every broken row → minimum at once, counted", ok,
    )  # fmt: skip


def hostile_lateral() -> Outcome:
    """Lateral errors of ±1e300 mm, ±inf and NaN: the correction stays within ±max_lateral_mm."""
    e = np.zeros(N)
    e[100:200], e[200:300], e[300:310], e[310:320], e[320:330] = 1e300, -1e300, np.inf, -np.inf, np.nan
    blk = SpeedController(max_lateral_mm=2.0)
    y = run_offline(blk, posterior=np.full((N, 3), 1 / 3), lateral_error=e, rate_hz=250.0)["lateral"].data
    ok = bool(np.isfinite(y).all() and np.abs(y).max() <= 2.0 and y[150] == -2.0 and y[250] == 2.0)
    ok = ok and blk.counters.get("lateral_fail_safe") == 30
    return Outcome(
        "lateral_hostile", "speed_controller", "lateral error ±1e300 mm, ±inf, NaN",
        f"correction {y.min():g}..{y.max():g} mm, held on {blk.counters.get('lateral_fail_safe')} non-finite samples",
        "|correction| ≤ max_lateral_mm, non-finite held and counted", ok,
    )  # fmt: skip


CASES: tuple[StressCase, ...] = (
    StressCase("posterior_hostile", "speed_controller", hostile_posteriors),
    StressCase("lateral_hostile", "speed_controller", hostile_lateral),
)
