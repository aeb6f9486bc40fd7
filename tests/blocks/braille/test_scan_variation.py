"""braille_scan's varying fingertip: each variation's statistics, the recorded conditions against
what the taxels saw, seeding, chunking, bad parameters, and the graphs' calibrated setting."""

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy import signal, stats

from flowtact import ConfigError
from flowtact.blocks.braille.cells import dot_positions, text_cells
from flowtact.blocks.braille.scan import BrailleScan
from flowtact.blocks.braille.variation import CONDITION_LABELS, ROBOT
from flowtact.testing import run_source

GRAPHS = Path(__file__).resolve().parents[3] / "graphs"
C = {name: j for j, name in enumerate(CONDITION_LABELS)}
NONE = {k: (1.0 if k.startswith("dot_height") else 0) for k in ROBOT} | {
    "drift_tau_s": 2.0,
    "speed_jitter_tau_s": 0.1,
}


def scan(duration=3.0, tick_s=0.1, seed=0, **params):
    return run_source(BrailleScan(**params), duration, tick_s=tick_s, seed=seed)


def test_the_defaults_vary_nothing():
    """Every variation parameter defaults to none: existing graphs and tests keep their results."""
    cfg = BrailleScan(text="a").config
    assert {k: getattr(cfg, k) for k in NONE} == NONE


def test_no_variation_reads_the_nominal_fingertip_bit_for_bit():
    """Zero variation is the fingertip's nominal reading (no gain, press, spread, dot or lateral
    term leaks in): taxels equal ``reading(compression(x, y))`` of the nominal sensor exactly."""
    out = scan(4.0, text="abz k", noise=0.0, y_offset_mm=0.4)
    tip = BrailleScan(text="abz k").config.fingertip()
    dots = dot_positions(text_cells("abz k"), tip.geometry)
    x, y = out["position"].data, out["y"].data
    np.testing.assert_array_equal(out["taxels"].data, tip.reading(tip.compression(x, y, dots)))
    cond = out["conditions"].data
    np.testing.assert_array_equal(cond[:, C["lateral"]], y)
    assert np.all(cond[:, C["press"]] == tip.press_mm) and np.all(cond[:, C["gain_1"]] == 1.0)
    assert np.all(cond[:, C["spread"]] == tip.sigma_mm) and np.all(cond[:, C["yaw_deg"]] == 0.0)
    np.testing.assert_array_equal(out["speed"].data, 30.0)


def test_recorded_conditions_are_what_the_taxels_saw():
    """With every variation on (dots all scaled alike so the recorded cell scale is each dot's),
    the taxels are rebuilt exactly from position and the recorded lateral, press, spread and gain;
    the cover's relaxation is checked against scipy's lfilter of that rebuilt compression."""
    text = "the quick brown fox"
    params = ROBOT | {"dot_height_min": 1.2, "dot_height_max": 1.2, "noise": 0.0}
    out = scan(8.0, text=text, seed=4, **(params | {"cover_tau_s": 0.0}))
    tip = BrailleScan(text=text).config.fingertip()
    dots = dot_positions(text_cells(text), tip.geometry)
    x, cond = out["position"].data, out["conditions"].data
    squeeze = tip.compression(
        x,
        cond[:, C["lateral"]],
        dots,
        height_scale=np.full(len(dots), 1.2),
        sigma_mm=cond[:, C["spread"]],
        press_mm=cond[:, C["press"]],
    )
    np.testing.assert_array_equal(out["taxels"].data, tip.reading(squeeze) * cond[:, C["gain_1"], None])
    assert set(np.unique(cond[:, C["dot_scale_1"]])) == {0.0, 1.2}  # 1.2 on a cell with dots, 0 between
    # the same run with the cover relaxing: a first-order low-pass of the compression, started at rest
    relaxed = scan(8.0, text=text, seed=4, **params)
    np.testing.assert_array_equal(relaxed["conditions"].data, cond)  # relaxation changes no condition
    a = math.exp(-0.004 / ROBOT["cover_tau_s"])
    zi = a * squeeze[0]  # y_0 = a·y_{-1} + (1 − a)·u_0 = u_0 with y_{-1} = u_0
    low, _ = signal.lfilter([1 - a], [1, -a], squeeze, axis=0, zi=zi[None, :])
    # eps × (terms of a geometric sum ≤ 1/(1 − a) ≈ 8) × the largest reading's condition (< 2)
    np.testing.assert_allclose(
        relaxed["taxels"].data, tip.reading(low) * cond[:, C["gain_1"], None], rtol=1e-13
    )
    assert np.abs(relaxed["taxels"].data - out["taxels"].data).max() > 0.01  # and it does blur


