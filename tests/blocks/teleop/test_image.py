"""Tests of blocks/teleop/image.py: crop, adaptive_threshold, blob_detect, blob_mask (White 2023, §3.1.1)."""

import doctest
import subprocess
import sys

import cv2
import numpy as np
import pytest
from numpy.testing import assert_array_equal

import flowtact.blocks.teleop.image as image_module
from flowtact import Chunk, ConfigError, SpecError, StreamSpec
from flowtact.blocks.teleop.hand import FINGERS
from flowtact.blocks.teleop.image import (
    TABLE_3_1,
    AdaptiveThreshold,
    BlobDetect,
    BlobDetectConfig,
    BlobMask,
    Crop,
    blob_mask_numpy,
)
from flowtact.blocks.teleop.tactip_sim import pins_px, pressed_frames
from flowtact.errors import MisalignedError
from flowtact.testing import run_offline

RATE = 40.0
UNITS = {"x": "DN", "pins": "px"}


def frames_spec(shape=(3, 240, 320)) -> StreamSpec:
    return StreamSpec(dtype="uint8", shape=shape, units="DN", rate_hz=RATE)


@pytest.fixture(scope="module")
def tactip():
    """Three emulated sensors' full and cropped frames (pressed with 0, 2 and 5 N), true pins."""
    force = np.array([[0.0, 2.0, 5.0]])
    full = pressed_frames(force)
    xy, _, _ = pins_px(force, np.zeros((1, 3, 2)))
    return full, full[:, :, 75:165, 40:280], list(xy[0] - [40, 75])  # pins in crop coordinates


# -- crop ------------------------------------------------------------------------------------------


def test_crop_default_is_the_centred_thesis_window(tactip):
    full, _, _ = tactip
    y = run_offline(Crop(), x=full, rate_hz=RATE, units=UNITS)["y"]
    assert y.data.shape == (1, 3, 90, 240) and y.data.dtype == np.uint8
    assert_array_equal(y.data, full[:, :, 75:165, 40:280])
    assert y.data.flags.c_contiguous


def test_crop_per_sensor_origins_and_spec():
    x = np.random.default_rng(0).integers(0, 256, (4, 3, 30, 40), dtype=np.uint8)
    block = Crop(x0_px=[0, 5, 10], y0_px=[2], width_px=20, height_px=8)
    y = run_offline(block, x=x, rate_hz=RATE, units=UNITS, chunk=3)["y"].data
    for s, x0 in enumerate((0, 5, 10)):
        assert_array_equal(y[:, s], x[:, s, 2:10, x0 : x0 + 20])
    spec = Crop(x0_px=[1], y0_px=[1], width_px=20, height_px=8).bind({"x": frames_spec((3, 30, 40))})["y"]
    assert (spec.shape, spec.dtype, spec.units, spec.rate_hz) == ((3, 8, 20), "uint8", "DN", RATE)


def test_crop_that_does_not_fit_is_a_spec_error():
    with pytest.raises(SpecError, match="does not fit"):
        Crop(x0_px=[40, 41, 90]).bind({"x": frames_spec()})  # 90 + 240 > 320
    with pytest.raises(SpecError, match="does not fit"):
        Crop().bind({"x": frames_spec((3, 90, 240))})  # default origins need a 320x240 frame
    with pytest.raises(SpecError, match="2 values"):
        Crop(x0_px=[0, 0]).bind({"x": frames_spec()})
    with pytest.raises(SpecError, match="uint8"):
        Crop().bind({"x": frames_spec().with_(dtype="float64")})
    with pytest.raises(SpecError, match="DN"):
        Crop().bind({"x": frames_spec().with_(units="1")})


def test_crop_passes_the_watermark_on():
    block = Crop(x0_px=[0], y0_px=[0], width_px=4, height_px=4)
    block.bind({"x": frames_spec((3, 8, 8))})
    x = np.zeros((2, 3, 8, 8), np.uint8)
    y = block(x=Chunk(np.array([0.0, 0.025]), x, 0.05))["y"]
    assert y.end == 0.05 and len(y) == 2


