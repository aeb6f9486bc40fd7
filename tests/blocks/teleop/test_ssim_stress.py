"""Numerical stress of ssim (issue 12, item 4): uniform and saturated images against scikit-image."""

from __future__ import annotations

import pytest

from flowtact.blocks.teleop import stress_cases as sc
from flowtact.verify.stress import run_case

CASES = [c for c in sc.CASES if c.block == "ssim"]


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_stress_case_passes(case):
    out = run_case(case)
    assert out.passed, f"{out.behaviour} | {out.measured}"
    assert out.metrics["err64"] <= 1e-12 and out.metrics["err32"] <= 1e-6
