"""Numerical stress of braille_scan: the cases of flowtact.blocks.braille.stress_cases."""

import pytest

from flowtact.blocks.braille import stress_cases as sc
from flowtact.verify.stress import run_case


@pytest.mark.parametrize("case", sc.CASES, ids=[c.name for c in sc.CASES])
def test_stress_case_passes(case):
    out = run_case(case)
    assert out.passed, f"{out.behaviour} | {out.measured}"
    assert not out.behaviour.startswith("CRASH")


def test_a_zero_or_negative_speed_never_stops_or_reverses_the_finger():
    for value in (0.0, -30.0):
        out = sc.speed_value(value)
        assert out.metrics["v_min"] == pytest.approx(5.0, rel=1e-9) == out.metrics["v_max"]
        assert out.metrics["counted"] == 400
