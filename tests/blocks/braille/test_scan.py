"""braille_scan: the fingertip's physics, its noise, its motion, its end and its ground truth."""

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from flowtact import ConfigError
from flowtact.blocks.braille.cells import CATEGORIES, Geometry, dot_positions, height_field, text_cells
from flowtact.blocks.braille.fingertip import taxel_offsets
from flowtact.blocks.braille.scan import BrailleScan
from flowtact.testing import run_source


def scan(duration=3.0, tick_s=0.1, seed=0, **params):
    return run_source(BrailleScan(**params), duration, tick_s=tick_s, seed=seed)


@pytest.mark.oracle
@pytest.mark.parametrize(("x", "y"), [(3.5, 0.0), (5.1, 0.7), (6.0, -1.9), (9.3, 2.6)])
def test_taxel_compression_matches_a_grid_convolution_of_the_height_field(x, y):
    """Independent oracle: the height field on a 0.02 mm grid, blurred by scipy's Gaussian filter,
    averaged over each electrode's square; the block integrates the same model by quadrature."""
    tip = BrailleScan(text="y").config.fingertip()  # y = dots 1 3 4 5 6
    g = tip.geometry
    dots = dot_positions(text_cells("y"), g)
    h = 0.02
    gx = np.arange(-8.0, 20.0, h) + h / 2
    gy = np.arange(-12.0, 12.0, h) + h / 2
    field = height_field(gx[None, :], gy[:, None], dots, g)
    blurred = gaussian_filter(field, tip.sigma_mm / h, mode="constant", truncate=6.0)
    ox, oy = taxel_offsets(tip.pitch_mm)
    half = tip.taxel_mm / 2
    expected = []
    for cx, cy in zip(x + ox, y + oy, strict=True):
        inside_x = np.abs(gx - cx) < half
        inside_y = np.abs(gy - cy) < half
        expected.append(blurred[np.ix_(inside_y, inside_x)].mean())
    got = tip.compression(np.array([x]), np.array([y]), dots)[0] - tip.press_mm
    assert max(expected) > 0.1  # dots under the finger: a real comparison
    np.testing.assert_allclose(got, expected, atol=0.01 * g.dot_height)


def test_a_single_dot_lights_the_taxels_under_it_and_no_others():
    # "a" is dot 1 alone: top-left of its cell, y = +dot pitch (4.25 mm) → taxel row 0 (y = +5) and 1 (+3)
    g = Geometry()
    x_dot = g.cell_pitch / 2 - g.dot_pitch / 2
    tip = BrailleScan(text="a").config.fingertip()
    dots = dot_positions(text_cells("a"), g)
    c = tip.compression(np.array([x_dot]), np.array([0.0]), dots)[0].reshape(6, 4) - tip.press_mm
    assert c[0, 1:3].min() > 0.1 and c[1, 1:3].min() > 0.05  # the inner columns of the top rows
    assert c[:2, [0, 3]].max() < 0.01  # the outer columns are 2 mm off the dot's rim
    assert c[3:].max() < 1e-6  # the bottom half feels only the flat paper
    # the dot sits midway between columns 1 and 2
    np.testing.assert_allclose(c[:, 1], c[:, 2], rtol=1e-12, atol=1e-15)
    # moving the finger +2 mm across the line moves the dot 2 mm down the array (one taxel row)
    shifted = tip.compression(np.array([x_dot]), np.array([2.0]), dots)[0].reshape(6, 4) - tip.press_mm
    assert np.argmax(shifted[:, 1]) == np.argmax(c[:, 1]) + 1


def test_readings_are_a_parallel_plate_of_the_compression_and_rest_at_the_press():
    out = scan(text="a", noise=0.0, duration=0.2)  # the finger over blank paper at first
    tip = BrailleScan(text="a").config.fingertip()
    u = tip.transmission * tip.press_mm
    np.testing.assert_allclose(out["taxels"].data[:10], u / (tip.gap_mm - u), rtol=1e-12)


def test_noise_is_seeded_reproducible_and_of_the_stated_sd():
    a = scan(text="ab", seed=4)["taxels"].data
    b = scan(text="ab", seed=4, tick_s=0.004)["taxels"].data
    c = scan(text="ab", seed=5)["taxels"].data
    clean = scan(text="ab", noise=0.0, seed=4)["taxels"].data
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    assert np.array_equal(clean, scan(text="ab", noise=0.0, seed=9)["taxels"].data)
    sd = (a - clean).std()
    assert 0.0095 < sd < 0.0105  # the default noise, 0.01, over ~7000 readings


