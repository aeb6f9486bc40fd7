"""Users' own data in: --replay of a CSV log on a node's own ports, default duration from the file,
the notice past its end, bad files refused in place, relative paths, run_graph(feed=...)."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from flowtact.recording.hdf5 import read_recording
from flowtact.testing import run_graph

ROOT = Path(__file__).parents[2]
TOUCH = str(ROOT / "graphs" / "touch.yaml")


def flowtact(*args, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "flowtact.cli", *args], capture_output=True, text=True, timeout=300, cwd=cwd
    )


@pytest.fixture(scope="module")
def sensor_log(tmp_path_factory):
    """2 s of the touch graph's own synthetic sensor, written as a CSV log with columns g1..g4, ref."""
    out = run_graph(TOUCH, duration_s=2.0)
    r, ref = out["sensor.r"], out["sensor.ref"]
    path = tmp_path_factory.mktemp("log") / "log.csv"
    table = np.column_stack([r.t, r.data, ref.data])
    np.savetxt(path, table, delimiter=",", fmt="%.17g", header="t,g1,g2,g3,g4,ref", comments="")
    return path, out


def test_csv_replay_keeps_names_ends_with_the_file_and_matches_the_live_run(sensor_log, tmp_path):
    log, live = sensor_log
    rec = tmp_path / "out.h5"
    proc = flowtact(
        "run",
        TOUCH,
        "--replay",
        f"sensor={log}:r=g1,g2,g3,g4",
        "--fast",
        "--inproc",
        "--record",
        str(rec),
        "--json",
    )
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert summary["duration_s"] == 2.0  # the file's end, not the graph's duration_s (3 s)
    assert summary["notes"] == ["sensor.force: not recorded (replay 'sensor' has no data for it)"]
    got = read_recording(rec)
    assert "sensor.r" in got.streams and "sensor.ref" in got.streams and "sensor.force" not in got.streams
    for name in ("force.f", "sa1.spikes", "fa1.spikes"):  # %.17g round-trips: the same downstream
        np.testing.assert_array_equal(got.streams[name].t, live[name].t, err_msg=name)
        np.testing.assert_array_equal(got.streams[name].data, live[name].data, err_msg=name)
    again = tmp_path / "again.h5"  # the provenance names the log by its absolute path: rerun elsewhere
    proc = flowtact("run", str(rec), "--fast", "--inproc", "--record", str(again), cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert np.array_equal(read_recording(again).streams["sa1.spikes"].t, got.streams["sa1.spikes"].t)


def test_fast_processes_are_bit_identical_to_inproc_and_say_once_when_past_the_end(sensor_log, tmp_path):
    log, _ = sensor_log
    runs = {}
    for mode in ("--inproc", None):
        rec = tmp_path / f"{mode or 'procs'}.h5"
        args = ["run", TOUCH, "--replay", f"sensor={log}:r=g1,g2,g3,g4", "--fast", "--duration", "3"]
        proc = flowtact(*args, *([mode] if mode else []), "--record", str(rec))
        assert proc.returncode == 0, proc.stderr
        notice = "replay 'sensor' ended at 2 s; the run continues to 3 s with no input from it"
        assert proc.stderr.count(notice) == 1, proc.stderr
        assert f"note: {notice}" in proc.stdout
        runs[mode] = read_recording(rec)
    a, b = runs.values()
    assert set(a.streams) == set(b.streams)
    for name in a.streams:
        assert np.array_equal(a.streams[name].t, b.streams[name].t), name
        assert np.array_equal(a.streams[name].data, b.streams[name].data), name
    assert a.streams["force.f"].t[-1] < 2.0  # nothing after the end: no held value


@pytest.mark.parametrize(
    ("content", "where", "message"),
    [
        (b"\x89PNG\r\n\x1a\n\x00\x00", "bad.csv:3:1", "not a text file"),
        (
            b"t,r[0],r[1],r[2],r[3],ref\n0,1,2,3,4,5\n0.001,1,2,3,4,abc\n",
            "bad.csv:3:15",
            "not a number in column 'ref': 'abc'",
        ),
        (b"t,r[0],r[1],r[2],r[3],ref\n0,1,2,3,4,5\n0.001,1,2,3,4\n", "bad.csv:3:13", "5 values in this row"),
        (b"time,ref\n0,1\n", "bad.csv:1:1", "no 't' column"),
        (b"t,ref\n0,1\n-1,1\n", "bad.csv:3:1", "time goes back"),
        (b"t,ref\n0,1\nnan,1\n", "bad.csv:3:1", "time 'nan' in column 't' is not a finite number"),
        (b"t,ref\n0,1\n0.1,1\n", "--replay:1:1", "bad.csv has no column for port 'r' of aunp_sensor"),
    ],
)
def test_bad_files_are_refused_before_start_naming_file_line_and_node(tmp_path, content, where, message):
    (tmp_path / "bad.csv").write_bytes(content)
    proc = flowtact("validate", TOUCH, "--replay", "sensor=bad.csv", cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    first = proc.stderr.splitlines()[0]
    assert first.startswith(f"{where}: ") and "node 'sensor'" in first and message in first, first
    assert "Traceback" not in proc.stderr


@pytest.mark.parametrize(
    ("replay", "message"),
    [
        ("sensr=log.csv", "unknown node 'sensr' (did you mean 'sensor'?)"),
        ("sensor=log.csv:rr=g1", "'rr' is not an output of aunp_sensor (did you mean 'r'?)"),
        ("sensor=log.csv:r", "'r' is not PORT=COLUMN[,COLUMN...]"),
        ("sensor=log.csv:r=g1,g2,g3,gg4", "no column 'gg4' in log.csv (did you mean 'g4'?)"),
        ("sensor", "expected NODE=FILE"),
    ],
)
def test_replay_usage_errors_are_located(sensor_log, tmp_path, replay, message):
    (tmp_path / "log.csv").write_bytes(sensor_log[0].read_bytes())
    proc = flowtact("validate", TOUCH, "--replay", replay, cwd=tmp_path)
    assert proc.returncode == 2 and proc.stderr.startswith("--replay:1:1: "), proc.stderr
    assert message in proc.stderr


def test_relative_paths_in_a_graph_file_are_beside_it(sensor_log, tmp_path):
    graphs = tmp_path / "project" / "graphs"
    (tmp_path / "project" / "data").mkdir(parents=True)
    graphs.mkdir()
    (tmp_path / "project" / "data" / "log.csv").write_bytes(sensor_log[0].read_bytes())
    (graphs / "g.yaml").write_text(
        "nodes:\n"
        "  log: {block: replay, params: {path: ../data/log.csv, stream: ref}}\n"
        "  lp: {block: lowpass, params: {cutoff_hz: 50}}\n"
        "edges: [log.y -> lp.x]\n"
        "record: [lp.y]\n"
    )
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    rec = elsewhere / "out.h5"
    proc = flowtact(
        "run", "../project/graphs/g.yaml", "--fast", "--inproc", "--record", "out.h5", cwd=elsewhere
    )
    assert proc.returncode == 0, proc.stderr
    got = read_recording(rec)
    assert got.streams["lp.y"].t[-1] == pytest.approx(1.999)  # the whole file: its end is the duration
    params = json.loads(got.provenance["params"])
    assert params["log"]["path"] == str(tmp_path / "project" / "data" / "log.csv")


def test_run_graph_feed_as_the_readme_shows(sensor_log):
    _, live = sensor_log
    t, r, ref = live["sensor.r"].t, live["sensor.r"].data, live["sensor.ref"].data
    fed = run_graph(TOUCH, feed={"sensor.r": (t, r), "sensor.ref": (t, ref)})
    assert "sensor.force" not in fed and fed["sensor.r"].data.shape == (2000, 4)
    for name in ("force.f", "dforce.y", "sa1.spikes", "fa1.spikes", "sa1_stim.y"):
        np.testing.assert_array_equal(fed[name].t, live[name].t, err_msg=name)
        np.testing.assert_array_equal(fed[name].data, live[name].data, err_msg=name)
    assert len(fed["sa1.spikes"]) > 0
    with pytest.raises(
        ValueError, match=r"feed: no output stream 'sensor\.rr' \(did you mean 'sensor\.r'\?\)"
    ):
        run_graph(TOUCH, feed={"sensor.rr": (t, r)})
