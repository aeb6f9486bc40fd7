"""Tests of blocks/teleop/ssim.py: the SSIM kernels against scikit-image, reference capture and recapture."""

import doctest
import subprocess
import sys

import numpy as np
import pytest
from numpy.testing import assert_array_equal
from skimage.metrics import structural_similarity

import flowtact.blocks.teleop.ssim as ssim_module
from flowtact import BadDataError, Chunk, SpecError, StreamSpec, concat
from flowtact.blocks.teleop.hand import FINGERS
from flowtact.blocks.teleop.ssim import Ssim, SsimReference, ssim_exact_numpy, ssim_frames
from flowtact.blocks.teleop.tactip_sim import pressed_frames
from flowtact.testing import run_offline

RATE = 40.0
UNITS = {"x": "DN"}


def oracle(ref: np.ndarray, cur: np.ndarray) -> float:
    return structural_similarity(ref, cur, win_size=7, gaussian_weights=False, data_range=255)


def tactip_series(levels, crop: bool, seed: int = 0) -> tuple[np.ndarray, list[np.ndarray]]:
    """An unpressed reference and one frame per contact force (new noise each), one emulated TacTip."""
    images = pressed_frames([0.0, *levels], seed)[:, 0]
    if crop:
        images = images[:, 75:165, 40:280]
    return images[0], list(images[1:])


LEVELS = (0.0, 0.5, 1.0, 2.0, 3.5, 5.0)  # N


@pytest.fixture(scope="module")
def series():
    return {crop: tactip_series(LEVELS, crop) for crop in (False, True)}


# -- the metric ----------------------------------------------------------------------------------------


@pytest.mark.oracle
@pytest.mark.parametrize("crop", [False, True], ids=["240x320", "90x240"])
def test_tactip_frames_match_skimage(series, crop):
    ref, frames = series[crop]
    want = np.array([oracle(ref, f) for f in frames])
    assert want.max() - want.min() > 0.05  # the levels really deform the image
    assert np.all(np.diff(want[1:]) < 0)  # more press, less similar
    stack = np.stack(frames)[:, None]
    got64 = SsimReference(ref[None]).compare(stack)[:, 0]
    got32 = SsimReference(ref[None], "float32").compare(stack)[:, 0]
    assert np.max(np.abs(got64 - want)) <= 1e-10
    assert np.max(np.abs(got32 - want)) <= 1e-6
    twin = np.array([ssim_exact_numpy(ref, f) for f in frames])
    assert np.max(np.abs(twin - want)) <= 1e-10
    assert np.max(np.abs(twin - got64)) <= 1e-12


@pytest.mark.oracle
@pytest.mark.parametrize("shape", [(240, 320), (90, 240), (7, 7), (8, 31), (33, 9)])
def test_random_images_match_skimage(shape):
    rng = np.random.default_rng(sum(shape))
    a = rng.integers(0, 256, shape, dtype=np.uint8)
    b = rng.integers(0, 256, shape, dtype=np.uint8)
    want = oracle(a, b)
    assert abs(ssim_frames(a, b) - want) <= 1e-10
    assert abs(ssim_frames(a, b, "float32") - want) <= 1e-6
    assert abs(ssim_frames(b, a) - oracle(b, a)) <= 1e-10


@pytest.mark.oracle
def test_per_window_map_matches_skimage(series):
    ref, frames = series[True]
    _, full = structural_similarity(
        ref, frames[3], win_size=7, gaussian_weights=False, data_range=255, full=True
    )
    m = ssim_exact_numpy(ref, frames[3], full=True)
    assert m.shape == (90 - 6, 240 - 6)
    assert np.max(np.abs(m - full[3:-3, 3:-3])) <= 1e-10


@pytest.mark.oracle
def test_identical_and_constant_images():
    rng = np.random.default_rng(5)
    a = rng.integers(0, 256, (90, 240), dtype=np.uint8)
    assert ssim_frames(a, a) == 1.0  # exact: numerator and denominator are the same float operations
    assert abs(ssim_frames(a, a, "float32") - 1.0) <= 1e-6
    zero, white = np.zeros((20, 30), np.uint8), np.full((20, 30), 255, np.uint8)
    for x, y in ((zero, zero), (white, white), (zero, white), (np.full_like(zero, 77), a[:20, :30])):
        want = oracle(x, y)
        assert abs(ssim_frames(x, y) - want) <= 1e-12, (x[0, 0], y[0, 0])
    assert ssim_frames(zero, zero) == 1.0 and abs(ssim_frames(zero, white) - oracle(zero, white)) < 1e-12
    assert ssim_frames(zero, white) < 1e-3  # c1 keeps it finite, and tiny


