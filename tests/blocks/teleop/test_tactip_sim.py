"""The emulated TacTips: determinism, tick invariance, pins, SSIM against force, scenarios, input drive."""

import numpy as np
import pytest

from flowtact import ConfigError
from flowtact.blocks.teleop.hand import FINGERS
from flowtact.blocks.teleop.tactip_sim import (
    HEIGHT,
    PX_PER_MM,
    WIDTH,
    TactipSim,
    TactipSimConfig,
    _units,
    pins_px,
    render,
    render_reference,
    scenario_contacts,
)
from flowtact.chunk import Chunk, StreamSpec
from flowtact.errors import BadDataError, SpecError
from flowtact.testing import assert_same, run_source

cv2 = pytest.importorskip("cv2")
skm = pytest.importorskip("skimage.metrics")

CROP = (slice(75, 165), slice(40, 280))  # the paper's 90×240 crop, centred


def ssim(a, b):
    return skm.structural_similarity(a, b, win_size=7, gaussian_weights=False, data_range=255)


def frames_at(forces, pos=(0.0, 0.0), seed=1, first_index=10, **params):
    forces = np.asarray(forces, float)
    n = len(forces)
    f = np.repeat(forces[:, None], 3, axis=1)
    p = np.tile(np.asarray(pos, float), (n, 3, 1))
    return render(f, p, first_index + np.arange(n), seed, params)


# -- determinism and chunking ------------------------------------------------------------------


@pytest.mark.parametrize("scenario", ["taps", "grasp"])
def test_any_tick_pattern_gives_identical_frames(scenario):
    def run(tick, empty=False):
        b = TactipSim(scenario=scenario, onset_s=0.1, tap_period_s=0.3, tap_s=0.25, grasp_period_s=1.6,
                      soft_rise_s=0.4, hold_s=0.3)  # fmt: skip
        return run_source(b, 1.2, tick_s=tick, seed=4, empty_between=empty)

    whole = run(1.2)
    assert len(whole["frames"]) == 48 and whole["force"].data.max() > 0.4
    for tick in (0.025, [0.013, 0.1, 0.0071, 0.25], 0.3):
        assert_same(run(tick), whole, f"tick={tick}")
    assert_same(run(0.05, empty=True), whole, "empty ticks")


def test_seed_changes_noise_not_the_sensors():
    a = run_source(TactipSim(scenario="rest"), 0.1, seed=1)["frames"].data.astype(float)
    b = run_source(TactipSim(scenario="rest"), 0.1, seed=2)["frames"].data.astype(float)
    d = a - b
    assert np.abs(d).max() > 0  # other noise
    assert abs(d.mean()) < 0.05 and 3.5 < d.std() < 5.0  # same scene: the difference is noise (√2·3 DN)


def test_frame_content_depends_only_on_seed_and_index():
    f = np.array([[0.0, 1.0, 3.0], [2.0, 0.5, 4.5]])
    p = np.zeros((2, 3, 2))
    both = render(f, p, [5, 9], seed=7)
    one = render(f[1:], p[1:], [9], seed=7)
    assert np.array_equal(both[1], one[0])
    assert not np.array_equal(render(f[1:], p[1:], [8], seed=7), one)


def test_numba_kernel_matches_numpy_twin():
    f = np.array([[0.0, 2.0, 5.0]])
    p = np.array([[[0.0, 0.0], [3.0, 1.0], [-8.0, -2.0]]])
    shear = np.array([[[0.0, 0.0], [0.4, -0.2], [1.0, 0.5]]])
    a = render(f, p, [3], 11, shear=shear, size=[[1.0, 1.3, 0.8]])
    b = render(f, p, [3], 11, shear=shear, size=[[1.0, 1.3, 0.8]], engine="numpy")
    diff = np.abs(a.astype(int) - b.astype(int))
    assert diff.max() <= 1 and (diff > 0).mean() < 1e-4  # exp/sqrt may differ by an ulp at a .5 rounding


