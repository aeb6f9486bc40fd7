"""The agreement helpers of the side-by-side suites (bench/agreement.py, bench/blocks/teleop/ssim_peers.py)
on hand-checkable cases, and the ``ssim`` suite end to end in --quick mode. No timing is asserted."""

from __future__ import annotations

import json

import numpy as np
import pytest

from flowtact.bench.agreement import EPS, fir_agreement, max_abs_diff
from flowtact.cli import main


def test_max_abs_diff_is_the_largest_elementwise_difference_and_nan_only_matches_nan():
    assert max_abs_diff([1.0, 2.0, 3.0], [1.0, 2.5, 2.0]) == 1.0
    assert max_abs_diff([np.nan, 1.0], [np.nan, 1.0]) == 0.0
    assert max_abs_diff([np.nan], [1.0]) == np.inf
    with pytest.raises(ValueError, match="shapes differ"):
        max_abs_diff([1.0], [1.0, 2.0])


def test_fir_agreement_counts_one_rounding_unit_of_each_outputs_own_dot_product():
    x = np.array([1.0, -2.0, 4.0, 8.0])
    coef = np.array([0.5, 0.0, -0.25])  # y[i] = 0.5·x[i−1] − 0.25·x[i+1] (pos 1, zeros outside)
    want = np.array([-0.25 * -2.0, 0.5 * 1 - 0.25 * 4, 0.5 * -2 - 0.25 * 8, 0.5 * 4])
    cond = np.array([0.5, 0.5 + 1.0, 1.0 + 2.0, 2.0])  # Σ|c_k·x[i−1+k]|
    assert fir_agreement(want, want, coef, x, 1) == {"max_abs": 0.0, "eps_units": 0.0}
    got = want.copy()  # want[0] = 0.5 and want[3] = 2.0: these perturbations are exact in float64
    got[0] += 4 * EPS * cond[0]  # four units at output 0 (2 eps)
    got[3] += 2 * EPS * cond[3]  # two units at output 3, a larger absolute difference (4 eps)
    r = fir_agreement(got, want, coef, x, 1)
    assert r == {"max_abs": 4 * EPS, "eps_units": 4.0}
    # the window position matters: read as pos 0, output 0's conditioning is |0.5·x[0]| + |−0.25·x[2]| = 1.5
    assert fir_agreement(got, want, coef, x, 0)["eps_units"] == pytest.approx(2 / 1.5)


def test_fir_agreement_flags_a_difference_where_there_is_nothing_to_round():
    x = np.zeros(5)
    coef = np.array([1.0, -1.0])
    assert fir_agreement(np.zeros(5), np.zeros(5), coef, x, 0)["eps_units"] == 0.0
    assert fir_agreement(np.full(5, 1e-300), np.zeros(5), coef, x, 0)["eps_units"] == np.inf
    with pytest.raises(ValueError, match="pos"):
        fir_agreement(np.zeros(5), np.zeros(5), coef, x, 2)


def test_savgol_block_and_scipy_agree_to_rounding_and_a_wrong_filter_does_not():
    signal = pytest.importorskip("scipy.signal")
    from flowtact import Chunk, StreamSpec
    from flowtact.blocks.signal.savgol import SavGol, savgol_coeffs

    x = np.random.default_rng(0).normal(size=500)
    block = SavGol(window=11, order=3, deriv=1, mode="centred")
    block.bind({"x": StreamSpec(units="N", rate_hz=1000.0)})
    y = np.concatenate([block(x=Chunk(np.arange(500) / 1e3, x))["y"].data, block.flush()["y"].data])
    coef = savgol_coeffs(11, 3, 1, rate_hz=1000.0)
    ref = signal.savgol_filter(x, 11, 3, deriv=1, delta=1e-3, mode="constant")
    assert fir_agreement(y, ref, coef, x, 5)["eps_units"] < 1000
    wrong = signal.savgol_filter(x, 11, 2, deriv=1, delta=1e-3, mode="constant")  # a different filter
    assert fir_agreement(wrong, ref, coef, x, 5)["eps_units"] > 1e6


def test_opencv_ssim_equals_scikit_image_for_both_windows_and_quality_ssim_does_not():
    pytest.importorskip("cv2")
    pytest.importorskip("skimage")
    from flowtact.bench.blocks.teleop.ssim_peers import (
        WINDOWS,
        OpenCvSsim,
        QualitySsim,
        downsample2,
        skimage_ssim,
    )

    rng = np.random.default_rng(1)
    ref = rng.integers(0, 256, (40, 52), dtype=np.uint8)
    cur = np.clip(ref.astype(int) + rng.integers(-40, 40, ref.shape), 0, 255).astype(np.uint8)
    for window in WINDOWS:
        want = skimage_ssim(ref, cur, window)
        assert 0.2 < want < 0.99
        assert abs(OpenCvSsim(ref, window).compare(cur) - want) < 1e-12
    assert abs(QualitySsim(ref).compare(cur) - skimage_ssim(ref, cur, "gauss1.5")) > 1e-4  # border windows
    assert downsample2(np.array([[1, 2, 9], [3, 4, 9]], np.uint8)).tolist() == [[3]]  # (10 + 2) // 4


@pytest.mark.slow
def test_the_ssim_suite_runs_in_quick_mode_with_its_agreement_plot(tmp_path):
    pytest.importorskip("cv2")
    pytest.importorskip("skimage")
    assert main(["bench", "ssim", "--quick", "--out", str(tmp_path)]) == 0
    res = json.loads((tmp_path / "results" / "ssim.json").read_text())
    assert res["status"] == "ok"
    rows = res["data"]["matrix"]
    assert {r["impl"] for r in rows} == {"flowtact", "OpenCV filters", "OpenCV quality", "scikit-image"}
    assert all(r["max_abs"] < 1e-10 for r in rows if r["impl"] in ("flowtact", "OpenCV filters"))
    assert not any(
        r["impl"] == "flowtact" and r["window"] != "box7" for r in rows
    )  # not supported, not faked
    assert (tmp_path / "plots" / "ssim-time_vs_agreement.png").exists()
