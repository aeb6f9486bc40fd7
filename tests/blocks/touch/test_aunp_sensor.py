"""The synthetic AuNP sensor: force profiles, gauge model, temperature compensation, determinism."""

import numpy as np
import pytest

from flowtact import ConfigError
from flowtact.blocks.touch.aunp import SENSITIVITY_PER_N, reduced_matrix
from flowtact.blocks.touch.aunp_sensor import AunpSensor
from flowtact.blocks.touch.calibration import GaugeForce
from flowtact.blocks.touch.presets import TABLE_I
from flowtact.testing import assert_same, run_offline, run_source

QUIET = {"noise_sd": 0.0, "temp_drift_c": 0.0}


def force(duration_s=1.5, **params):
    out = run_source(AunpSensor(**params), duration_s, tick_s=0.25)
    return out["force"].t, out["force"].data


def centred_derivative(x, dt=1e-3):
    """5-point centred first derivative (what savgol window 5 / order 4 computes), edges zero."""
    d = np.zeros_like(x)
    d[2:-2] = (x[:-4] - 8 * x[1:-3] + 8 * x[3:-1] - x[4:]) / (12 * dt)
    return d


def test_rest_is_the_baseline_normal_force():
    t, f = force(0.5, scenario="rest", baseline_n=0.12)
    assert len(t) == 500 and np.array_equal(t, np.arange(500) / 1000.0)
    assert np.all(f[:, :2] == 0.0) and np.all(f[:, 2] == 0.12)


@pytest.mark.parametrize(("indentation_um", "stiffness"), [(20.0, 5.0), (10.0, 8.0), (35.0, 2.0)])
def test_touch_adds_stiffness_times_indentation(indentation_um, stiffness):
    p = dict(
        scenario="touch",
        onset_s=0.2,
        ramp_s=0.02,
        unload_s=0.02,
        hold_s=0.5,
        indentation_um=indentation_um,
        stiffness_n_per_mm=stiffness,
    )
    t, f = force(1.2, **p)
    step = stiffness * indentation_um * 1e-3
    before, plateau, after = t < 0.2, (t >= 0.22) & (t < 0.72), t >= 0.74 + 0.005
    assert np.all(f[before] == [0.0, 0.0, 0.12])
    np.testing.assert_allclose(f[plateau, 2], 0.12 + step, rtol=0, atol=1e-15)
    np.testing.assert_allclose(f[after], np.tile([0.0, 0.0, 0.12], (after.sum(), 1)), atol=1e-15)
    # monotone raised-cosine ramps in between
    load = (t >= 0.2) & (t <= 0.22)
    assert np.all(np.diff(f[load, 2]) >= 0)


def test_touch_tangential_force_lags_at_loading_and_snaps_back_at_unloading():
    p = dict(
        scenario="touch",
        onset_s=0.2,
        ramp_s=0.02,
        unload_s=0.02,
        hold_s=0.5,
        shear_ratio=0.5,
        shear_rise_s=0.08,
        shear_release_s=0.004,
        stiffness_n_per_mm=5.0,
    )
    t, f = force(1.2, **p)
    d_fz = 5.0 * 20e-3
    fx, fz = f[:, 0], f[:, 2]
    # within the friction cone of the probe's own normal load, at every sample
    assert np.all(np.hypot(fx, f[:, 1]) <= 1.0 * (fz - 0.12) + 1e-15)
    # plateau: shear_ratio of the added normal force, along +x
    plateau = (t >= 0.3) & (t < 0.72)
    np.testing.assert_allclose(fx[plateau], 0.5 * d_fz, atol=1e-15)
    # lag: when the normal load is complete the shear is still far from its plateau
    i_full = np.searchsorted(t, 0.22)
    assert fz[i_full] == pytest.approx(0.12 + d_fz) and fx[i_full] < 0.2 * 0.5 * d_fz
    # release: shear is gone within shear_release_s of the unloading start, normal force is not
    i_rel = np.searchsorted(t, 0.72 + 0.004)
    assert fx[i_rel] == pytest.approx(0.0, abs=1e-15) and fz[i_rel] > 0.12 + 0.9 * d_fz