# -- adaptive_threshold --------------------------------------------------------------------------------


def test_threshold_equals_opencv(tactip):
    full, crop, _ = tactip
    for x in (full, crop):
        y = run_offline(AdaptiveThreshold(), x=x, rate_hz=RATE, units=UNITS)["y"].data
        for s in range(3):
            want = cv2.adaptiveThreshold(
                x[0, s], 255, cv2.ADAPTIVE_THRESH_GAUSSIAN_C, cv2.THRESH_BINARY, 31, -25
            )
            assert_array_equal(y[0, s], want)
    y = run_offline(AdaptiveThreshold(c_dn=-5.0, radius_px=3), x=crop, rate_hz=RATE, units=UNITS)["y"].data
    want = cv2.adaptiveThreshold(crop[0, 1], 255, cv2.ADAPTIVE_THRESH_GAUSSIAN_C, cv2.THRESH_BINARY, 7, -5)
    assert_array_equal(y[0, 1], want)


def test_threshold_keeps_pins_and_drops_skin(tactip):
    _, crop, true = tactip
    y = run_offline(AdaptiveThreshold(), x=crop, rate_hz=RATE, units=UNITS)["y"].data
    assert set(np.unique(y)) == {0, 255}
    for s in range(3):
        centres = np.rint(true[s]).astype(int)
        assert (y[0, s, centres[:, 1], centres[:, 0]] == 255).all()  # every pin centre is set
        assert (y[0, s] == 255).mean() < 0.15  # the dark skin is not
    assert AdaptiveThreshold.requires == {"cv2": "vision"}


# -- blob_detect ---------------------------------------------------------------------------------------


def test_table_3_1_is_reordered_to_thumb_index_middle():
    # Table 3.1 columns are Index, Middle, Thumb; flowtact's order is thumb, index, middle.
    printed = {  # index, middle, thumb, as printed
        "min_threshold": (20.3, 48.1, 25.8),
        "max_threshold": (176.3, 235.4, 161.2),
        "min_area": (23.2, 42.0, 33.4),
        "max_area": (131.2, 109.8, 156.9),
        "min_circularity": (0.495, 0.475, 0.453),
        "min_inertia": (0.453, 0.537, 0.553),
        "min_convexity": (0.71, 0.658, 0.382),
    }
    for key, (index, middle, thumb) in printed.items():
        assert TABLE_3_1[key] == (thumb, index, middle), key
    c = BlobDetectConfig()
    assert c.min_threshold_dn == TABLE_3_1["min_threshold"] and c.max_area_px2 == TABLE_3_1["max_area"]
    assert c.min_inertia_ratio == TABLE_3_1["min_inertia"] and c.min_convexity == TABLE_3_1["min_convexity"]
    assert FINGERS == ("thumb", "index", "middle")


def test_finds_all_30_pins_with_each_sensors_parameters(tactip):
    _, crop, true = tactip
    out = run_offline(BlobDetect(), x=crop, rate_hz=RATE, units=UNITS)
    assert out["count"].data.tolist() == [[30.0, 30.0, 30.0]]
    pins = out["pins"].data
    assert pins.shape == (1, 3, 30, 3) and not np.isnan(pins).any()
    for s in range(3):
        found = pins[0, s]
        assert_array_equal(np.lexsort((found[:, 0], found[:, 1])), np.arange(30))  # sorted by y, then x
        d = np.hypot(found[:, None, 0] - true[s][None, :, 0], found[:, None, 1] - true[s][None, :, 1])
        assert d.min(axis=1).max() < 0.5  # every blob within half a pixel of a true pin
        assert len(set(d.argmin(axis=1))) == 30  # and each pin found once
        assert ((found[:, 2] > 5) & (found[:, 2] < 14)).all()  # diameters of the ~10 px pin tips


