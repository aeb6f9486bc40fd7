"""Numerical stress of savgol (issue 12, item 4): scale, NaN/inf, jittered and gapped timestamps."""

from __future__ import annotations

import numpy as np
import pytest

from flowtact.blocks.signal import stress_cases as sc
from flowtact.blocks.signal.savgol import SavGol
from flowtact.testing import run_offline
from flowtact.verify.stress import run_case

CASES = [c for c in sc.CASES if c.block == "savgol"]


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_stress_case_passes(case):
    out = run_case(case)
    assert out.passed, f"{out.behaviour} | {out.measured}"


def test_jitter_is_counted_and_really_hurts():
    out = sc.savgol_jitter()
    assert out.metrics["irregular_dt"] == out.metrics["expected"] > 4000
    assert out.metrics["rel_rms"] > 0.05  # the flag is not crying wolf: F' is off by ~10 %


def test_gaps_counted_once_each_whatever_the_chunking():
    t = np.delete(np.arange(400), [100, 101, 102, 300]) / sc.RATE
    for chunk in (None, 1, 7, 101):
        blk = SavGol()
        run_offline(blk, x=np.sin(t), t=t, chunk=chunk)
        assert blk.counters == {"sample_gaps": 2}, chunk


def test_regular_stream_far_from_zero_counts_nothing():
    t = 1e5 + np.arange(2000) / sc.RATE  # interval rounding ~1e-11 s: far below 1 % of dt
    blk = SavGol()
    run_offline(blk, x=np.zeros(2000), t=t, chunk=333)
    assert blk.counters == {}


def test_half_percent_jitter_is_tolerated_two_percent_is_not():
    grid = np.arange(100) / sc.RATE
    for jit, want in ((0.004, 0), (0.02, 99)):
        t = grid + jit / sc.RATE * (np.arange(100) % 2)  # alternate ±jit·dt intervals
        blk = SavGol()
        run_offline(blk, x=np.zeros(100), t=t)
        assert blk.counters.get("irregular_dt", 0) == want