def test_noise_level_and_independence():
    clean = frames_at([0.0], noise_dn=0.0)[0].astype(float)
    noisy = frames_at([0.0, 0.0], noise_dn=3.0)
    n1, n2 = noisy[0] - clean, noisy[1] - clean
    flat = (clean > 10) & (clean < 200)  # away from clipping
    assert abs(n1[flat].mean()) < 0.05
    assert n1[flat].std() == pytest.approx(3.0, rel=0.04)  # rounding adds 1/12 DN²
    # frames share only the rounding of the clean image (1/12 DN² of 9: a correlation of ≈ 0.009)
    assert abs(np.corrcoef(n1[flat], n2[flat])[0, 1]) < 0.02
    # and neighbouring pixels are independent
    assert abs(np.corrcoef(n1[:, :, 1:][flat[:, :, 1:]], n1[:, :, :-1][flat[:, :, 1:]])[0, 1]) < 0.02


# -- the image ---------------------------------------------------------------------------------


def blob_detector(**kw):
    p = cv2.SimpleBlobDetector_Params()
    p.filterByColor, p.blobColor = True, 255
    for k, v in kw.items():
        setattr(p, k, v)
    return cv2.SimpleBlobDetector_create(p)


def test_rest_frame_shows_30_bright_pins_where_the_model_puts_them():
    ref = render_reference(seed=3)
    xy, radius, _ = pins_px(np.zeros((1, 3)), np.zeros((1, 3, 2)))
    det = blob_detector(minThreshold=30, maxThreshold=250, minArea=10, maxArea=2000,
                        minCircularity=0.1, minInertiaRatio=0.1, minConvexity=0.1)  # fmt: skip
    for s in range(3):
        kp = det.detect(ref[s])
        assert len(kp) == 30, FINGERS[s]
        found = np.array([k.pt for k in kp])
        dist = np.linalg.norm(found[:, None, :] - xy[0, s][None], axis=2)
        assert dist.min(axis=1).max() < 0.5 and len(set(dist.argmin(axis=1))) == 30
        # every pin inside the paper's 90×240 crop, with its whole tip
        assert xy[0, s, :, 0].min() - radius.max() > 40 and xy[0, s, :, 0].max() + radius.max() < 280
        assert xy[0, s, :, 1].min() - radius.max() > 75 and xy[0, s, :, 1].max() + radius.max() < 165
        # pins are bright on a dark membrane
        assert np.median(ref[s][CROP]) < 45 and np.percentile(ref[s][CROP], 99.5) > 120


# White 2023 Table 3.1: per-sensor blob parameters, in our sensor order (thumb, index, middle)
TABLE_3_1 = {
    "thumb": (25.8, 161.2, 33.4, 156.9, 0.453, 0.553, 0.382),
    "index": (20.3, 176.3, 23.2, 131.2, 0.495, 0.453, 0.71),
    "middle": (48.1, 235.4, 42.0, 109.8, 0.475, 0.537, 0.658),
}


@pytest.mark.parametrize("force_n", [0.0, 2.5, 5.0])
def test_paper_blob_parameters_find_all_30_pins(force_n):
    frame = frames_at([force_n], pos=(1.0, 0.5))[0]
    for s, name in enumerate(FINGERS):
        lo, hi, amin, amax, circ, inertia, convex = TABLE_3_1[name]
        det = blob_detector(minThreshold=lo, maxThreshold=hi, filterByArea=True, minArea=amin, maxArea=amax,
                            filterByCircularity=True, minCircularity=circ, filterByInertia=True,
                            minInertiaRatio=inertia, filterByConvexity=True, minConvexity=convex)  # fmt: skip
        assert len(det.detect(frame[s])) == 30, name


def test_sensors_are_not_identical():
    xy, _, bright = pins_px(np.zeros((1, 3)), np.zeros((1, 3, 2)))
    for a, b in ((0, 1), (0, 2), (1, 2)):
        assert np.abs(xy[0, a] - xy[0, b]).max() > 0.5
        assert np.abs(bright[0, a] - bright[0, b]).max() > 3.0
    ref = render_reference(seed=3, params={"noise_dn": 0.0}).astype(float)
    assert np.abs(ref[0] - ref[1]).mean() > 1.0 and np.abs(ref[1] - ref[2]).mean() > 1.0


