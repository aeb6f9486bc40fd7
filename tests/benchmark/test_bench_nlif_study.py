"""The NLIF accuracy and scale suites' measuring pieces: spike-train distances on hand-checkable
trains, the exact LIF oracle against closed forms, and one quick run of nlif_accuracy through the runner."""

from __future__ import annotations

import json
import math
import time

import numpy as np
import pytest

from flowtact.bench.blocks.spiking.lif_reference import exact_spikes
from flowtact.bench.blocks.spiking.nlif_accuracy import ou_paths
from flowtact.bench.blocks.spiking.nlif_scale import paced, realtime_crossing
from flowtact.bench.blocks.spiking.spike_metrics import (
    coincidence_factor,
    count_error,
    split_by_neuron,
    van_rossum_sq,
)
from flowtact.cli import main

TAU = 0.005


def test_van_rossum_of_identical_trains_is_zero_and_of_one_lone_spike_is_a_half():
    a = np.array([0.1, 0.2, 0.35])
    assert van_rossum_sq(a, a, TAU) == pytest.approx(0.0, abs=1e-12)
    assert van_rossum_sq([0.1], [], TAU) == pytest.approx(0.5)
    assert van_rossum_sq([], [0.1, 0.5], TAU) == pytest.approx(1.0)  # two far-apart lone spikes


def test_van_rossum_of_a_shifted_spike_is_one_minus_the_kernel_overlap_and_symmetric():
    d = 0.002
    expected = 1.0 - math.exp(-d / TAU)
    assert van_rossum_sq([0.1], [0.1 + d], TAU) == pytest.approx(expected, rel=1e-12)
    assert van_rossum_sq([0.1 + d], [0.1], TAU) == pytest.approx(expected, rel=1e-12)
    # two pairs far apart add up
    assert van_rossum_sq([0.1, 0.5], [0.1 + d, 0.5 + d], TAU) == pytest.approx(2 * expected, rel=1e-9)


def test_coincidence_factor_matches_a_hand_computed_value():
    ref, model = np.array([0.1, 0.3, 0.5]), np.array([0.101, 0.35, 0.5])
    # 2 coincidences within ±2 ms; expected by chance 2·ν·Δ·N_ref = 2·3·0.002·3 = 0.036
    expected = (2 - 0.036) / 3.0 / (1 - 2 * 3 * 0.002)
    assert coincidence_factor(ref, model, 0.002, 1.0) == pytest.approx(expected, rel=1e-12)
    assert coincidence_factor(ref, ref, 0.002, 1.0) == pytest.approx(1.0)
    assert coincidence_factor(ref, ref + 0.01, 0.002, 1.0) < 0  # no coincidence: below chance


def test_coincidences_pair_one_to_one():
    # two model spikes near one reference spike count once
    assert coincidence_factor([0.1], [0.0995, 0.1005], 0.002, 1.0) < coincidence_factor(
        [0.1], [0.1], 0.002, 1.0
    )


def test_count_error_and_split_by_neuron():
    assert count_error([10, 10], [9, 12]) == pytest.approx(3 / 20)
    trains = split_by_neuron([0.3, 0.1, 0.2], [1, 0, 1], 3)
    assert [list(t) for t in trains] == [[0.1], [0.2, 0.3], []]


def test_exact_oracle_reproduces_numerics_oracle_b():
    h = 1e-5
    t = np.arange(round(2.0 / h) + 1) * h
    times, idx = exact_spikes(1.5 + np.sin(2 * np.pi * 5 * t), h, 0.01, 0.0, [1.0])
    assert len(times) == 179 and not idx.any()
    np.testing.assert_allclose(times[:4] * 1e3, [9.180725, 16.615325, 23.115400, 29.044015], atol=2e-5)


def test_exact_oracle_constant_drive_gives_the_closed_form_intervals_with_refractoriness():
    tau, ref = 0.01, 0.0035
    h = 1e-3
    times, _ = exact_spikes(np.full(101, 2.0), h, tau, 0.0, [1.0], refractory=ref)
    first = tau * math.log(2.0)  # v = 2(1 − e^{−t/τ}) reaches 1
    expected = first + np.arange(len(times)) * (first + ref)
    np.testing.assert_allclose(times, expected, atol=1e-12)
    assert len(times) == int((0.1 - first) / (first + ref)) + 1


