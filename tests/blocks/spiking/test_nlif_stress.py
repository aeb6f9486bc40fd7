"""Numerical stress of nlif (issue 12, item 4): the cases of flowtact.blocks.spiking.stress_cases."""

from __future__ import annotations

import numpy as np
import pytest

from flowtact.blocks.spiking import stress_cases as sc
from flowtact.verify.stress import EPS, run_case

FAST = [c for c in sc.CASES if not c.slow]
LONG = [c for c in sc.CASES if c.slow]


@pytest.mark.parametrize("case", FAST, ids=[c.name for c in FAST])
def test_stress_case_passes(case):
    out = run_case(case)
    assert out.passed, f"{out.behaviour} | {out.measured}"
    assert not out.behaviour.startswith("CRASH")


def test_tiny_tau_exp_reaches_the_drive_exactly_and_euler_is_refused():
    out = sc.tau_tiny("exp")
    assert out.metrics["v_err"] == 0.0  # e^(−1000) underflows to 0: v = u·(1 − 0) exactly
    assert out.metrics["spikes_sub"] == 0 and out.metrics["spikes_sup"] == 2000
    refused = sc.tau_tiny("euler")
    assert refused.passed and "refused at bind" in refused.behaviour and "dt >= 2·tau" in refused.behaviour


def test_huge_tau_euler_error_is_first_order_and_exp_is_exact():
    assert sc.tau_huge("exp").metrics["rel_err"] <= 1000 * 4 * EPS
    euler = sc.tau_huge("euler").metrics["rel_err"]
    assert 0.1 * sc.DT / 1e6 < euler <= sc.DT / 1e6  # dt/(2τ) in size: a real first-order error


@pytest.mark.parametrize("case", LONG, ids=[c.name for c in LONG])
def test_long_run_1e7_steps_no_drift(case):
    out = case.run()
    assert out.passed, out.measured
    assert out.metrics["v_change"] == 0.0  # the fixed point is reached and held bit for bit


@pytest.mark.slow
@pytest.mark.parametrize("case", LONG, ids=[c.name for c in LONG])
def test_long_run_1e8_steps_no_drift(case):
    out = case.full()
    assert out.passed, out.measured


def test_long_run_grid_spikes_exactly_on_grid():
    m = sc.long_run("exp", 200_000, 1.5, chunk=65_536)
    assert m["max_t_err"] == 0.0 and m["period"] == pytest.approx(0.011, abs=1e-12)
    # 1.5·(1 − a^k) > 1 first for k = 11 updates, i.e. in step 10, then every 11 steps
    assert m["spikes"] == (200_000 - 1 - 10) // 11 + 1
    v = sc.long_run("euler", 50_000, 0.9, chunk=4096)
    assert abs(v["v_last"] - 0.9) <= 4 * EPS * 0.9 / (1 - np.exp(-0.1))