def test_random_text_follows_the_seed():
    def text(seed):
        out = scan(random_letters=12, seed=seed, duration=10.0)["char"].data
        runs = out[np.r_[True, np.diff(out) != 0]]
        return "".join(CATEGORIES[int(k)] for k in runs if k != 0)

    assert text(1) == text(1) and text(1) != text(2) and len(text(1)) <= 12


def test_char_is_the_letter_whose_dots_lie_under_the_finger_centre():
    out = scan(text="hi you", noise=0.0, duration=5.0)
    x, char = out["position"].data, out["char"].data
    g = Geometry()
    for k, ch in enumerate("hi you"):
        lo, hi = g.cell_span(k)
        inside = (x >= lo) & (x <= hi)
        assert inside.any()
        assert set(char[inside]) == {CATEGORIES.index("space" if ch == " " else ch)}
    assert set(char[x < g.cell_span(0)[0]]) == {0}  # gap before the first cell


def test_the_scan_ends_when_the_line_is_read_and_ends_at_says_when():
    blk = BrailleScan(text="abc", speed_mm_s=40.0)
    assert blk.specs({})["char"].categories  # the declared categories, the config's rate
    end = blk.ends_at({})
    out = run_source(blk, end + 1.0, tick_s=0.05)
    x = out["position"].data
    lo, hi = blk.config.track()
    assert x[0] == lo and x[-1] <= hi < x[-1] + 40.0 / 250.0  # to the end of the line, not past
    assert out["position"].t[-1] + 1 / 250.0 == pytest.approx(end)  # nothing after ends_at
    assert (hi - lo) / 40.0 < end <= (hi - lo) / 40.0 + 1 / 250.0 + 1e-9  # samples at x0 .. ≤ hi
    np.testing.assert_allclose(np.diff(x), 40.0 / 250.0, rtol=1e-9)


def test_ends_at_with_a_steered_speed_is_the_bound_at_the_slowest_speed():
    from flowtact import StreamSpec

    blk = BrailleScan(text="abc", min_speed_mm_s=10.0)
    speed = {"speed": StreamSpec("float64", (), "mm/s", 250.0)}
    lo, hi = blk.config.track()
    assert (hi - lo) / 10.0 < blk.ends_at(speed) <= (hi - lo) / 10.0 + 1 / 250.0 + 1e-9


def test_a_speed_command_steers_the_next_sample_and_lateral_moves_the_finger():
    n = 250
    speed = np.r_[np.full(100, 20.0), np.full(n - 100, 50.0)]
    lateral = np.r_[np.zeros(150), np.full(n - 150, 1.5)]
    out = run_source(
        BrailleScan(text="abcdef", y_offset_mm=-0.5),
        1.0,
        tick_s=[0.004, 0.012, 0.1],
        inputs={"speed": speed, "lateral": lateral},
        rate_hz=250.0,
        units={"speed": "mm/s", "lateral": "mm"},
    )
    v = np.diff(out["position"].data) * 250.0
    np.testing.assert_allclose(v[:100], 20.0, rtol=1e-9)  # moves into samples 1..100: commands 0..99
    np.testing.assert_allclose(v[100:], 50.0, rtol=1e-9)  # sample 100's command moves sample 101 on
    y = out["y"].data
    assert set(y[:151]) == {-0.5} and set(y[151:]) == {1.0}


@pytest.mark.parametrize(
    ("params", "field", "words"),
    [
        ({"text": "abc1"}, "text", "letters a-z and spaces"),
        ({"text": "ABC"}, "text", "letters a-z and spaces"),
        ({"text": ""}, "text", "random_letters"),
        ({"text": "ab", "random_letters": 3}, "text", "one or the other"),
        ({"text": "ab", "min_speed_mm_s": 50.0, "max_speed_mm_s": 40.0}, "max_speed_mm_s", ">= min_speed"),
        ({"text": "ab", "gap_mm": 0.2}, "gap_mm", "gap would close"),
        ({"text": "ab", "speed_mm_s": 0.0}, "speed_mm_s", "> 0"),
    ],
)
def test_bad_parameters_are_refused_naming_the_parameter(params, field, words):
    with pytest.raises(ConfigError) as e:
        BrailleScan(**params)
    assert e.value.field == field and words in str(e.value) and "braille_scan" in str(e.value)