def test_touch_drives_fa1_at_onset_and_offset_and_sa1_on_the_plateau():
    """The design property the afferent models rely on (Table I drives from the true force)."""
    t, f = force(1.2, scenario="touch", onset_s=0.2, hold_s=0.5)  # the defaults
    df = centred_derivative(f)
    drive = {}
    for pop, w in TABLE_I.items():
        drive[pop] = f @ np.array(w[:3]) + df @ np.array(w[3:6])
    fa1, sa1 = drive["FA1"], drive["SA1"]
    rest, plateau = (t >= 0.05) & (t < 0.19), (t >= 0.35) & (t < 0.70)
    onset, offset = (t >= 0.2) & (t < 0.24), (t >= 0.71) & (t < 0.72)
    assert fa1[onset].max() > 1.5 * fa1[plateau].max()
    assert fa1[offset].max() > 1.5 * fa1[plateau].max()
    assert fa1[(t >= 0.72) & (t < 0.74)].max() < fa1[plateau].min()  # then unloading inhibits FA1
    assert fa1[(t >= 0.72) & (t < 0.74)].min() < 0.0
    assert sa1[plateau].min() > 2.0 * sa1[rest].max()


def test_slip_lasts_slip_s_and_turns_the_shear():
    p = dict(
        scenario="slip",
        onset_s=0.1,
        ramp_s=0.02,
        stiffness_n_per_mm=5.0,
        drag_s=0.3,
        slip_s=0.26,
        slip_turn_deg=180.0,
        hold_s=0.3,
        shear_angle_deg=30.0,
        friction_mu=1.0,
        kinetic_ratio=0.6,
    )
    t, f = force(1.3, **p)
    fxy = np.hypot(f[:, 0], f[:, 1])
    # friction (eq. 4): never above mu_s * Fz; reaches it at the slip onset
    assert np.all(fxy <= 1.0 * f[:, 2] + 1e-15)
    i_slip = np.searchsorted(t, 0.1 + 0.02 + 0.3)
    assert fxy[i_slip] == pytest.approx(f[i_slip, 2], rel=1e-12)
    # the direction changes only during the slip event, and by slip_turn_deg
    loaded = fxy > 1e-3
    ang = np.unwrap(np.arctan2(f[loaded, 1], f[loaded, 0]))
    moving = np.abs(np.diff(ang)) > 1e-9
    tl = t[loaded]
    duration = tl[1:][moving][-1] - tl[:-1][moving][0]
    assert duration == pytest.approx(0.26, abs=0.002)
    assert np.degrees(ang[0]) == pytest.approx(30.0)
    assert np.degrees(ang[-1] - ang[0]) == pytest.approx(180.0, abs=1e-9)
    # after the slip the tangential force sits at the kinetic level, reversed
    after = (t > 0.1 + 0.02 + 0.3 + 0.26) & (t < 0.1 + 0.02 + 0.3 + 0.26 + 0.3)
    np.testing.assert_allclose(fxy[after], 0.6 * 0.22, rtol=1e-12)


def test_trials_repeat_every_period():
    t, f = force(3.0, scenario="touch", onset_s=0.1, hold_s=0.3, period_s=1.0, repeat=3)
    one = f[(t >= 0.0) & (t < 1.0)]
    np.testing.assert_allclose(f[(t >= 1.0) & (t < 2.0)], one, atol=1e-15)
    np.testing.assert_allclose(f[(t >= 2.0) & (t < 3.0)], one, atol=1e-15)
    t2, f2 = force(3.0, scenario="touch", onset_s=0.1, hold_s=0.3, period_s=1.0, repeat=2)
    assert np.all(f2[t2 >= 2.0] == [0.0, 0.0, 0.12])


def test_config_rules():
    with pytest.raises(ConfigError, match="shear_release_s"):
        AunpSensor(shear_release_s=0.05, unload_s=0.03)
    with pytest.raises(ConfigError, match="period_s"):
        AunpSensor(scenario="touch", hold_s=1.0, period_s=0.5, repeat=0)
    with pytest.raises(ConfigError, match="shear_ratio"):
        AunpSensor(shear_ratio=1.5, friction_mu=1.0)
    AunpSensor(hold_s=1.0, period_s=0.5, repeat=1)  # one trial: the period does not matter


def test_gauges_invert_eq2_exactly_without_noise():
    out = run_source(AunpSensor(scenario="slip", **QUIET), 1.5, tick_s=0.1)
    a = np.array(reduced_matrix(*SENSITIVITY_PER_N))
    r = out["r"].data
    rebuilt = np.stack(
        [a[i, 0] * r[:, 0] + a[i, 1] * r[:, 1] + a[i, 2] * r[:, 2] + a[i, 3] * r[:, 3] for i in range(3)], 1
    )
    np.testing.assert_allclose(rebuilt, out["force"].data, rtol=0, atol=1e-14)
    assert np.all(out["ref"].data == 0.0)