def test_dot_heights_are_uniform_within_the_tolerance_and_not_all_equal():
    """Each dot's height factor is uniform on [dot_height_min, dot_height_max] (DIN 32976's 0.5-0.7 mm
    on the model's 0.5 mm nominal: 1.0-1.4). 'a' has one dot, so each cell's scale is one dot's:
    a Kolmogorov-Smirnov test against the uniform law, at a level that fails a wrong law."""
    out = scan(60.0, tick_s=1.0, text="a" * 150, speed_mm_s=30.0, dot_height_min=1.0, dot_height_max=1.4)
    cond, x = out["conditions"].data, out["position"].data
    cell = np.floor(x / (6.0 * 1.7)).astype(int)
    first = np.unique(cell[(cell >= 0) & (cell < 150)], return_index=True)[1]
    scales = cond[(cell >= 0) & (cell < 150), C["dot_scale_1"]][first]
    assert len(scales) == 150 and scales.min() >= 1.0 and scales.max() <= 1.4
    assert len(np.unique(scales)) == 150
    assert stats.kstest(scales, stats.uniform(1.0, 0.4).cdf).pvalue > 1e-3
    assert stats.kstest(scales, stats.uniform(1.0, 0.3).cdf).pvalue < 1e-3  # a narrower law is refused


@pytest.mark.parametrize(("param", "channel"), [("press_drift_mm", "press"), ("gain_drift", "gain_1")])
def test_drift_is_slow_and_of_the_stated_size(param, channel):
    """An OU drift of sd s and time constant τ over T = 200 τ (N = 10 000 samples): neighbouring
    samples correlate by e^(−dt/τ); samples 10 τ apart do not (|r| within 3 standard errors,
    Bartlett: var r ≈ (τ/dt)/N); the sd is s within 3 standard errors (N_eff ≈ T/2τ)."""
    tau, sd, dt, n = 0.2, 0.01, 0.004, 10_000
    out = scan(n * dt, tick_s=1.0, text="a" * 130, **{param: sd, "drift_tau_s": tau})
    v = out["conditions"].data[:, C[channel]]
    assert len(v) == n
    z = v - 0.1 if channel == "press" else np.log(v)
    z = z - z.mean()

    def corr(lag):
        return float(np.corrcoef(z[:-lag], z[lag:])[0, 1])

    assert abs(corr(1) - math.exp(-dt / tau)) < 3 * math.sqrt(2 * dt / tau / n) + 1e-3
    assert abs(corr(round(10 * tau / dt))) < 3 * math.sqrt(tau / dt / n)
    n_eff = n * dt / (2 * tau)
    assert abs(z.std() / sd - 1) < 3 / math.sqrt(2 * n_eff)


def test_speed_jitters_around_the_command_and_position_is_the_true_one():
    """The actual speed is the command times (1 + an OU jitter of sd speed_jitter); ``position``
    integrates the actual speed (the robot's encoders measure where the finger is)."""
    out = scan(20.0, tick_s=0.5, text="ab" * 50, speed_mm_s=30.0, speed_jitter=0.05, speed_jitter_tau_s=0.1)
    v, x = out["speed"].data, out["position"].data
    np.testing.assert_allclose(np.diff(x) / 0.004, v[1:], rtol=1e-9)  # x_i = x_{i−1} + v_i·dt
    r = v / 30.0 - 1.0
    n_eff = len(r) * 0.004 / (2 * 0.1)
    assert abs(r.std() / 0.05 - 1) < 3 / math.sqrt(2 * n_eff) and abs(r.mean()) < 3 * 0.05 / math.sqrt(n_eff)
    assert float(np.corrcoef(r[:-1], r[1:])[0, 1]) > math.exp(-0.004 / 0.1) - 0.01
    assert r.min() >= -0.2 - 1e-12 and r.max() <= 0.2 + 1e-12  # clipped at 4 sd