def test_each_sensor_uses_its_own_column():
    """Square blobs whose contour areas fall between the sensors' Table 3.1 area limits."""
    img = np.full((90, 240), 20, np.uint8)
    # contour area of a k×k pixel square is (k−1)²: 25, 36 and 100 px²
    for row, (side, n) in enumerate(((6, 5), (7, 4), (11, 3))):
        for k in range(n):
            img[10 + 28 * row : 10 + 28 * row + side, 10 + 30 * k : 10 + 30 * k + side] = 200
    x = np.stack([img] * 3)[None]
    count = run_offline(BlobDetect(), x=x, rate_hz=RATE, units=UNITS)["count"].data[0]
    # area limits (min, max): thumb 33.4-156.9, index 23.2-131.2, middle 42.0-109.8
    assert count.tolist() == [4.0 + 3.0, 5.0 + 4.0 + 3.0, 3.0]


def test_fewer_pins_pad_with_nan_and_more_keep_the_largest():
    x = pressed_frames([0.0])[:, :, 75:165, 40:280].copy()
    x[:, :, :33] = np.median(x)  # skin over the top row of pins: 20 left
    out = run_offline(BlobDetect(), x=x, rate_hz=RATE, units=UNITS)
    assert out["count"].data.tolist() == [[20.0, 20.0, 20.0]]
    assert not np.isnan(out["pins"].data[0, :, :20]).any() and np.isnan(out["pins"].data[0, :, 20:]).all()
    block = BlobDetect(max_pins=8)
    small = run_offline(block, x=x, rate_hz=RATE, units=UNITS)
    assert small["pins"].data.shape == (1, 3, 8, 3)
    assert small["count"].data.tolist() == [[20.0, 20.0, 20.0]]  # the count is what was detected
    for s in range(3):
        kept, every = small["pins"].data[0, s], out["pins"].data[0, s, :20]
        assert kept[:, 2].min() >= np.sort(every[:, 2])[-8]  # the 8 largest
        assert_array_equal(np.lexsort((kept[:, 0], kept[:, 1])), np.arange(8))
    assert block.counters == {"pins_dropped": 36}


def test_blob_detect_config_and_specs():
    with pytest.raises(ConfigError, match=r"'min_area_px2'.*same length"):
        BlobDetect(min_area_px2=[1.0, 2.0])
    with pytest.raises(ConfigError, match="max_threshold_dn"):
        BlobDetect(min_threshold_dn=[50.0], max_threshold_dn=[40.0])
    one = BlobDetect(
        min_threshold_dn=[30.0],
        max_threshold_dn=[200.0],
        min_area_px2=[20.0],
        max_area_px2=[150.0],
        min_circularity=[0.5],
        min_inertia_ratio=[0.5],
        min_convexity=[0.5],
    )
    specs = one.bind({"x": frames_spec((2, 90, 240))})
    assert specs["pins"].shape == (2, 30, 3) and specs["pins"].units == "px"
    assert specs["count"].shape == (2,) and specs["count"].labels is None
    specs = BlobDetect().bind({"x": frames_spec((3, 90, 240))})
    assert specs["count"].labels == FINGERS
    with pytest.raises(SpecError, match="3 sensors"):
        BlobDetect().bind({"x": frames_spec((2, 90, 240))})


# -- blob_mask -----------------------------------------------------------------------------------------


def test_mask_keeps_pins_and_zeroes_skin(tactip):
    _, crop, true = tactip
    det = run_offline(BlobDetect(), x=crop, rate_hz=RATE, units=UNITS)
    y = run_offline(BlobMask(), x=crop, pins=det["pins"].data, rate_hz=RATE, units=UNITS)["y"].data
    assert y.shape == crop.shape and y.dtype == np.uint8
    for s in range(3):
        c = np.rint(true[s]).astype(int)
        assert_array_equal(y[0, s, c[:, 1], c[:, 0]], crop[0, s, c[:, 1], c[:, 0]])  # pin centres kept
        kept = y[0, s] > 0
        assert 0.03 < kept.mean() < 0.25  # only ~30 small discs survive
        assert_array_equal(y[0, s][kept], crop[0, s][kept])  # kept pixels unchanged
        assert crop[0, s][~kept].mean() < 40  # what is dropped is the dark skin
    assert_array_equal(y, blob_mask_numpy(crop, det["pins"].data))