def test_exact_oracle_finds_a_crossing_inside_a_segment_whose_ends_are_below_threshold():
    # one 20 ms segment, drive falling 4 → −4: v rises above 1 (~1.2 at 7 ms) and ends far below
    coarse = exact_spikes(np.array([4.0, -4.0]), 0.02, 0.01, 0.0, [1.0])[0]
    fine_u = np.linspace(4.0, -4.0, 2001)  # the same linear drive on a 10 µs grid
    fine = exact_spikes(fine_u, 1e-5, 0.01, 0.0, [1.0])[0]
    assert len(coarse) == len(fine) == 1
    assert coarse[0] == pytest.approx(fine[0], abs=1e-12)


def test_ou_paths_have_the_stationary_sd_and_correlation_time():
    x = ou_paths(200_000, 4, 1e-4, 0.002, 0.5, seed=1)
    assert x.std() == pytest.approx(0.5, rel=0.05)
    lag = 20  # 2 ms = one correlation time
    r = np.mean([np.corrcoef(x[:-lag, i], x[lag:, i])[0, 1] for i in range(4)])
    assert r == pytest.approx(math.exp(-1.0), abs=0.05)


def test_realtime_crossing_interpolates_log_log_and_is_none_when_always_fast():
    assert realtime_crossing([10, 100, 1000], [10.0, 2.0, 0.5]) == pytest.approx(math.sqrt(100 * 1000))
    assert realtime_crossing([10, 100], [10.0, 2.0]) is None


def test_paced_runs_every_tick_in_order_and_reports_each_one():
    seen = []

    def blk(x):
        seen.append(x)

    late, busy = paced(blk, list(range(20)), period=1e-4)
    assert seen == list(range(20))
    assert late.shape == busy.shape == (20,) and np.isfinite(late).all() and (busy >= 0).all()


def test_nlif_accuracy_quick_through_the_runner(tmp_path):
    assert main(["bench", "nlif_accuracy", "--quick", "--out", str(tmp_path)]) == 0
    res = json.loads((tmp_path / "results" / "nlif_accuracy.json").read_text())
    assert res["status"] == "ok"
    checks = {c["name"] for c in res["checks"]}
    assert any("deterministic" in c for c in checks) and any("noisy" in c for c in checks)
    assert len(res["tradeoffs"]) == 2
    for t in res["tradeoffs"]:
        assert len(t["points"]) == 12 and sum(p["default"] for p in t["points"]) == 1
    report = (tmp_path / "REPORT.md").read_text()
    assert "float32 is **not supported**" in report
    assert len(list((tmp_path / "plots").glob("*.png"))) >= 2


def test_paced_stops_a_run_that_falls_far_behind():
    def slow(**_):
        time.sleep(0.002)

    late, _ = paced(slow, list(range(1000)), period=1e-4, give_up=0.01)
    assert len(late) < 1000 and late[-1] > 0.01


def test_the_lateness_axis_writes_numbers_as_numbers():
    """The symlog lateness axis of the nlif_scale plot reads −1, 0, 10, not −10⁰, 10¹."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    from flowtact.bench.blocks.spiking.nlif_scale import SIGMAS, draw

    rows = [
        {"sigma": s, "n": n, "rtf": 5.0, "rtf_q1": 4.0, "rtf_q3": 6.0, "late_p99_ms": late}
        for s in SIGMAS
        for n, late in ((100, -0.5), (10_000, 30.0))
    ]
    fig = Figure()
    draw(rows)(fig)
    fig.canvas.draw()
    ax2 = fig.axes[1]
    texts = [t.get_text() for t in ax2.get_yticklabels() if t.get_text()]
    assert "−1" in texts and "10" in texts, texts
    assert not [t for t in texts if "10^" in t or "{" in t or "⁰" in t], texts
