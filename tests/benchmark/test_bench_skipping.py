"""The ``skipping`` benchmark suite's pieces: what it names as skipped, the gate figures, the record comparison."""

from __future__ import annotations

import numpy as np
import pytest

from flowtact.bench import skipping
from flowtact.graphfile.graph import load_graph, resolve_graph_path
from flowtact.running.compile import compile_graph


def test_skipped_parts_names_the_pruned_node_the_unfed_inputs_and_the_unused_outputs():
    plan = compile_graph(load_graph(resolve_graph_path("touch")))
    text = skipping.skipped_parts(plan)
    assert text.startswith("not started: `ddforce`")
    assert "inputs not fed: `fa1_drive.x3`, `sa1_drive.x3`" in text
    assert "`sa1.v`" in text and "`sensor.temp_c`" in text
    full = compile_graph(load_graph(resolve_graph_path("touch")), prune=False)
    assert skipping.skipped_parts(full) == "nothing"


def test_gate_figures_on_hand_checkable_frames():
    frames = np.zeros((5, 3, 8, 8), np.uint8)  # frame 0 is the reference and is left out
    frames[2, 0, 3, 3] = 7  # frame 2 differs from 1 by 7 DN at one pixel, 3 from 2; 4 equals 3
    ssim = np.array([[1.0, 1.0, 1.0], [0.9, 0.8, 0.5], [0.9, 0.7, 0.5], [0.9, 0.8, 0.5], [0.9, 0.8, 0.5]])
    g = skipping.gate_figures(frames, ssim)
    assert g["equal_fraction"] == pytest.approx(1 / 3)  # pairs (1,2) (2,3) (3,4): only (3,4) equal
    assert g["max_pixel_change_dn"] == 7
    # largest |ΔSSIM|·|slope|: 0.1 on sensor 1 (index) times 19.1 N
    assert g["reuse_error_n"] == pytest.approx(0.1 * abs(skipping.SSIM_SLOPE_N[1]))


def test_pruned_and_forced_full_touch_record_the_same_and_a_difference_is_caught():
    graph = load_graph(resolve_graph_path("touch"))
    pruned, full = compile_graph(graph), compile_graph(graph, prune=False)
    same, detail = skipping.same_records(pruned, full, 1.0)
    assert same and detail == "10 streams identical"
    other = compile_graph(load_graph(resolve_graph_path("touch"), overrides=["sensor.scenario=rest"]))
    same, detail = skipping.same_records(pruned, other, 1.0)
    assert not same and "sensor.force" in detail


def test_cpu_per_graph_second_is_positive_and_counts_only_the_run():
    plan = compile_graph(load_graph(resolve_graph_path("touch")))
    assert skipping.cpu_per_graph_second(plan, 0.5) > 0