def test_yaw_moves_the_lateral_position_linearly_with_x_within_each_trial():
    """Trials of 2 cells: within each, lateral = y − (offset + (x − trial start)·tan yaw), a straight
    line in x whose slope is −tan of the recorded yaw; each trial has its own."""
    pitch = 6.0 * 1.7
    out = scan(8.0, text="abcdefgh", trial_cells=2, yaw_sd_deg=2.0, lateral_sd_mm=0.5, y_offset_mm=0.3)
    x, cond = out["position"].data, out["conditions"].data
    k = np.clip(np.floor(x / pitch).astype(int) // 2, 0, 3)
    slopes = []
    for trial in range(4):
        m = k == trial
        yaw = np.unique(cond[m, C["yaw_deg"]])
        assert len(yaw) == 1
        slope, icpt = np.polyfit(x[m] - trial * 2 * pitch, cond[m, C["lateral"]], 1)
        assert slope == pytest.approx(-math.tan(math.radians(yaw[0])), abs=1e-12)
        resid = cond[m, C["lateral"]] - (icpt + slope * (x[m] - trial * 2 * pitch))
        assert np.abs(resid).max() < 1e-12  # linear: x up to 80 mm, lateral ~1 mm, eps-level residual
        slopes.append(slope)
    assert len(set(slopes)) == 4 and max(abs(s) for s in slopes) > 1e-3


def test_per_trial_draws_change_at_trial_boundaries_only():
    out = scan(6.0, text="abcdef", trial_cells=1, press_sd_mm=0.03, gain_sd=0.1, lateral_sd_mm=0.5)
    x, cond = out["position"].data, out["conditions"].data
    cell = np.clip(np.floor(x / (6.0 * 1.7)).astype(int), 0, 5)
    for ch in ("press", "gain_1"):
        per_cell = [np.unique(cond[cell == k, C[ch]]) for k in range(6) if (cell == k).any()]
        assert all(len(u) == 1 for u in per_cell) and len({float(u[0]) for u in per_cell}) == len(per_cell)


def test_cover_wear_grows_the_spread_with_the_distance_slid():
    out = scan(10.0, text="abcdefghijklmn", wear_per_m=0.5)
    x, spread = out["position"].data, out["conditions"].data[:, C["spread"]]
    np.testing.assert_allclose(spread, 0.6 * (1 + 0.5e-3 * (x - x[0])), rtol=1e-14)


def test_same_seed_same_recording_another_seed_another():
    a, b, c = (scan(3.0, seed=s, text="abc", **ROBOT) for s in (7, 7, 8))
    for port in ("taxels", "conditions", "speed", "position"):
        np.testing.assert_array_equal(a[port].data, b[port].data)
    assert not np.array_equal(a["conditions"].data, c["conditions"].data)
    assert not np.array_equal(a["taxels"].data, c["taxels"].data)


def test_variation_leaves_the_text_and_the_motion_draws_alone():
    """Variation draws from its own streams: the random text (``char``) and, without speed jitter,
    the motion are the same with and without it."""
    a = scan(3.0, seed=3, text="", random_letters=5)
    b = scan(3.0, seed=3, text="", random_letters=5, **(ROBOT | {"speed_jitter": 0.0}))
    for port in ("char", "position"):
        np.testing.assert_array_equal(a[port].data, b[port].data)
    assert len(np.unique(a["char"].data)) > 3


@pytest.mark.parametrize("tick_s", [0.004, 0.036, 0.5])
def test_varying_scan_is_chunking_invariant(tick_s):
    ref = scan(3.0, tick_s=1.0, seed=2, text="bat", **ROBOT)
    got = scan(3.0, tick_s=tick_s, seed=2, text="bat", **ROBOT)
    for port in ref:
        np.testing.assert_array_equal(got[port].data, ref[port].data)


@pytest.mark.parametrize(
    ("params", "field", "words"),
    [
        ({"dot_height_min": 1.2, "dot_height_max": 1.1}, "dot_height_max", "must be >= dot_height_min"),
        ({"press_sd_mm": 0.2}, "gap_mm", "highest press + highest dot"),
        ({"speed_jitter": 0.3}, "speed_jitter", "0.2"),
        ({"yaw_sd_deg": -1.0}, "yaw_sd_deg", "0"),
        ({"drift_tau_s": 0.0}, "drift_tau_s", "0"),
    ],
)
def test_bad_variation_parameters_are_refused_in_one_line(params, field, words):
    with pytest.raises(ConfigError) as e:
        BrailleScan(text="a", **params)
    msg = str(e.value)
    assert e.value.field == field and words in msg and "braille_scan" in msg and "\n" not in msg


@pytest.mark.parametrize("graph", ["braille_open.yaml", "braille.yaml"])
def test_both_braille_graphs_turn_the_calibrated_variation_on(graph):
    params = yaml.safe_load((GRAPHS / graph).read_text())["nodes"]["scan"]["params"]
    assert {k: params.get(k) for k in ROBOT} == ROBOT


def test_turning_one_variation_off_leaves_the_others_draws_as_they_were():
    """Each variation draws from a fixed place in its stream: with the lateral offset off, press,
    gain and yaw are the same values (so an ablation compares like with like)."""
    a = scan(3.0, seed=5, text="abc", **ROBOT)["conditions"].data
    b = scan(3.0, seed=5, text="abc", **(ROBOT | {"lateral_sd_mm": 0.0}))["conditions"].data
    for ch in ("press", "gain_1", "yaw_deg", "spread", "dot_scale_1"):
        np.testing.assert_array_equal(a[:, C[ch]], b[:, C[ch]])
    assert not np.array_equal(a[:, C["lateral"]], b[:, C["lateral"]])
