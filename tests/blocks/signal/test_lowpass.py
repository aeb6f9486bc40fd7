"""Tests of the lowpass block in blocks/signal/savgol.py (first-order, on the samples' own timestamps)."""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from flowtact import BadDataError, Chunk, ConfigError, SpecError, StreamSpec
from flowtact.blocks.signal.lowpass import Lowpass, lowpass_apply, lowpass_apply_python
from flowtact.testing import assert_same, run_offline

signal = pytest.importorskip("scipy.signal")


def jittered(n, rate=100.0, jitter=0.3, seed=0):
    rng = np.random.default_rng(seed)
    return np.cumsum(rng.uniform(1 - jitter, 1 + jitter, n) / rate)


def test_step_response_is_the_continuous_one_at_every_sample_even_with_jitter():
    t = jittered(300)
    x = np.ones((300, 2))
    x[0] = 0.0  # the state starts at the first sample (0), then a unit step
    y = run_offline(Lowpass(cutoff_hz=5.0), x=x, t=t, rate_hz=100.0)["y"].data
    assert_allclose(y[:, 0], 1.0 - np.exp(-2 * math.pi * 5.0 * (t - t[0])), rtol=1e-12, atol=1e-15)


def test_nominal_mode_equals_scipy_lfilter():
    rng = np.random.default_rng(1)
    x = rng.normal(size=(500, 3))
    y = run_offline(Lowpass(cutoff_hz=8.0, time_base="nominal", initial="zero"), x=x, rate_hz=100.0)["y"].data
    a = 1.0 - math.exp(-2 * math.pi * 8.0 / 100.0)
    ref = signal.lfilter([a], [1.0, -(1.0 - a)], x, axis=0)
    assert_allclose(y, ref, rtol=1e-11, atol=1e-13)


def test_kernel_equals_python_twin_bit_for_bit():
    rng = np.random.default_rng(2)
    t = jittered(400, jitter=0.9, seed=3)
    t[100] = t[99]  # a repeated stamp
    x = rng.normal(size=(400, 4))
    for use_t, first in ((True, True), (True, False), (False, True)):
        s1, s2 = np.zeros(4), np.zeros(4)
        a = lowpass_apply(t, x, s1, 0.0, False, 2 * math.pi * 7.0, 0.3, use_t, first)
        b = lowpass_apply_python(t, x, s2, 0.0, False, 2 * math.pi * 7.0, 0.3, use_t, first)
        assert_array_equal(a[0], b[0])
        assert_array_equal(s1, s2)
        assert a[1:] == b[1:]


def test_chunking_invariance_on_irregular_stamps_any_shape():
    t = jittered(301, jitter=0.8)
    x = np.random.default_rng(4).normal(size=(301, 3, 2))
    whole = run_offline(Lowpass(), x=x, t=t, rate_hz=100.0)
    for chunk in (1, 7, [3, 250, 1, 64]):
        assert_same(run_offline(Lowpass(), x=x, t=t, rate_hz=100.0, chunk=chunk), whole)
    assert whole["y"].data.shape == (301, 3, 2)


def test_a_gap_lets_the_output_move_further_and_repeated_stamps_do_not_move_it():
    t = np.array([0.0, 0.01, 0.02, 0.5, 0.5, 0.51])
    x = np.array([0.0, 1.0, 1.0, 1.0, 5.0, 1.0])
    block = Lowpass(cutoff_hz=10.0)
    y = run_offline(block, x=x, t=t, rate_hz=100.0)["y"].data
    assert y[3] == pytest.approx(1.0 - math.exp(-2 * math.pi * 10.0 * 0.5), rel=1e-12)
    assert y[4] == y[3]  # a sample stamped like its predecessor leaves the state alone
    assert block.counters["nonincreasing_t"] == 1


def test_bad_data_policies_and_watermark():
    x = np.array([1.0, np.nan, 1.0])
    with pytest.raises(BadDataError):
        run_offline(Lowpass(), x=x, rate_hz=100.0)
    assert_array_equal(run_offline(Lowpass(on_bad_data="hold"), x=x, rate_hz=100.0)["y"].data, 1.0)
    assert len(run_offline(Lowpass(on_bad_data="drop"), x=x, rate_hz=100.0)["y"]) == 2
    block = Lowpass()
    block.bind({"x": StreamSpec(shape=(3,), units="N", rate_hz=100.0)})
    assert block(x=Chunk(np.array([0.0]), np.ones((1, 3)), 0.007))["y"].end == 0.007
    assert block(x=Chunk(np.empty(0), np.empty((0, 3)), 0.017))["y"].end == 0.017


def test_config_and_spec_errors():
    with pytest.raises(ConfigError, match="cutoff_hz"):
        Lowpass(cutoff_hz=0.0)
    with pytest.raises(SpecError, match="half"):
        Lowpass(cutoff_hz=60.0).bind({"x": StreamSpec(shape=(3,), units="N", rate_hz=100.0)})
    out = Lowpass().bind({"x": StreamSpec(shape=(3,), units="N", rate_hz=100.0, labels=("a", "b", "c"))})
    assert out["y"].labels == ("a", "b", "c") and out["y"].units == "N"
