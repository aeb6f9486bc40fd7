"""graphs/braille.yaml: the closed loop compiles, reads, steers, and runs the same in one process or three."""

import numpy as np
import pytest
from runs import ROOT

from flowtact.blocks.braille.reading import char_windows
from flowtact.blocks.braille.train_braille import HELDOUT_SEED
from flowtact.blocks.spiking.nb_model import load_model
from flowtact.recording.hdf5 import read_recording
from flowtact.running.launch import load_compiled, run_compiled
from flowtact.runtime.placement import place

GRAPH = ROOT / "graphs" / "braille.yaml"
SHORT = ["scan.random_letters=6"]


def test_the_loop_closes_through_the_scan_s_delayed_speed_input():
    plan = load_compiled(GRAPH)
    edges = {(e.src, e.src_port, e.dst, e.dst_port) for e in plan.active_edges}
    assert ("control", "speed", "scan", "speed") in edges
    assert plan.graph.nodes["scan"].cls.inputs["speed"].delay
    assert plan.graph.tick_s == 0.004
    assert len(place(plan, fast=True).groups) == 3


def test_the_shipped_model_is_the_first_layer_s_and_held_out_seeds_were_not_trained_on():
    m = load_model(ROOT / "blocks" / "braille" / "models" / "braille_first.npz")
    assert m.n_units == 24 and m.classes == tuple("abcdefghijklmnopqrstuvwxyz")
    assert m.provenance["spikes_stream"] == "afferents.spikes"
    assert max(m.provenance["seeds"]) < HELDOUT_SEED
    assert m.provenance["command"].startswith("flowtact train-braille")


@pytest.mark.slow
def test_fast_closed_loop_runs_are_bit_identical_in_process_and_across_processes(tmp_path):
    run_compiled(load_compiled(GRAPH, overrides=SHORT), fast=True, inproc=True, record=tmp_path / "inproc.h5")
    summary = run_compiled(load_compiled(GRAPH, overrides=SHORT), fast=True, record=tmp_path / "procs.h5")
    assert set(summary.processes) == {"finger", "neurons", "brain"}
    a, b = read_recording(tmp_path / "inproc.h5"), read_recording(tmp_path / "procs.h5")
    assert set(a.streams) == set(b.streams)
    for name in a.streams:
        x, y = a.streams[name], b.streams[name]
        assert np.array_equal(x.t, y.t) and np.array_equal(x.data, y.data), name
    # and it did read and steer: one decision per letter, the speed followed the decoder
    char, speed = a.streams["scan.char"], a.streams["control.speed"].data
    _, letters = char_windows(char.t, char.data)
    assert len(letters) == 6 and len(a.streams["decoder.decision"].t) == 6
    ctl = load_compiled(GRAPH).graph.nodes["control"].params
    lo, hi = ctl["min_speed_mm_s"], ctl["max_speed_mm_s"]
    assert 10.0 <= lo < hi <= 80.0  # inside the paper's range
    assert speed.min() >= lo and speed.max() <= hi and len(np.unique(speed)) > 10  # steered, within bounds


def test_recording_only_the_text_keeps_the_loop_closed():
    """Demand flows back through the delayed speed input: the controller runs though nothing records
    it (a single backward pass of the compiler once left the loop open, silently)."""
    from flowtact.blocks.braille.reading import graph_text
    from flowtact.graphfile.graph import load_graph
    from flowtact.running.compile import compile_graph

    path, text = graph_text(GRAPH, seed=1, text="ab", record=["scan.char"])
    plan = compile_graph(load_graph(path, text=text))
    assert plan.order == ["scan", "afferents", "windows", "decoder", "control"]
    assert plan.demanded["control"] == {"speed"} and plan.demanded["decoder"] == {"running"}
    assert "speed" in plan.needed["scan"]
