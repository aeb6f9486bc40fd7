"""Tests of blocks/touch/calibration.py: gauge_force (eqs. 1–2 of Rager et al.) and shear_angle (eq. 3)."""

import doctest

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from flowtact import BadDataError, Chunk, ConfigError, SpecError, StreamSpec, concat
from flowtact.blocks.touch.aunp import SENSITIVITY_PER_N, reduced_matrix
from flowtact.blocks.touch.calibration import GaugeForce, ShearAngle
from flowtact.errors import MisalignedError
from flowtact.testing import run_offline

RATE = 1000.0
R_SPEC = StreamSpec(shape=(4,), units="1", rate_hz=RATE)
REF_SPEC = StreamSpec(shape=(), units="1", rate_hz=RATE)


def gauges_from_force(f: np.ndarray, sens=SENSITIVITY_PER_N) -> np.ndarray:
    """Inverse of eq. 2 (the synthetic sensor's model): forces (n, 3) -> ΔR/R (n, 4)."""
    xs, ys, zs = sens
    fx, fy, fz = f.T
    return np.stack(
        [
            fz * zs / 4 - fx * xs / 2,
            fz * zs / 4 + fy * ys / 2,
            fz * zs / 4 + fx * xs / 2,
            fz * zs / 4 - fy * ys / 2,
        ],
        1,
    )


# -- gauge_force --------------------------------------------------------------------------------------


def test_reduced_mode_hand_computed():
    r = np.array([[0.001, 0.004, 0.009, 0.002], [-0.01, 0.0, 0.01, 0.0]])
    out = run_offline(GaugeForce(sensitivity_per_n=[0.02, 0.05, 0.04]), r=r)["f"]
    # Fx = (r3 - r1)/Xs, Fy = (r2 - r4)/Ys, Fz = (r1 + r2 + r3 + r4)/Zs
    assert_allclose(out.data, [[0.4, 0.04, 0.4], [1.0, 0.0, 0.0]], rtol=1e-14, atol=1e-16)


def test_general_mode_hand_computed():
    a = [[1.0, 2.0, 0.0, -1.0], [0.0, 0.0, 3.0, 0.0], [0.5, 0.5, 0.5, 0.5]]
    r = np.array([[1.0, 2.0, 3.0, 4.0], [0.0, -1.0, 2.0, 0.0]])
    out = run_offline(GaugeForce(mode="general", matrix=a), r=r)["f"]
    assert_array_equal(out.data, [[1.0, 9.0, 5.0], [-2.0, 6.0, 0.5]])  # exact small-integer sums


def test_reduced_equals_general_with_reduced_matrix():
    r = np.random.default_rng(0).normal(0.0, 0.01, (500, 4))
    sens = (0.03, 0.02, 0.05)
    red = run_offline(GaugeForce(mode="reduced", sensitivity_per_n=sens), r=r, chunk=17)["f"]
    gen = run_offline(GaugeForce(mode="general", matrix=reduced_matrix(*sens)), r=r)["f"]
    assert_array_equal(red.data, gen.data)  # bit for bit


def test_recovers_the_synthetic_sensors_force():
    t = np.arange(1000) / RATE
    f = np.stack([0.3 * np.sin(2 * np.pi * t), 0.2 * np.cos(5 * t), 0.12 + t], 1)
    out = run_offline(GaugeForce(), r=gauges_from_force(f), chunk=64)["f"]
    assert_allclose(out.data, f, rtol=1e-12, atol=1e-14)
    assert_array_equal(out.t, t)


def test_reference_gauge_is_subtracted_from_every_gauge():
    f = np.tile([0.2, -0.1, 0.5], (300, 1))
    drift = np.linspace(0.0, 0.01, 300)  # temperature: common to all gauges and the reference
    r = gauges_from_force(f) + drift[:, None]
    plain = run_offline(GaugeForce(), r=r)["f"].data
    assert_allclose(plain[:, 2], 0.5 + 4 * drift / SENSITIVITY_PER_N[2], rtol=1e-12)  # Fz drifts
    comp = run_offline(GaugeForce(), r=r, ref=drift)["f"].data
    assert_allclose(comp, f, rtol=1e-12, atol=1e-14)


def test_reference_aligned_across_different_chunkings():
    rng = np.random.default_rng(1)
    r, ref = rng.normal(0, 0.01, (400, 4)), rng.normal(0, 0.001, 400)
    t = np.arange(400) / RATE
    whole = run_offline(GaugeForce(), r=r, ref=ref)["f"]
    b = GaugeForce()
    b.bind({"r": R_SPEC, "ref": REF_SPEC})
    outs = [b(r=Chunk(t[:150], r[:150]), ref=Chunk(t[:10], ref[:10]))["f"]]
    assert len(outs[0]) == 10  # emits the common prefix only
    outs.append(b(r=Chunk(t[150:], r[150:]))["f"])
    outs.append(b(ref=Chunk(t[10:], ref[10:]))["f"])
    got = concat(outs)
    assert_array_equal(got.t, whole.t)
    assert_array_equal(got.data, whole.data)
    with pytest.raises(MisalignedError):
        b(r=Chunk(t[:5] + 1.0, r[:5]), ref=Chunk(t[:5] + 1.0005, ref[:5]))