def test_vignetting_darkens_the_edges():
    ref = render_reference(seed=3, params={"noise_dn": 0.0}).astype(float)
    for s in range(3):
        centre = ref[s, 100:140, 150:170].min()  # skin between pin rows
        rim = ref[s, 110:130, 20:30].mean()
        assert rim < 0.75 * centre
    flat = render_reference(seed=3, params={"noise_dn": 0.0, "vignette": 0.0}).astype(float)
    assert flat[0, 110:130, 20:30].mean() > ref[0, 110:130, 20:30].mean()


def test_pins_move_away_from_the_contact_and_swell_under_it():
    xy0, r0, b0 = pins_px(np.zeros((1, 3)), np.zeros((1, 3, 2)))
    c = np.array([[[0.0, 0.0], [6.0, 1.0], [-6.0, -1.0]]])
    xy, r, b = pins_px(np.full((1, 3), 4.0), c)
    units = _units(TactipSimConfig().unit_seed, TactipSimConfig().vignette)
    for s in range(3):
        centre_px = units.rot[s] @ (c[0, s] * PX_PER_MM) + units.centre_px[s]
        out0 = np.linalg.norm(xy0[0, s] - centre_px, axis=1)
        out = np.linalg.norm(xy[0, s] - centre_px, axis=1)
        moved = np.linalg.norm(xy[0, s] - xy0[0, s], axis=1)
        assert np.all(out >= out0 - 0.05)  # radially outward (within the small rotation)
        assert moved.max() > 3.0 and moved.max() < 7.0  # px
        near = out0.argmin()
        assert r[0, s, near] > 1.08 * r0[0, s, near] and b[0, s, near] > 1.1 * b0[0, s, near]
        far = out0.argmax()
        assert moved[far] < 0.5 and r[0, s, far] == pytest.approx(r0[0, s, far], rel=1e-3)


@pytest.mark.parametrize("pos", [(0.0, 0.0), (5.0, 1.5), (-9.0, -3.0)])
def test_ssim_falls_steadily_with_force(pos):
    forces = [0.0, 0.5, 1.0, 2.0, 3.0, 4.0, 5.0]
    ref = render_reference(seed=2)
    fr = frames_at(forces, pos=pos, seed=2)
    for s in range(3):
        crop = [ssim(ref[s][CROP], f[s][CROP]) for f in fr]
        full = [ssim(ref[s], f[s]) for f in fr]
        assert np.all(np.diff(crop) < 0) and np.all(np.diff(full) < 0), (pos, s, crop, full)
        assert 0.78 < crop[0] < 0.9  # noise alone (the paper's rest SSIM ≈ 0.83–0.85)
        assert crop[-1] < (0.7 if pos[0] != -9.0 else 0.75) and crop[-1] > 0.5
        assert crop[1] < crop[0] - 0.002  # a light touch registers


def test_ssim_alone_leaves_a_position_error():
    """Same force, different contact: SSIM differs, so a linear SSIM→force fit has a residual."""
    ref = render_reference(seed=2)
    values = [
        ssim(ref[1][CROP], frames_at([3.0], pos=p, seed=2)[0, 1][CROP]) for p in ((0, 0), (10, 3), (-12, 0))
    ]
    assert max(values) - min(values) > 0.03


# -- scenarios -----------------------------------------------------------------------------------


def test_force_output_is_the_scenario_truth_and_frames_show_it():
    b = TactipSim(scenario="taps")
    out = run_source(b, 1.5, tick_s=0.2, seed=9)
    t = out["force"].t
    assert np.array_equal(t, np.arange(60) / 40.0)
    truth = scenario_contacts(b.config, b.seed_scenario, t)
    assert np.array_equal(out["force"].data, truth.force)
    assert np.array_equal(out["contact"].data, truth.position)
    again = render(truth.force, truth.position, np.arange(60), b.seed_frames, b.config,
                   shear=truth.shear, size=truth.size)  # fmt: skip
    assert np.array_equal(out["frames"].data, again)
    assert out["force"].end == 1.5 and out["frames"].end == 1.5


