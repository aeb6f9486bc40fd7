"""Numerical stress of gauge_force (issue 12, item 4): 1e6 / 1e-12 scale, NaN/inf, overflow."""

from __future__ import annotations

import pytest

from flowtact.blocks.touch import stress_cases as sc
from flowtact.verify.stress import run_case

CASES = list(sc.CASES)


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_stress_case_passes(case):
    out = run_case(case)
    assert out.passed, f"{out.behaviour} | {out.measured}"


def test_overflow_counted_per_row():
    m = sc.gauge_overflow().metrics
    assert m["bad_rows"] == m["counted"] == 10