def test_three_sensors_are_independent():
    rng = np.random.default_rng(2)
    ref = rng.integers(0, 256, (3, 30, 40), dtype=np.uint8)
    frames = rng.integers(0, 256, (4, 3, 30, 40), dtype=np.uint8)
    frames[1, 1] = ref[1]
    got = SsimReference(ref).compare(frames)
    for i in range(4):
        for s in range(3):
            assert abs(got[i, s] - oracle(ref[s], frames[i, s])) <= 1e-12
    assert got[1, 1] == 1.0


def test_reference_rejects_bad_shapes():
    with pytest.raises(ValueError, match="7"):
        SsimReference(np.zeros((3, 6, 40), np.uint8))
    with pytest.raises(ValueError, match="shape"):
        SsimReference(np.zeros((3, 10, 10), np.uint8)).compare(np.zeros((1, 2, 10, 10), np.uint8))


# -- the block -----------------------------------------------------------------------------------------


def _stack(frames: list[np.ndarray]) -> np.ndarray:
    """(k, 3, H, W): the same frame for all three sensors, made distinct by flipping."""
    return np.stack([np.stack([f, f[::-1], f[:, ::-1]]) for f in frames])


def test_block_reference_is_the_first_frame(series):
    ref, frames = series[True]
    x = _stack([ref, *frames])
    out = run_offline(Ssim(), x=x, rate_hz=RATE, units=UNITS, chunk=3)
    y = out["y"]
    assert y.data.shape == (len(frames) + 1, 3)
    assert_array_equal(y.t, np.arange(len(frames) + 1) / RATE)
    assert_array_equal(y.data[0], [1.0, 1.0, 1.0])
    for i, f in enumerate(frames, start=1):
        assert abs(y.data[i, 0] - oracle(ref, f)) <= 1e-10
        assert abs(y.data[i, 1] - oracle(ref[::-1], f[::-1])) <= 1e-10
        assert abs(y.data[i, 2] - oracle(ref[:, ::-1], f[:, ::-1])) <= 1e-10


def test_block_specs():
    spec = StreamSpec(dtype="uint8", shape=(3, 90, 240), units="DN", rate_hz=RATE)
    out = Ssim().bind({"x": spec})["y"]
    assert (out.dtype, out.shape, out.units, out.rate_hz, out.labels) == ("float64", (3,), "1", RATE, FINGERS)
    two = Ssim().bind({"x": spec.with_(shape=(2, 9, 9))})["y"]
    assert two.shape == (2,) and two.labels is None
    single = Ssim().bind({"x": spec.with_(shape=(9, 9))})["y"]
    assert single.shape == ()
    for bad, word in (
        (spec.with_(dtype="float64"), "uint8"),
        (spec.with_(units="1"), "DN"),
        (spec.with_(shape=(3, 6, 240)), "7"),
        (spec.with_(shape=(3, 90, 240, 1)), "shape"),
    ):
        with pytest.raises(SpecError, match=word):
            Ssim().bind({"x": bad})
    with pytest.raises(SpecError, match="recapture"):
        Ssim().bind({"x": spec, "recapture": StreamSpec(shape=(3,), units="1", rate_hz=RATE)})


def test_single_image_stream():
    rng = np.random.default_rng(8)
    x = rng.integers(0, 256, (3, 12, 14), dtype=np.uint8)
    y = run_offline(Ssim(), x=x, rate_hz=RATE, units=UNITS)["y"].data
    assert y.shape == (3,) and y[0] == 1.0
    assert abs(y[2] - oracle(x[0], x[2])) <= 1e-12


def test_float32_mode_close_to_float64(series):
    ref, frames = series[False]
    x = _stack([ref, *frames[:3]])
    y64 = run_offline(Ssim(), x=x, rate_hz=RATE, units=UNITS)["y"].data
    y32 = run_offline(Ssim(precision="float32"), x=x, rate_hz=RATE, units=UNITS)["y"].data
    assert np.max(np.abs(y64 - y32)) <= 1e-6
    assert not np.array_equal(y64[1:], y32[1:])  # the formula really ran in float32