@pytest.mark.parametrize("scenario", ["touch", "slip"])
def test_gauge_force_recovers_the_true_force_within_noise(scenario):
    sd = 2e-5
    out = run_source(AunpSensor(scenario=scenario, noise_sd=sd, temp_drift_c=1.0), 1.5, tick_s=0.1, seed=5)
    f = run_offline(GaugeForce(mode="reduced"), r=out["r"].data, ref=out["ref"].data)["f"].data
    err = f - out["force"].data
    xs, ys, zs = SENSITIVITY_PER_N
    # predicted noise after eq. 2 with the reference subtracted from every gauge
    expected = np.array([np.sqrt(2) * sd / xs, np.sqrt(2) * sd / ys, np.sqrt(4 + 16) * sd / zs])
    rms = np.sqrt((err**2).mean(0))
    np.testing.assert_allclose(rms, expected, rtol=0.1)
    assert np.abs(err.mean(0)).max() < 4 * expected.max() / np.sqrt(len(err))


def test_reference_gauge_compensates_temperature_drift():
    p = dict(scenario="touch", noise_sd=1e-6, temp_drift_c=2.0, temp_period_s=3.0, temp_coeff_per_c=-1e-3)
    out = run_source(AunpSensor(**p), 1.5, tick_s=0.1, seed=1)
    raw = run_offline(GaugeForce(), r=out["r"].data)["f"].data - out["force"].data
    comp = run_offline(GaugeForce(), r=out["r"].data, ref=out["ref"].data)["f"].data - out["force"].data
    # uncompensated: the drift shows on Fz (4·α·ΔT/Zs), not on the differences Fx, Fy
    dtemp = out["temp_c"].data - 25.0
    np.testing.assert_allclose(raw[:, 2], 4 * -1e-3 * dtemp / SENSITIVITY_PER_N[2], atol=1e-3)
    assert np.abs(raw[:, 2]).max() > 0.05
    assert np.abs(comp).max() < 1e-3
    assert np.ptp(dtemp) > 1.0 and np.abs(dtemp).max() <= 2.0


def test_temperature_output_and_drift_off():
    out = run_source(AunpSensor(temp_drift_c=0.0, ambient_c=31.0), 0.3)
    assert np.all(out["temp_c"].data == 31.0)
    assert out["temp_c"].data.shape == (300,)


def test_seed_changes_noise_not_the_truth():
    a = run_source(AunpSensor(), 0.6, seed=1)
    b = run_source(AunpSensor(), 0.6, seed=1)
    c = run_source(AunpSensor(), 0.6, seed=2)
    assert_same(a, b, "same seed")
    assert np.array_equal(a["force"].data, c["force"].data)
    assert not np.array_equal(a["r"].data, c["r"].data)


def test_streams_do_not_depend_on_what_is_demanded():
    full = run_source(AunpSensor(scenario="slip"), 1.0, seed=4)
    for demanded in ({"ref"}, {"r"}, {"force"}, {"temp_c", "ref"}):
        block = AunpSensor(scenario="slip")
        block.bind({}, seed=4, demanded=frozenset(demanded))
        chunks = [block(now) for now in np.arange(1, 11) * 0.1]
        for port in demanded:
            got = np.concatenate([c[port].data for c in chunks])
            assert np.array_equal(got, full[port].data), (demanded, port)
        assert all(set(c) == demanded for c in chunks)


@pytest.mark.parametrize("scenario", ["touch", "slip", "rest"])
def test_chunking_invariance_with_irregular_ticks(scenario):
    p = dict(scenario=scenario, onset_s=0.05, hold_s=0.2, drag_s=0.1, period_s=0.9, repeat=0)
    whole = run_source(AunpSensor(**p), 2.0, seed=9, tick_s=2.0)
    ticks = [0.0004, 0.0137, 0.001, 0.25, 0.0, 0.0031]
    assert_same(run_source(AunpSensor(**p), 2.0, seed=9, tick_s=ticks, empty_between=True), whole, scenario)


def test_specs_and_labels():
    block = AunpSensor(rate_hz=500.0)
    specs = block.bind({})
    assert specs["force"].units == "N" and specs["force"].labels == ("Fx", "Fy", "Fz")
    assert specs["r"].shape == (4,) and specs["r"].units == "1"
    assert specs["temp_c"].units == "degC" and specs["ref"].shape == ()
    assert all(s.rate_hz == 500.0 and not s.events for s in specs.values())
    assert len(block(0.1)["r"]) == 50