def test_mask_kernel_equals_numpy_twin():
    rng = np.random.default_rng(9)
    frames = rng.integers(1, 256, (4, 2, 30, 50), dtype=np.uint8)
    pins = np.column_stack([rng.uniform(-5, 55, 40), rng.uniform(-5, 35, 40), rng.uniform(0.5, 15, 40)])
    pins = pins.reshape(4, 2, 5, 3)
    pins[0, 0, 1] = np.nan
    pins[1, 1, 2, 2] = -3.0  # negative diameter: no pin
    pins[2, 0, 0, 0] = np.inf
    for scale in (0.5, 1.0, 1.7):
        y = run_offline(BlobMask(scale=scale), x=frames, pins=pins, rate_hz=RATE, units=UNITS, chunk=3)["y"]
        assert_array_equal(y.data, blob_mask_numpy(frames, pins, scale))
    one = np.zeros((1, 1, 5, 3))
    one[0, 0, :, :] = np.nan
    one[0, 0, 0] = (10.0, 10.0, 4.0)
    y = run_offline(BlobMask(), x=frames[:1, :1], pins=one, rate_hz=RATE, units=UNITS)["y"].data
    assert (y > 0).sum() == 13  # the disc of radius 2 on the pixel grid


def test_mask_pairs_inputs_by_time():
    block = BlobMask()
    block.bind({"x": frames_spec((1, 9, 9)), "pins": StreamSpec(shape=(1, 2, 3), units="px", rate_hz=RATE)})
    frames = np.full((3, 1, 9, 9), 9, np.uint8)
    pins = np.tile([4.0, 4.0, 3.0], (3, 1, 2, 1))
    t = np.arange(3) / RATE
    y = block(x=Chunk(t, frames, 0.075), pins=Chunk(t[:1], pins[:1], 0.025))["y"]
    assert len(y) == 1 and y.end == 0.025  # the later input decides
    y = block(x=Chunk(t[:0], frames[:0], 0.075), pins=Chunk(t[1:], pins[1:], 0.075))["y"]
    assert_array_equal(y.t, t[1:])
    with pytest.raises(MisalignedError):
        block(x=Chunk(np.array([1.0]), frames[:1]), pins=Chunk(np.array([1.5]), pins[:1]))
    with pytest.raises(SpecError, match="sensors"):
        BlobMask().bind(
            {"x": frames_spec((3, 9, 9)), "pins": StreamSpec(shape=(2, 30, 3), units="px", rate_hz=RATE)}
        )


def test_pipeline_crop_detect_mask(tactip):
    full, crop, _ = tactip
    c = run_offline(Crop(), x=full, rate_hz=RATE, units=UNITS)["y"]
    det = run_offline(BlobDetect(), x=c.data, rate_hz=RATE, units=UNITS)
    assert det["count"].data.tolist() == [[30.0] * 3]
    m = run_offline(BlobMask(scale=1.5), x=c.data, pins=det["pins"].data, rate_hz=RATE, units=UNITS)["y"]
    assert_array_equal(m.data, blob_mask_numpy(crop, det["pins"].data, 1.5))


def test_module_imports_opencv_lazily():
    code = "import sys, flowtact.blocks.teleop.image; assert 'cv2' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True)
    assert BlobDetect.requires == {"cv2": "vision"} and Crop.requires == () and BlobMask.requires == ()


def test_docstring_examples():
    assert doctest.testmod(image_module, raise_on_error=True).failed == 0
