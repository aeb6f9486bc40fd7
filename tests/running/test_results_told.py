"""Runs tell their results: a block's own summary line (Braille read, replay played), no deadline
lines on a virtual clock, and no fault counter raised by a shipped graph working as designed."""

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
from runs import allow_args, env

from flowtact.recording.hdf5 import read_recording
from flowtact.runtime.inproc import RunSummary

ROOT = Path(__file__).parents[2]
BRAILLE = str(ROOT / "graphs" / "braille.yaml")
TOUCH = str(ROOT / "graphs" / "touch.yaml")


def flowtact(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "flowtact.cli", *args], capture_output=True, text=True, timeout=300
    )


def test_the_braille_loop_says_what_it_read_and_how_much_was_right(tmp_path):
    rec = tmp_path / "loop.h5"
    proc = flowtact("run", BRAILLE, "--fast", "--json", "--record", str(rec))
    assert proc.returncode == 0, proc.stderr
    s = json.loads(proc.stdout)
    # the shipped graph raises no counter that signals a fault upstream (it was float rounding)
    assert "late_spikes" not in s["counters"].get("decoder", {}), s["counters"]
    said = s["block_summaries"]
    m = re.fullmatch(
        r'read (\d+) windows, (\d+) right \(against the window labels\): "([a-z]+)"', said["decoder"]
    )
    assert m, said
    n, right, text = int(m[1]), int(m[2]), m[3]
    # the counts are the recording's: each decision against the letter under the finger in its window
    r = read_recording(rec)
    dec, char = r.streams["decoder.decision"], r.streams["scan.char"]
    classes, cats = dec.spec.categories, char.spec.categories
    decided = [classes[int(d)] for d in dec.data]
    truth = [cats[int(char.data[np.searchsorted(char.t, t) - 1])] for t in dec.t]
    assert n == len(decided) == 26 and text == "".join(decided)
    assert right == sum(a == b for a, b in zip(decided, truth, strict=True))
    # The varying fingertip at the loop's 100-300 mm/s reads about 2 letters in 3 (17/26 when
    # written; constant speed: 73 % at 80 mm/s, less faster). A decoder at chance (1/26) gets 8 or
    # more of 26 right with probability < 1e-5 (binomial tail): a broken decoder would not.
    assert right >= 8
    scan = re.fullmatch(r'scanned "([a-z]+)" \(26 letters\) in ([\d.]+) s, (\d+) mm/s mean', said["scan"])
    assert scan and scan[1] == "".join(truth), said
    assert 100 <= int(scan[3]) <= 300  # the controller's bounds
    assert f"decoder: {said['decoder']}" in RunSummary(**_fields(s)).format()


def _fields(s: dict) -> dict:
    keep = ("graph", "duration_s", "wall_s", "stopped_by", "block_summaries")
    return {k: s[k] for k in keep}


DEADLINE = """\
name: ramp
nodes:
  src:  {block: "toyblocks:Ramp", process: a}
  gain: {block: "toyblocks:Scale", process: b, params: {gain: 2.0}}
edges: [src.y -> gain.x]
deadlines:
  - {from: src, to: gain, budget: 1us}
record: [gain.y]
"""


def test_a_fast_summary_has_no_wall_clock_deadline_lines(tmp_path):
    path = tmp_path / "deadline.yaml"
    path.write_text(DEADLINE)
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "flowtact.cli",
            *allow_args(["run", str(path), "--fast", "--duration", "2", "--json"]),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        env=env(),
    )
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["paths"] == {} and "deadline" not in proc.stderr, proc.stdout
    # the same summary in real time shows the path (the line is left out only on a virtual clock)
    paths = {"src -> gain": {"n": 5, "p50_us": 80.0, "p99_us": 90.0, "budget_us": 1.0, "violations": 5}}
    live = RunSummary(graph="g", duration_s=2, wall_s=2, stopped_by="duration", paths=paths, realtime=True)
    fast = RunSummary(graph="g", duration_s=2, wall_s=2, stopped_by="duration", paths=paths, realtime=None)
    assert "deadline src -> gain" in live.format() and "deadline" not in fast.format()
    assert fast.to_dict()["paths"] == {}


def test_a_replayed_run_says_what_it_replayed(tmp_path):
    rec = tmp_path / "touch.h5"
    assert (
        flowtact("run", TOUCH, "--fast", "--inproc", "--duration", "1.5", "--record", str(rec)).returncode
        == 0
    )
    for where in (["--inproc"], []):
        proc = flowtact("run", str(rec), "--fast", "--replay", f"sensor={rec}", *where)
        assert proc.returncode == 0, proc.stderr
        line = next((ln for ln in proc.stdout.splitlines() if ln.strip().startswith("sensor: ")), "")
        assert line.strip().startswith(f"sensor: replayed {rec} ("), proc.stdout
        assert "r: 1,500 samples, 0-1.499 s" in line, line


def test_a_block_summary_is_one_bounded_line():
    from flowtact.runtime.inproc import SUMMARY_MAX_CHARS, block_summaries

    class Says:
        name = "says"

        def __init__(self, text):
            self.text = text

        def summary(self):
            return self.text

    got = block_summaries({"a": Says("two\nlines"), "b": Says(None), "c": Says("x" * 10**6)})
    assert got["a"] == "two lines" and "b" not in got
    assert len(got["c"]) == SUMMARY_MAX_CHARS and got["c"].endswith("…")
