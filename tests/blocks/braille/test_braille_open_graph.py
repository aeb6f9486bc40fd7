"""graphs/braille_open.yaml: runs to the end of the line, identical in-process and across processes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from flowtact.recording.hdf5 import read_recording
from flowtact.running.launch import load_compiled, run_compiled
from flowtact.runtime.placement import place

ROOT = Path(__file__).resolve().parents[3]
GRAPH = ROOT / "graphs" / "braille_open.yaml"


@pytest.mark.slow
def test_fast_recordings_are_bit_identical_in_process_and_across_processes(tmp_path):
    plan = load_compiled(GRAPH)
    assert len(place(plan, fast=True).groups) == 2  # finger and neurons: really two processes
    run_compiled(plan, fast=True, inproc=True, record=tmp_path / "inproc.h5")
    summary = run_compiled(load_compiled(GRAPH), fast=True, record=tmp_path / "procs.h5")
    assert set(summary.processes) == {"finger", "neurons"}
    a, b = read_recording(tmp_path / "procs.h5"), read_recording(tmp_path / "inproc.h5")
    assert set(a.streams) == set(b.streams) == {
        "scan.taxels", "scan.char", "scan.position", "scan.y", "afferents.spikes", "cuneate.spikes"
    }  # fmt: skip
    for name in b.streams:
        x, y = a.streams[name], b.streams[name]
        assert len(y.t) > 0, name
        assert np.array_equal(x.t, y.t) and np.array_equal(x.data, y.data), name
    # the whole alphabet was read, to the end of the line, and both layers fired
    char = b.streams["scan.char"].data
    assert set(np.unique(char)) == set(range(27))  # gap + a..z
    assert b.streams["scan.position"].data[-1] > 26 * 10.2
    assert len(b.streams["afferents.spikes"].t) > 1000 and len(b.streams["cuneate.spikes"].t) > 1000


LOOP = """
name: loop
seed: 3
tick_s: 0.004
nodes:
  scan: {block: braille_scan, process: finger, params: {text: "abc", min_speed_mm_s: 10}}
  ctl:  {block: weighted_sum, process: control, params: {w1: [W24], bias: -140, units: "mm/s"}}
edges:
  - scan.taxels -> ctl.x1
  - ctl.y -> scan.speed
record: [scan.position, ctl.y]
""".replace("W24", ", ".join(["100"] * 24))


@pytest.mark.slow
def test_a_speed_loop_steers_the_next_sample_and_is_identical_across_processes(tmp_path):
    """A toy controller (speed = 100·Σ taxels − 140 mm/s) fed back through the delayed input: each
    sample's motion uses the command computed from the previous sample, clamped; same bits in
    one process and in two."""
    path = tmp_path / "loop.yaml"
    path.write_text(LOOP)
    plan = load_compiled(path)
    lo, hi = plan.graph.nodes["scan"].make().config.track()
    assert plan.ends["scan"] == pytest.approx((hi - lo) / 10.0, abs=0.005)  # bound at min speed
    run_compiled(plan, fast=True, inproc=True, record=tmp_path / "inproc.h5")
    run_compiled(load_compiled(path), fast=True, record=tmp_path / "procs.h5")
    a, b = read_recording(tmp_path / "inproc.h5"), read_recording(tmp_path / "procs.h5")
    for name in ("scan.position", "ctl.y"):
        assert np.array_equal(a.streams[name].t, b.streams[name].t), name
        assert np.array_equal(a.streams[name].data, b.streams[name].data), name
    x, cmd = a.streams["scan.position"].data, a.streams["ctl.y"].data
    assert x[-1] <= hi < x[-1] + 100 / 250  # read to the end of the line, then stopped
    v = np.diff(x) * 250.0
    np.testing.assert_allclose(v, np.clip(cmd[: len(v)], 10.0, 100.0), rtol=1e-9)
    assert (cmd < 10.0).any() and (cmd > 10.0).any()  # the loop really steered (and was clamped)