def _numpy_samples(block, n):
    """The samples of a freshly bound sensor from its profile's formulas as elementwise numpy
    expressions: the oracle of the compiled pass (the same operations, in the same order)."""
    c = block.config

    def rc(x):
        return 0.5 - 0.5 * np.cos(np.pi * np.clip(x, 0.0, 1.0))

    t = np.arange(n) / c.rate_hz
    f = np.zeros((n, 3))
    f[:, 2] = c.baseline_n
    if c.scenario != "rest":
        k = np.clip(np.floor((t - c.onset_s) / c.period_s), 0.0, (c.repeat - 1) if c.repeat else np.inf)
        u = t - c.onset_s - k * c.period_s
        d_fz = c.stiffness_n_per_mm * c.indentation_um * 1e-3
        if c.scenario == "touch":
            u_off = c.ramp_s + c.hold_s
            v = u - u_off
            q_off = rc(np.array(u_off / c.shear_rise_s))
            fz = c.baseline_n + d_fz * (rc(u / c.ramp_s) - rc(v / c.unload_s))
            shear = np.where(u < u_off, rc(u / c.shear_rise_s), q_off * (1.0 - rc(v / c.shear_release_s)))
            m = c.shear_ratio * d_fz * shear
            theta = np.radians(c.shear_angle_deg)
            f[:, 0], f[:, 1] = m * np.cos(theta), m * np.sin(theta)
        else:
            u2 = c.ramp_s + c.drag_s
            u3 = u2 + c.slip_s
            rc1 = rc((u - (u3 + c.hold_s)) / c.unload_s)
            rc3 = rc((u - u2) / c.slip_s)
            fz = c.baseline_n + d_fz * (rc(u / c.ramp_s) - rc1)
            top = c.baseline_n + d_fz
            mu_s, mu_k = c.friction_mu, c.friction_mu * c.kinetic_ratio
            m = np.where(
                u < u2,
                mu_s * top * rc((u - c.ramp_s) / c.drag_s),
                np.where(u < u3, top * (mu_s - (mu_s - mu_k) * rc3), mu_k * top * (1.0 - rc1)),
            )
            phi = np.radians(c.shear_angle_deg) + np.radians(c.slip_turn_deg) * rc3
            f[:, 0], f[:, 1] = m * np.cos(phi), m * np.sin(phi)
        f[:, 2] = fz
    dtemp = c.temp_drift_c * np.sin((2.0 * np.pi / c.temp_period_s) * t + block.temp_phase)
    drift = c.temp_coeff_per_c * dtemp
    xs, ys, zs = c.sensitivity_per_n
    shear = f[:, [0, 1, 0, 1]] * np.array([-(xs / 2.0), ys / 2.0, xs / 2.0, -(ys / 2.0)])
    noise = block.noise_rng.standard_normal((n, 5)) * c.noise_sd  # the block's own stream, from its start
    return {
        "force": f,
        "r": (f[:, 2] * (zs / 4.0))[:, None] + shear + drift[:, None] + noise[:, :4],
        "ref": drift + noise[:, 4],
        "temp_c": c.ambient_c + dtemp,
    }


@pytest.mark.parametrize(
    "params",
    [
        {"scenario": "touch", "shear_angle_deg": 30.0, "repeat": 0, "period_s": 0.7},
        {
            "scenario": "slip",
            "drag_s": 0.1,
            "repeat": 2,
            "period_s": 1.0,
            "sensitivity_per_n": (0.021, 0.018, 0.043),
        },
        {"scenario": "rest", "temp_drift_c": 0.0},
    ],
)
def test_compiled_samples_are_the_profile_formulas(params):
    """To a few ulp of each stream's scale. On this machine they agree bit for bit (numba's cos is
    libm's, as numpy's is here: scripts/graph_digests.py showed every recording unchanged); a
    numpy or numba build with other sin/cos may differ in the last bits."""
    n = 2500
    oracle = AunpSensor(**params)
    oracle.bind({}, seed=3)
    want = _numpy_samples(oracle, n)
    got = run_source(AunpSensor(**params), n / 1000.0, seed=3, tick_s=0.1)
    for port, data in want.items():
        atol = 8 * np.finfo(np.float64).eps * np.abs(data).max()
        np.testing.assert_allclose(got[port].data, data, rtol=0, atol=atol, err_msg=port)