def test_taps_rise_through_the_force_range_at_each_position():
    c = TactipSimConfig.build({"levels": 10, "force_min_n": 0.5, "force_max_n": 5.0, "level_jitter": 0.0})
    t = np.arange(0, 40.0, 1 / 40)
    truth = scenario_contacts(c, 5, t)
    assert truth.force.min() == 0.0 and truth.force.max() == pytest.approx(5.0)
    for s in range(3):
        peaks = [truth.force[(t >= 0.25 + k) & (t < 1.25 + k), s].max() for k in range(20)]
        np.testing.assert_allclose(peaks[:10], np.linspace(0.5, 5.0, 10), atol=1e-12)
        np.testing.assert_allclose(peaks[10:], np.linspace(0.5, 5.0, 10), atol=1e-12)
        # the position holds for 10 taps (up to the per-tap jitter), then moves
        pos = truth.position[:, s]
        first, second = pos[(t > 0.25) & (t < 10.25)], pos[(t > 10.25) & (t < 20.25)]
        assert np.ptp(first, axis=0).max() <= 0.6 + 1e-12
        assert np.abs(first.mean(0) - second.mean(0)).max() > 0.3
    # each sensor its own positions
    assert np.abs(truth.position[:, 0] - truth.position[:, 1]).max() > 1.0
    assert np.abs(truth.position).max(axis=(0, 1)) == pytest.approx([9.3, 3.3], abs=1.0)


def test_grasp_alternates_a_slow_soft_and_a_fast_firm_object():
    c = TactipSimConfig.build({"scenario": "grasp", "onset_s": 0.5})
    t = np.arange(0, 8.5, 1 / 40)
    f = scenario_contacts(c, 3, t).force[:, 0]  # thumb
    soft, firm = (t >= 0.5) & (t < 4.5), t >= 4.5

    def rise_s(mask):
        x, tt = f[mask], t[mask]
        top = x.max()
        return tt[np.argmax(x >= 0.9 * top)] - tt[np.argmax(x >= 0.1 * top)]

    assert f[t < 0.5].max() == 0.0
    assert f[soft].max() == pytest.approx(2.5, rel=0.11) and f[firm].max() == pytest.approx(4.0, rel=0.11)
    assert rise_s(soft) > 4 * rise_s(firm)
    fingers = scenario_contacts(c, 3, t).force
    assert np.all(fingers[:, 1] <= fingers[:, 0]) and np.all(fingers[:, 2] <= fingers[:, 0])


def test_rest_has_no_contact():
    out = run_source(TactipSim(scenario="rest"), 0.5)
    assert np.all(out["force"].data == 0.0) and np.all(out["contact"].data == 0.0)


def test_only_force_demanded_skips_rendering():
    b = TactipSim(scenario="taps")
    b.bind({}, seed=1, demanded=frozenset({"force"}))
    out = b(2.0)
    assert set(out) == {"force"} and len(out["force"]) == 80


# -- input-driven (closed loop) --------------------------------------------------------------------


def drive(force, tick, rate=100.0, empty=False, duration=1.0, **params):
    b = TactipSim(**params)
    out = run_source(
        b, duration, tick_s=tick, inputs={"force": force}, rate_hz=rate, seed=5, empty_between=empty
    )
    return b, out


def input_force(n=100):
    t = np.arange(n) / 100.0
    return np.stack([np.clip(5 * t, 0, 3), 2.0 * (t > 0.3), np.where(t > 0.6, 4.5, 0.5)], axis=1)


def test_input_force_renders_the_latest_sample_and_echoes_it():
    f_in = input_force()
    b, out = drive(f_in, 0.1, contact_mm=[1.0, -0.5])
    t = out["force"].t
    assert np.array_equal(t, np.arange(40) / 40.0)
    # latest sample with time <= frame time: sample index floor(t·100)
    expect = f_in[np.floor(t * 100 + 1e-9).astype(int)]
    assert np.array_equal(out["force"].data, expect)
    pos = np.tile([1.0, -0.5], (40, 3, 1))
    assert np.array_equal(out["contact"].data, pos)
    assert np.array_equal(out["frames"].data, render(expect, pos, np.arange(40), b.seed_frames, b.config))
    ref = render_reference(b.seed_frames, b.config)
    s = [ssim(ref[0][CROP], f[0][CROP]) for f in out["frames"].data[[0, 8, 16]]]  # 0, 1, 2 N on the thumb
    assert s[0] > s[1] > s[2]