def test_reference_is_the_rounded_mean_of_the_first_frames():
    rng = np.random.default_rng(3)
    x = rng.integers(0, 256, (6, 2, 16, 20), dtype=np.uint8)
    out = run_offline(Ssim(reference_frames=3), x=x, rate_hz=RATE, units=UNITS, chunk=[1, 2, 1, 2])
    y = out["y"]
    assert_array_equal(y.t, np.arange(6) / RATE)  # no frame lost, times kept
    total = x[:3].astype(np.int64).sum(0)
    ref = np.floor(total / 3 + 0.5).astype(np.uint8)  # rounded half up
    for i in range(6):
        for s in range(2):
            assert abs(y.data[i, s] - oracle(ref[s], x[i, s])) <= 1e-12


def test_stream_shorter_than_the_reference_uses_what_came():
    rng = np.random.default_rng(4)
    x = rng.integers(0, 256, (2, 1, 10, 10), dtype=np.uint8)
    block = Ssim(reference_frames=5)
    out = run_offline(block, x=x, rate_hz=RATE, units=UNITS, flush=False)
    assert len(out["y"]) == 0  # still collecting
    out = run_offline(block, x=x, rate_hz=RATE, units=UNITS)
    ref = ((x[0].astype(int) + x[1] + 1) // 2).astype(np.uint8)
    assert len(out["y"]) == 2
    assert abs(out["y"].data[1, 0] - oracle(ref[0], x[1, 0])) <= 1e-12
    assert block.counters == {"reference_short": 1}


def _frames(n: int, seed: int = 6) -> np.ndarray:
    rng = np.random.default_rng(seed)
    base = rng.integers(0, 200, (1, 3, 14, 18))
    drift = np.arange(n)[:, None, None, None] * 3
    return np.clip(base + drift + rng.integers(0, 20, (n, 3, 14, 18)), 0, 255).astype(np.uint8)


def expected_with_recaptures(x: np.ndarray, starts: list[int]) -> np.ndarray:
    """SSIM of each frame against the last frame index in ``starts`` not after it (reference_frames 1)."""
    out = np.empty(x.shape[:2])
    for i in range(len(x)):
        r = max(s for s in starts if s <= i)
        for s in range(x.shape[1]):
            out[i, s] = oracle(x[r, s], x[i, s])
    return out


def test_recapture_makes_the_next_frame_the_reference():
    x = _frames(8)
    rc = np.zeros(8)
    rc[3] = 1.0  # same time stamp as frame 3: frame 3 is the new reference
    rc[5] = 0.7
    out = run_offline(Ssim(), x=x, recapture=rc, rate_hz=RATE, units=UNITS)
    y = out["y"].data
    assert np.max(np.abs(y - expected_with_recaptures(x, [0, 3, 5]))) <= 1e-12
    assert y[3].tolist() == [1.0] * 3 and y[5].tolist() == [1.0] * 3
    assert Ssim().example().inputs["recapture"].max() > 0.5  # the conformance example recaptures


def test_recapture_between_frames_applies_to_the_first_later_frame():
    """A 100 Hz recapture stream against 40 Hz frames, fed in unrelated chunks with watermarks."""
    x = _frames(10)
    t_x = np.arange(10) / RATE  # 0, 25, 50, ... ms
    t_rc = np.arange(26) / 100.0  # 0, 10, 20, ... ms
    v_rc = np.zeros(26)
    v_rc[[6, 13]] = 1.0  # 60 ms -> frame at 75 ms (index 3); 130 ms -> frame at 150 ms (index 6)
    want = expected_with_recaptures(x, [0, 3, 6])

    def drive(x_cuts, rc_cuts, with_ends):
        block = Ssim()
        block.bind(
            {
                "x": StreamSpec(dtype="uint8", shape=(3, 14, 18), units="DN", rate_hz=RATE),
                "recapture": StreamSpec(shape=(), units="1", rate_hz=100.0),
            }
        )
        outs = []
        for (a, b), (c, d) in zip(x_cuts, rc_cuts, strict=True):
            end_rc = (t_rc[d] if d < 26 else 0.26) if with_ends else None
            outs.append(
                block(
                    x=Chunk(t_x[a:b], x[a:b], None),
                    recapture=Chunk(t_rc[c:d], v_rc[c:d], end_rc),
                )["y"]
            )
        outs.append(block.flush().get("y", Chunk(np.empty(0), np.empty((0, 3)))))
        return concat(outs)

    # frames arrive well before the recapture samples that concern them
    early = drive([(0, 6), (6, 10), (10, 10), (10, 10)], [(0, 2), (2, 7), (7, 14), (14, 26)], False)
    late = drive([(0, 1), (1, 2), (2, 5), (5, 10)], [(0, 20), (20, 21), (21, 26), (26, 26)], True)
    whole = drive([(0, 10)], [(0, 26)], False)
    for run in (early, late, whole):
        assert_array_equal(run.t, t_x)
        assert np.max(np.abs(run.data - want)) <= 1e-12
    assert_array_equal(early.data, whole.data)
    assert_array_equal(late.data, whole.data)


def test_frames_wait_for_the_recapture_watermark():
    x = _frames(4)
    block = Ssim()
    block.bind(
        {
            "x": StreamSpec(dtype="uint8", shape=(3, 14, 18), units="DN", rate_hz=RATE),
            "recapture": StreamSpec(shape=(), units="1", rate_hz=RATE),
        }
    )
    t = np.arange(4) / RATE
    empty_rc = Chunk(np.empty(0), np.empty(0), None)
    y = block(x=Chunk(t, x, 0.1), recapture=empty_rc)["y"]
    assert len(y) == 0 and y.end == 0.0  # held: nothing is known of the recapture stream yet
    y = block(x=Chunk(t[:0], x[:0], 0.1), recapture=Chunk(np.empty(0), np.empty(0), 0.05))["y"]
    assert_array_equal(y.t, t[:2])  # watermark 50 ms: frames at 0 and 25 ms are safe
    assert y.end == t[2]  # the output's watermark stops at the first held frame
    y = block(x=Chunk(t[:0], x[:0], 0.1), recapture=Chunk(np.array([0.05]), np.array([1.0]), 0.06))["y"]
    assert_array_equal(y.t, t[2:3])
    assert y.data[0].tolist() == [1.0, 1.0, 1.0]  # recaptured at 50 ms
    y = block.flush()["y"]
    assert_array_equal(y.t, t[3:])


def test_recapture_while_collecting_finishes_the_current_reference():
    x = _frames(6)
    rc = np.zeros(6)
    rc[1] = 1.0
    y = run_offline(Ssim(reference_frames=3), x=x, recapture=rc, rate_hz=RATE, units=UNITS)["y"].data
    assert y.shape == (6, 3)
    assert y[0].tolist() == [1.0] * 3  # a one-frame reference (the recapture came at frame 1)
    ref = ((x[1:4].astype(np.int64).sum(0) * 2 + 3) // 6).astype(np.uint8)
    for i in range(1, 6):
        assert abs(y[i, 0] - oracle(ref[0], x[i, 0])) <= 1e-12


def test_bad_recapture_samples():
    x = _frames(3)
    rc = np.array([0.0, np.nan, 0.0])
    with pytest.raises(BadDataError, match="recapture"):
        run_offline(Ssim(), x=x, recapture=rc, rate_hz=RATE, units=UNITS)
    block = Ssim(on_bad_data="drop")
    y = run_offline(block, x=x, recapture=rc, rate_hz=RATE, units=UNITS)["y"]
    assert len(y) == 3 and block.counters["nonfinite_drop"] == 1


def test_watermark_passes_through():
    x = _frames(3)
    block = Ssim()
    block.bind({"x": StreamSpec(dtype="uint8", shape=(3, 14, 18), units="DN", rate_hz=RATE)})
    y = block(x=Chunk(np.arange(3) / RATE, x, 0.075))["y"]
    assert y.end == 0.075 and len(y) == 3
    y = block(x=Chunk(np.empty(0), x[:0], 0.2))["y"]
    assert y.end == 0.2 and len(y) == 0


def test_imports_neither_opencv_nor_torch():
    code = (
        "import sys, flowtact.blocks.teleop.ssim, flowtact.blocks.teleop.force_linear; "
        "bad = [m for m in ('cv2', 'torch', 'skimage') if m in sys.modules]; assert not bad, bad"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_docstring_examples():
    assert doctest.testmod(ssim_module, raise_on_error=True).failed == 0
