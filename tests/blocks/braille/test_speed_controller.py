"""speed_controller: the confidence → speed law, its bounds, rate limit and fail-safe; the lateral corrector."""

import numpy as np
import pytest

from flowtact import ConfigError
from flowtact.blocks.braille.speed_controller import SpeedController, confidence
from flowtact.testing import CHECKS, run_offline


def posteriors(top: np.ndarray, c: int = 4) -> np.ndarray:
    """Rows whose largest probability is ``top`` (the rest spread evenly)."""
    top = np.asarray(top, float)
    rest = (1.0 - top) / (c - 1)
    return np.column_stack([top, *[rest] * (c - 1)])


def speeds(blk, p, rate=250.0):
    return run_offline(blk, posterior=p, rate_hz=rate)["speed"].data


def test_confidence_measures():
    p = np.array([[0.7, 0.1, 0.1, 0.1], [0.25] * 4, [1.0, 0, 0, 0], [2.0, 2.0, 0, 0]])
    np.testing.assert_allclose(confidence(p, "max"), [0.7, 0.25, 1.0, 0.5])
    h = -(0.7 * np.log(0.7) + 3 * 0.1 * np.log(0.1))
    np.testing.assert_allclose(confidence(p, "entropy"), [1 - h / np.log(4), 0.0, 1.0, 0.5])
    bad = np.array([[np.nan, 0.5, 0.5, 0], [0, 0, 0, 0], [-0.1, 1.1, 0, 0], [np.inf, 0, 0, 0]])
    assert np.isnan(confidence(bad, "max")).all() and np.isnan(confidence(bad, "entropy")).all()


def test_target_is_linear_between_unsure_and_sure_and_clamped_outside():
    blk = SpeedController(min_speed_mm_s=10, max_speed_mm_s=70, unsure=0.4, sure=0.9, max_accel_mm_s2=1e9)
    v = speeds(blk, posteriors([0.3, 0.4, 0.65, 0.9, 1.0]))
    np.testing.assert_allclose(v, [10, 10, 40, 70, 70])
    assert blk.counters["clamped"] == 2  # confidences beyond the corners (0.3 and 1.0)


def test_rate_limit_bounds_every_step():
    blk = SpeedController(max_accel_mm_s2=500.0, start_speed_mm_s=10.0)
    v = speeds(blk, posteriors(np.r_[np.full(200, 0.99), np.full(200, 0.3)]))
    dv = np.abs(np.diff(np.r_[10.0, v]))
    assert dv.max() <= 500.0 / 250.0 + 1e-12
    assert v.max() == 80.0 and v[-1] == 10.0 and blk.counters["rate_limited"] > 0
    np.testing.assert_allclose(v[:3], [12.0, 14.0, 16.0])


def test_speed_never_leaves_the_bounds_whatever_comes_in():
    rng = np.random.default_rng(0)
    p = rng.uniform(-0.5, 2.0, (2000, 6))
    p[rng.random(2000) < 0.05] = np.nan
    p[rng.random(2000) < 0.02] = np.inf
    blk = SpeedController(min_speed_mm_s=15, max_speed_mm_s=60, start_speed_mm_s=60)
    v = speeds(blk, p)
    assert np.isfinite(v).all() and v.min() >= 15 and v.max() <= 60


def test_a_broken_posterior_stops_at_the_minimum_at_once():
    p = posteriors(np.full(100, 0.99))
    p[60] = np.nan
    p[61] = 0.0
    blk = SpeedController(max_accel_mm_s2=100.0, start_speed_mm_s=80.0)
    v = speeds(blk, p)
    assert v[59] == 80.0 and v[60] == v[61] == 10.0  # no rate limit on the way down to safety
    assert v[62] == pytest.approx(10.4) and blk.counters["fail_safe"] == 2


def test_irregular_time_steps_use_the_real_interval():
    blk = SpeedController(max_accel_mm_s2=100.0, start_speed_mm_s=10.0)
    t = np.array([0.0, 0.01, 0.11, 0.12])
    out = run_offline(blk, posterior=posteriors(np.full(4, 1.0)), t=t, rate_hz=250.0)
    np.testing.assert_allclose(out["speed"].data, [10.4, 11.4, 21.4, 22.4])


def test_lateral_corrector_integrates_the_error_within_its_bound():
    err = np.r_[np.full(250, 0.5), np.full(10, np.nan), np.full(250, -1.0)]
    blk = SpeedController(lateral_gain_hz=2.0, max_lateral_mm=0.6)
    out = run_offline(blk, posterior=posteriors(np.full(510, 0.5)), lateral_error=err, rate_hz=250.0)
    y = out["lateral"].data
    assert y[0] == pytest.approx(-2.0 * 0.004 * 0.5)
    assert y[100] == pytest.approx(-101 * 0.004)  # −0.004 mm per sample
    assert y[249] == -0.6 and (y[250:260] == -0.6).all()  # clamped at −0.6; held through the NaNs
    assert y[260] == pytest.approx(-0.6 + 0.008) and y[-1] == 0.6 and np.abs(y).max() <= 0.6
    assert blk.counters["lateral_fail_safe"] == 10 and blk.counters["lateral_clamped"] > 0


def test_bad_parameters_are_refused_naming_the_field():
    with pytest.raises(ConfigError, match="'max_speed_mm_s' must be >= min_speed_mm_s"):
        SpeedController(min_speed_mm_s=50, max_speed_mm_s=20)
    with pytest.raises(ConfigError, match="'sure' must be > unsure"):
        SpeedController(unsure=0.8, sure=0.7)
    with pytest.raises(ConfigError, match="'start_speed_mm_s' must lie in"):
        SpeedController(start_speed_mm_s=100.0)


@pytest.mark.parametrize("check", CHECKS, ids=lambda c: c.__name__.removeprefix("check_"))
def test_speed_controller_conforms(check):
    check(SpeedController)