def test_tare_subtracts_mean_of_first_samples_and_loses_nothing():
    rng = np.random.default_rng(2)
    f = np.array([0.05, -0.02, 0.3]) + rng.normal(0.0, 0.01, (200, 3))
    r = gauges_from_force(f)
    raw = run_offline(GaugeForce(), r=r)["f"].data
    block = GaugeForce(tare_samples=25)
    block.bind({"r": R_SPEC})
    t = np.arange(200) / RATE
    first = block(r=Chunk(t[:24], r[:24]))["f"]
    assert len(first) == 0  # held back until the offset is known
    rest = block(r=Chunk(t[24:], r[24:]))["f"]
    assert_array_equal(rest.t, t)
    assert_allclose(rest.data, raw - raw[:25].mean(axis=0), rtol=1e-12, atol=1e-15)
    whole = run_offline(GaugeForce(tare_samples=25), r=r)["f"]
    assert_array_equal(whole.data, rest.data)


def test_tare_on_a_short_stream_uses_what_arrived():
    r = gauges_from_force(np.array([[0.1, 0.0, 0.2], [0.3, 0.0, 0.4]]))
    block = GaugeForce(tare_samples=10)
    out = run_offline(block, r=r)["f"]
    assert_allclose(out.data, [[-0.1, 0.0, -0.1], [0.1, 0.0, 0.1]], atol=1e-14)
    assert block.counters == {"tare_short": 1}


def test_gauge_force_specs():
    spec = GaugeForce().bind({"r": R_SPEC})["f"]
    assert (spec.shape, spec.units, spec.labels, spec.rate_hz) == ((3,), "N", ("Fx", "Fy", "Fz"), RATE)
    for bad, port, msg in [
        ({"r": R_SPEC.with_(units="mN")}, "r", "ΔR/R"),
        ({"r": R_SPEC.with_(shape=(3,))}, "r", r"shape \(4,\)"),
        ({"r": R_SPEC, "ref": REF_SPEC.with_(shape=(1,))}, "ref", r"shape \(\)"),
        ({"r": R_SPEC, "ref": REF_SPEC.with_(rate_hz=500.0)}, "ref", "500 Hz"),
    ]:
        with pytest.raises(SpecError, match=msg) as e:
            GaugeForce().bind(bad)
        assert e.value.port == port


def test_gauge_force_config_rules():
    with pytest.raises(ConfigError, match="'matrix' is required with mode 'general'"):
        GaugeForce(mode="general")
    with pytest.raises(ConfigError, match="'matrix' must have 4 columns"):
        GaugeForce(mode="general", matrix=[[1, 2, 3, 4], [1, 2, 3], [1, 2, 3, 4]])
    with pytest.raises(ConfigError, match="'matrix' must be a list of at least 3"):
        GaugeForce(mode="general", matrix=[[1, 2, 3, 4]])
    with pytest.raises(ConfigError, match="'matrix' is only used with mode 'general'"):
        GaugeForce(matrix=reduced_matrix(1, 1, 1))
    with pytest.raises(ConfigError, match="'sensitivity_per_n' must be > 0"):
        GaugeForce(sensitivity_per_n=[0.02, 0.0, 0.04])


def test_gauge_force_bad_data_hold_uses_the_last_good_sample_across_chunks():
    r = gauges_from_force(np.random.default_rng(3).normal(0, 0.2, (100, 3)))
    bad = r.copy()
    bad[70, 2] = np.nan
    with pytest.raises(BadDataError, match="input 'r'"):
        run_offline(GaugeForce(), r=bad)
    block = GaugeForce(on_bad_data="hold")
    out = run_offline(block, r=bad, chunk=30)["f"].data
    held = r.copy()
    held[70, 2] = r[69, 2]
    assert_array_equal(out, run_offline(GaugeForce(), r=held)["f"].data)
    assert block.counters == {"nonfinite_hold": 1}
    out = run_offline(GaugeForce(on_bad_data="drop"), r=bad, chunk=30)["f"]
    assert len(out) == 99 and 0.070 not in out.t


# -- shear_angle --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("dx", "dy", "theta"),
    [
        (1, 0, 0.0),
        (1, 1, np.pi / 4),
        (0, 1, np.pi / 2),
        (-1, 1, 3 * np.pi / 4),
        (-1, 0, np.pi),
        (-1, -1, -3 * np.pi / 4),
        (0, -1, -np.pi / 2),
        (1, -1, -np.pi / 4),
        (0, 0, 0.0),
    ],
)
def test_shear_angle_quadrants(dx, dy, theta):
    # Θ = atan2(r2 − r4, r3 − r1): build gauges with r3 − r1 = dx, r2 − r4 = dy on a common offset
    base = 0.01
    r = np.array([[base, base + 0.004 * dy, base + 0.004 * dx, base]])
    out = run_offline(ShearAngle(), r=r)["theta"]
    assert_allclose(out.data, [theta], atol=1e-12)


def test_shear_angle_follows_the_shear_force_and_ignores_common_mode():
    rng = np.random.default_rng(4)
    phi = rng.uniform(-np.pi, np.pi, 300)
    f = np.stack([np.cos(phi), np.sin(phi), rng.uniform(0.1, 2.0, 300)], 1)
    r = gauges_from_force(f, sens=(0.02, 0.02, 0.04)) + rng.normal(0, 1.0, (300, 1))
    out = run_offline(ShearAngle(), r=r, chunk=7)["theta"]
    assert_allclose(out.data, phi, atol=1e-9)
    spec = ShearAngle().bind({"r": R_SPEC})["theta"]
    assert (spec.shape, spec.units, spec.rate_hz) == ((), "rad", RATE)
    with pytest.raises(SpecError, match="ΔR/R"):
        ShearAngle().bind({"r": R_SPEC.with_(units="N")})


def test_docstring_examples_run():
    import flowtact.blocks.touch.calibration as module

    result = doctest.testmod(module, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted >= 3
    assert result.failed == 0
