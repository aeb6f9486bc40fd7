"""graphs/braille_open.yaml: runs to the end of the line, identical in-process and across processes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from flowtact.launch import load_plan, run_plan
from flowtact.record import read_recording
from flowtact.runtime.placement import place

ROOT = Path(__file__).resolve().parents[3]
GRAPH = ROOT / "graphs" / "braille_open.yaml"


@pytest.mark.slow
def test_fast_recordings_are_bit_identical_in_process_and_across_processes(tmp_path):
    plan = load_plan(GRAPH)
    assert len(place(plan, fast=True).groups) == 2  # finger and neurons: really two processes
    run_plan(plan, fast=True, inproc=True, record=tmp_path / "inproc.h5")
    summary = run_plan(load_plan(GRAPH), fast=True, record=tmp_path / "procs.h5")
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