def test_input_drive_is_tick_invariant():
    f_in = input_force()
    _, whole = drive(f_in, 1.0)
    for tick in (0.01, [0.013, 0.1, 0.0071, 0.25], 0.07):
        assert_same(drive(f_in, tick)[1], whole, f"tick={tick}")
    assert_same(drive(f_in, 0.05, empty=True)[1], whole, "empty chunks")
    # a 40 Hz force stream stamped on the frame times gives the same frames as its 100 Hz origin
    slow = f_in[::5][: len(f_in) // 5]
    _, out = drive(slow, 0.1, rate=20.0)
    assert np.array_equal(out["force"].data, slow[np.arange(40) // 2])


def test_frames_wait_for_the_force_watermark():
    b = TactipSim()
    b.bind({"force": StreamSpec(shape=(3,), units="N", rate_hz=100.0)}, seed=0)
    f = np.ones((1, 3))
    out = b(0.2, force=Chunk(np.array([0.04]), f))  # no end: covered up to 0.04 s
    assert np.array_equal(out["frames"].t, [0.0, 0.025]) and out["frames"].end == 0.05
    out = b(0.2, force=Chunk(np.empty(0), np.empty((0, 3)), 0.05))  # nothing more before 0.05: not yet 0.05
    assert len(out["frames"]) == 0 and out["force"].end == 0.05
    out = b(0.2, force=Chunk(np.array([0.05]), 2 * f, 0.1))  # up to (not at) 0.1
    assert np.array_equal(out["force"].t, [0.05, 0.075]) and np.all(out["force"].data == 2.0)
    assert out["force"].end == 0.1
    out = b(0.3, force=Chunk(np.empty(0), np.empty((0, 3)), 0.3))
    assert np.array_equal(out["force"].t, [0.1, 0.125, 0.15, 0.175, 0.2, 0.225, 0.25, 0.275])
    assert out["force"].end == 0.3
    out = b.flush()
    assert all(len(c) == 0 for c in out.values())


def test_force_input_specs_are_checked():
    for bad in (StreamSpec(shape=(3,), units="mN"), StreamSpec(shape=(2,), units="N")):
        with pytest.raises(SpecError) as e:
            TactipSim().bind({"force": bad})
        assert e.value.port == "force"


def test_nonfinite_input_force():
    f_in = input_force(40)
    f_in[10, 1] = np.nan
    with pytest.raises(BadDataError, match="force"):
        drive(f_in, 0.1, duration=0.4)
    b, out = drive(f_in, 0.1, duration=0.4, on_bad_data="hold")
    assert np.isfinite(out["force"].data).all() and b.counters == {"nonfinite_hold": 1}


def test_config_rules():
    with pytest.raises(ConfigError, match="force_max_n"):
        TactipSim(force_min_n=3.0, force_max_n=2.0)
    with pytest.raises(ConfigError, match="tap_s"):
        TactipSim(tap_s=2.0, tap_period_s=1.0)
    with pytest.raises(ConfigError, match="grasp_period_s"):
        TactipSim(scenario="grasp", grasp_period_s=1.0)
    with pytest.raises(ConfigError, match="contact_mm"):
        TactipSim(contact_mm=[0.0, 0.0, 1.0])
    TactipSim(contact_mm=[0, 0, 1, 1, 2, 2])


def test_output_specs():
    specs = TactipSim(fps=30.0).bind({})
    assert specs["frames"] == StreamSpec(dtype="uint8", shape=(3, HEIGHT, WIDTH), units="DN", rate_hz=30.0)
    assert specs["force"].labels == FINGERS and specs["force"].units == "N"
    assert specs["contact"].shape == (3, 2) and specs["contact"].units == "mm"
