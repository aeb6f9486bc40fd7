"""braille_cell_windows: the decoder's windows from position alone; the loop decides the same without ``char``."""

import numpy as np
import yaml
from runs import ROOT

from flowtact.blocks.braille.cell_windows import NO_CELL, BrailleCellWindows, cell_window_values
from flowtact.blocks.braille.cells import Geometry
from flowtact.blocks.braille.reading import char_windows, graph_text, position_windows, read_line
from flowtact.blocks.braille.scan import BrailleScan
from flowtact.testing import run_offline, run_source

GRAPH = ROOT / "graphs" / "braille.yaml"


def test_cells_from_position_are_the_scan_s_character_cells_sample_for_sample():
    """On a line of letters the position rule marks exactly the samples ``char`` marks, with the
    cell's index (the scan's speed jitters, so the samples fall anywhere in a cell)."""
    scan = BrailleScan(text="hello", speed_mm_s=37.0, speed_jitter=0.1)
    out = run_source(scan, 3.0, tick_s=0.1)
    x, char = out["position"].data, out["char"].data
    k = cell_window_values(x, Geometry())
    assert (k[x >= 5 * Geometry().cell_pitch] == 5).any()  # past the line: a cell the robot cannot tell blank
    x, char, k = (a[x < 5 * Geometry().cell_pitch] for a in (x, char, k))
    np.testing.assert_array_equal(k >= 0, char != 0)
    np.testing.assert_array_equal(k[k >= 0], np.floor(x[k >= 0] / Geometry().cell_pitch))


def test_the_window_is_the_cell_s_dots_and_nothing_of_the_text():
    g = Geometry()  # pitch 10.2 mm; dots ±(2.125 + 1.275) = ±3.4 mm around the centre
    x = np.array([-5.0, 1.7, 5.1, 8.5, 8.6, 11.9, 1e6 + 5.1, np.nan])
    np.testing.assert_array_equal(
        cell_window_values(x, g), [NO_CELL, 0, 0, 0, NO_CELL, 1, np.floor((1e6 + 5.1) / 10.2), NO_CELL]
    )
    assert cell_window_values(np.array([6.7]), g, origin_mm=1.6)[0] == 0  # the line moved 1.6 mm on
    out = run_offline(BrailleCellWindows(), position=np.array([0.0, np.inf, 5.0]), rate_hz=250.0,
                      units={"position": "mm"})  # fmt: skip
    assert out["window"].data.tolist() == [NO_CELL, NO_CELL, 0.0]


def test_offline_windows_from_position_equal_those_from_char():
    r = read_line(seed=4, speed_mm_s=45.0, text="ab cab", layers=("first",))
    pos, char = r.streams["scan.position"], r.streams["scan.char"]
    w_char, letters = char_windows(char.t, char.data)
    w_pos, labels = position_windows(pos.t, pos.data, char.data)
    assert labels == ("a", "b", "space", "c", "a", "b")  # the space cell is a window from position
    keep = [i for i, c in enumerate(labels) if c != "space"]
    np.testing.assert_array_equal(w_pos[keep], w_char)
    np.testing.assert_array_equal(r.windows, w_char)
    assert letters == r.letters


def _run(doc: dict, record: list[str]) -> dict:
    from flowtact.graphfile.graph import load_graph
    from flowtact.running.compile import compile_graph
    from flowtact.running.source_ends import default_duration
    from flowtact.runtime.inproc import InprocExecutor
    from flowtact.testing import MemoryRecorder

    doc = {**doc, "record": record}
    plan = compile_graph(load_graph(GRAPH, text=yaml.safe_dump(doc, sort_keys=False)))
    mem = MemoryRecorder()
    InprocExecutor(plan, fast=True, tick_s=plan.graph.tick_s, recorder=mem).run(default_duration(plan, None))
    return {"plan": plan, "chunks": mem.chunks}


def test_the_loop_reads_the_same_with_char_withheld():
    """graphs/braille.yaml with ``scan.char`` neither connected nor recorded (so never computed)
    decides the same letters at the same instants as the same loop windowed by ``char`` itself."""
    _, text = graph_text(GRAPH, seed=7, letters=8)
    doc = yaml.safe_load(text)
    doc["nodes"]["decoder"]["params"]["threshold"] = 0.5
    want = ["decoder.decision", "control.speed"]
    blind = _run(doc, want)
    assert "char" not in blind["plan"].demanded["scan"]
    by_char = yaml.safe_load(text)
    by_char["nodes"]["decoder"]["params"].update(threshold=0.5, window_labels=True, gap=["gap", "space"])
    by_char["edges"] = [e for e in by_char["edges"] if "windows" not in e] + ["scan.char -> decoder.window"]
    del by_char["nodes"]["windows"]
    seen = _run(by_char, [*want, "scan.char"])
    got = {}
    for name, run in (("blind", blind), ("seen", seen)):
        got[name] = {
            s: (
                np.concatenate([c.t for c in run["chunks"][s]]),
                np.concatenate([c.data for c in run["chunks"][s]]),
            )
            for s in want
        }
    (ta, da), (tb, db) = got["blind"]["decoder.decision"], got["seen"]["decoder.decision"]
    assert len(da) == 8  # one decision per letter (the window past the line's end stays unfinished)
    np.testing.assert_array_equal(ta, tb)
    np.testing.assert_array_equal(da, db)
    # the speed too, up to the last letter's end: past it the blind loop sees one more (blank) cell
    # under the finger and slows down for it, where char says "gap"
    (sa, va), (sb, vb) = got["blind"]["control.speed"], got["seen"]["control.speed"]
    n = int(np.searchsorted(sa, ta[-1]))
    assert n > 100
    np.testing.assert_array_equal(sa[:n], sb[:n])
    np.testing.assert_array_equal(va[:n], vb[:n])
