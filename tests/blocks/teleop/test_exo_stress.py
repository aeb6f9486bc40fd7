"""Numerical stress of the exoskeleton chain (issue 12, item 4): singular IK poses, out-of-range FSR
readings and extreme forces, down to the force-feedback command."""

from __future__ import annotations

import pytest

from flowtact.blocks.teleop import stress_cases as sc
from flowtact.verify.stress import run_case

CASES = [c for c in sc.CASES if c.block != "ssim"]


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_stress_case_passes(case):
    out = run_case(case)
    assert out.passed, f"{out.behaviour} | {out.measured}"


def test_folded_finger_error_is_the_arccos_conditioning_not_zero():
    err = sc.ik_pose("folded").metrics["ang_err"]
    assert 1e-10 < err <= 3 * (8 * 2.2e-16) ** 0.5  # √ε-sized: arccos near 1, as derived


def test_full_scale_force_is_clamped_at_max_us():
    assert sc.feedback_extreme().metrics["max_dev"] == 600.0
