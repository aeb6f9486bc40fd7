"""Sources with inputs: a plant in a feedback loop, ticked every tick, identical in and across processes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import toyblocks
from runs import TEST_BLOCKS

from flowtact.recording.hdf5 import read_recording
from flowtact.running.launch import load_compiled, run_compiled
from flowtact.testing import CHECKS, run_source

LOOP = """
name: loop
nodes:
  plant: {block: "toyblocks:Plant", process: hardware, params: {rate_hz: 100, gain: 0.5}}
  ctl:   {block: "toyblocks:Scale", process: control, params: {gain: -0.8}}
edges:
  - plant.y -> ctl.x
  - ctl.y -> plant.u
record: [plant.y, ctl.y]
"""


@pytest.mark.parametrize("check", CHECKS, ids=lambda c: c.__name__)
def test_a_source_with_inputs_conforms(check):
    check(toyblocks.Plant)


def test_a_source_gets_what_arrived_since_its_last_tick_and_runs_without_input():
    out = run_source(toyblocks.Plant(), 0.3, tick_s=0.05, inputs={"u": np.full(30, 2.0)}, rate_hz=100.0)
    # sample i sees the commands stamped before it, delivered in the same tick
    assert out["y"].data[0] == 1.0 and np.all(out["y"].data[1:] == 2.0)
    alone = run_source(toyblocks.Plant(), 0.3, tick_s=0.05)
    assert len(alone["y"]) == 30 and np.all(alone["y"].data == 1.0)


@pytest.mark.slow
def test_a_feedback_loop_through_a_source_is_identical_in_and_across_processes(tmp_path: Path):
    graph = tmp_path / "loop.yaml"
    graph.write_text(LOOP)
    # a loop keeps the real-time tick in --fast runs (5 ms), so the command really comes back
    a = run_compiled(
        load_compiled(graph, allow_modules=TEST_BLOCKS),
        duration_s=1.0,
        fast=True,
        inproc=True,
        record=tmp_path / "a.h5",
    )
    b = run_compiled(
        load_compiled(graph, allow_modules=TEST_BLOCKS), duration_s=1.0, fast=True, record=tmp_path / "b.h5"
    )
    assert set(b.processes) == {"hardware", "control"}
    ra, rb = read_recording(tmp_path / "a.h5"), read_recording(tmp_path / "b.h5")
    y = ra.streams["plant.y"].data
    assert len(y) == 100 and a.samples["plant.y"] == 100
    # the loop really closes: the command (−0.8·y, one tick late) pulls the output away from 1
    assert y[0] == 1.0 and np.ptp(y) > 0.3
    for name in ("plant.y", "ctl.y"):
        assert np.array_equal(ra.streams[name].t, rb.streams[name].t)
        assert np.array_equal(ra.streams[name].data, rb.streams[name].data), name


def test_a_graph_may_set_its_tick_and_a_bad_one_is_refused(tmp_path: Path):
    from flowtact.errors import GraphFileError
    from flowtact.graphfile.graph import load_graph

    ok = tmp_path / "ok.yaml"
    ok.write_text(LOOP + "tick_s: 0.002\n")
    assert load_graph(str(ok), allow_modules=TEST_BLOCKS).tick_s == 0.002
    bad = tmp_path / "bad.yaml"
    bad.write_text(LOOP + "tick_s: -1\n")
    with pytest.raises(GraphFileError, match="'tick_s' must be a number of seconds > 0"):
        load_graph(str(bad), allow_modules=TEST_BLOCKS)
