"""Numerical stress of weighted_sum (issue 12, item 4): 1e6 / 1e-12 scale, NaN/inf, overflow."""

from __future__ import annotations

import numpy as np
import pytest

from flowtact.blocks.signal import stress_cases as sc
from flowtact.blocks.signal.weighted_sum import WeightedSum
from flowtact.testing import run_offline
from flowtact.verify.stress import run_case

CASES = [c for c in sc.CASES if c.block == "weighted_sum"]


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_stress_case_passes(case):
    out = run_case(case)
    assert out.passed, f"{out.behaviour} | {out.measured}"


def test_overflow_is_counted_not_a_warning_and_finite_rows_untouched():
    x = np.ones((6, 3))
    x[2] = 1e308
    x[4] = [1e308, -1e308, 0.0]  # +inf and −inf terms: NaN
    blk = WeightedSum(w1=[4.0, 4.0, 1.0])
    y = run_offline(blk, x1=x, units={"x1": "N"}, chunk=4)["y"].data  # filterwarnings=error: no warning
    assert blk.counters == {"overflow": 2}
    assert np.isinf(y[2]) and np.isnan(y[4])
    assert y[[0, 1, 3, 5]].tolist() == [9.0] * 4
