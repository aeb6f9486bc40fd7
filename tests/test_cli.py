"""The flowtact command end to end: run, record, re-run from a recording, replay, blocks, graph, plot."""

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from flowtact.cli import main
from flowtact.recording.hdf5 import read_recording

ROOT = Path(__file__).parent.parent
TOUCH = str(ROOT / "graphs" / "touch.yaml")
SLIP = str(ROOT / "graphs" / "slip.yaml")


def flowtact(*args):
    return subprocess.run(
        [sys.executable, "-m", "flowtact.cli", *args], capture_output=True, text=True, timeout=300
    )


@pytest.fixture(scope="module")
def touch_h5(tmp_path_factory):
    out = tmp_path_factory.mktemp("rec") / "touch.h5"
    proc = flowtact("run", TOUCH, "--fast", "--duration", "3", "--record", str(out))
    assert proc.returncode == 0, proc.stderr
    assert "sa1.spikes" in proc.stdout and "real time" in proc.stdout
    return out


@pytest.mark.parametrize("graph", [TOUCH, SLIP])
def test_graphs_validate(graph, capsys):
    assert main(["validate", graph]) == 0
    out = capsys.readouterr().out
    assert "ddforce: not started" in out


def test_recording_layout_and_provenance(touch_h5):
    with h5py.File(touch_h5, "r") as f:
        for name in ("force.f", "sa1.spikes", "fa1.spikes", "sensor.force"):
            assert f"streams/{name}/t" in f and f"streams/{name}/data" in f
        assert f["streams/force.f/data"].shape == (3000, 3)
        assert f["streams/force.f"].attrs["units"] == "N"
    rec = read_recording(touch_h5)
    assert rec.provenance["graph_seed"] == 7
    seeds = json.loads(rec.provenance["seeds"])
    assert set(seeds) >= {"sensor", "sa1", "fa1"}
    params = json.loads(rec.provenance["params"])
    assert params["dforce"]["window"] == 5 and params["dforce"]["order"] == 4
    assert "numpy" in json.loads(rec.provenance["versions"])
    t = rec.streams["sa1.spikes"].t
    assert len(t) > 0 and np.all(np.diff(t) >= 0)


def test_rerun_from_a_recording_is_identical(touch_h5, tmp_path):
    again = tmp_path / "again.h5"
    proc = flowtact("run", str(touch_h5), "--fast", "--duration", "3", "--record", str(again))
    assert proc.returncode == 0, proc.stderr
    a, b = read_recording(touch_h5), read_recording(again)
    for name in a.streams:
        assert np.array_equal(a.streams[name].t, b.streams[name].t)
        assert np.array_equal(a.streams[name].data, b.streams[name].data)


def test_replaying_the_sensor_reproduces_every_downstream_stream(touch_h5, tmp_path):
    out = tmp_path / "replayed.h5"
    proc = flowtact(
        "run", TOUCH, "--fast", "--duration", "3", "--replay", f"sensor={touch_h5}", "--record", str(out)
    )
    assert proc.returncode == 0, proc.stderr
    a, b = read_recording(touch_h5), read_recording(out)
    for name in ("force.f", "dforce.y", "sa1.spikes", "fa1.spikes"):
        assert np.array_equal(a.streams[name].t, b.streams[name].t), name
        assert np.array_equal(a.streams[name].data, b.streams[name].data), name
    assert np.array_equal(a.streams["sensor.r"].data, b.streams["sensor.r"].data)  # the names are kept
    assert set(b.streams) == set(a.streams)


def test_run_json_summary():
    proc = flowtact("run", SLIP, "--fast", "--duration", "1", "--json")
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert summary["duration_s"] == 1.0
    assert "ddforce" in summary["pruned"]
    assert summary["events"]["sa1.spikes"] > 0


def test_blocks_catalogue_and_one_block(capsys):
    assert main(["blocks"]) == 0
    out = capsys.readouterr().out
    for name in ("aunp_sensor", "gauge_force", "savgol", "weighted_sum", "nlif", "rate", "pulses", "replay"):
        assert name in out
    assert main(["blocks", "savgol"]) == 0
    out = capsys.readouterr().out
    assert "window" in out and "Parameters:" in out and "Inputs:" in out
    assert main(["blocks", "savgl"]) == 2
    assert "did you mean 'savgol'" in capsys.readouterr().err


def test_graph_drawing(tmp_path):
    for suffix in (".dot", ".svg", ".png"):
        out = tmp_path / f"touch{suffix}"
        assert main(["graph", TOUCH, "-o", str(out)]) == 0
        assert out.stat().st_size > 0
    dot = (tmp_path / "touch.dot").read_text()
    assert '"ddforce" [label="ddforce\\n(savgol)", style="rounded,dashed"' in dot


def test_plot(touch_h5, tmp_path):
    out = tmp_path / "fig.png"
    assert main(["plot", str(touch_h5), "-o", str(out)]) == 0
    assert out.stat().st_size > 10_000


def test_replaying_a_node_that_has_inputs_drops_them(touch_h5, tmp_path):
    out = tmp_path / "replayed_dforce.h5"
    proc = flowtact(
        "run", TOUCH, "--fast", "--duration", "3", "--replay", f"dforce={touch_h5}", "--record", str(out)
    )
    assert proc.returncode == 0, proc.stderr
    a, b = read_recording(touch_h5), read_recording(out)
    assert np.array_equal(a.streams["sa1.spikes"].data, b.streams["sa1.spikes"].data)
    assert np.array_equal(a.streams["dforce.y"].data, b.streams["dforce.y"].data)


def test_a_realtime_run_is_paced_by_the_wall_clock():
    proc = flowtact("run", SLIP, "--duration", "0.6", "--json")
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert summary["wall_s"] >= 0.6 and summary["realtime_factor"] <= 1.0


def wait_recorded(proc, path: Path, stream: str, n: int, timeout_s: float = 60.0) -> int:
    """Wait until the run ``proc``'s committed recording holds ``n`` samples of ``stream``; how many it holds.

    The recorder commits about once a second; start-up alone can take seconds on a busy machine, so
    this polls for the data instead of sleeping a fixed time.
    """
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        assert proc.poll() is None, f"the run ended early: {proc.communicate()[1]}"
        try:
            got = len(read_recording(path).streams[stream].t)
        except (OSError, KeyError):  # not created yet
            got = 0
        if got >= n:
            return got
        time.sleep(0.2)
    raise AssertionError(f"{path} held fewer than {n} samples of {stream} after {timeout_s:g} s")


def test_ctrl_c_stops_cleanly_and_keeps_the_recording(tmp_path):
    out = tmp_path / "interrupted.h5"
    proc = subprocess.Popen(
        [sys.executable, "-m", "flowtact.cli", "run", TOUCH, "--duration", "600", "--record", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        seen = wait_recorded(
            proc, out, "force.f", 500
        )  # running, with over half a second of 1 kHz samples kept
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, stderr
    assert "interrupted" in stdout
    rec = read_recording(out)
    n = len(rec.streams["force.f"].t)
    assert n >= seen >= 500  # nothing that was kept before the interrupt is lost
    assert rec.summary is not None and rec.summary["stopped_by"] == "interrupted"
    assert rec.summary["samples"]["force.f"] == n  # and the stop flushed every sample the run made


def test_bad_samples_stop_the_run_naming_the_node_and_keep_what_came_before(tmp_path):
    t = np.arange(2000) / 1000.0
    x = np.sin(t)
    x[1500] = np.nan
    np.savez(tmp_path / "log.npz", t=t, data=x)
    graph = tmp_path / "g.yaml"
    graph.write_text(
        "nodes:\n"
        f"  log: {{block: replay, params: {{path: '{tmp_path / 'log.npz'}', units: N}}}}\n"
        "  df:  {block: savgol, params: {deriv: 1}}\n"
        "edges:\n  - log.y -> df.x\n"
        "record: [log.y, df.y]\n"
    )
    out = tmp_path / "failed.h5"
    proc = flowtact("run", str(graph), "--fast", "--duration", "2", "--tick", "0.25", "--record", str(out))
    assert proc.returncode == 1
    assert "node 'df' (savgol) failed at t=1.750 s" in proc.stderr
    assert "non-finite sample(s) on input 'x', first at t=1.500000 s" in proc.stderr
    assert "Traceback" not in proc.stderr
    rec = read_recording(out)
    assert len(rec.streams["log.y"].t) >= 1500  # everything before the failing tick was kept


def test_bench_lists_the_suites_of_every_room_but_not_their_helpers(capsys, monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)  # suites come from entry points, not from a bench/ folder here
    assert main(["bench", "--list"]) == 0
    listed = {line.split()[0] for line in capsys.readouterr().out.splitlines()}
    assert {"savgol", "nlif", "ssim", "teleop", "force_estimation", "transport", "executor"} <= listed
    assert not listed & {"ezmsg_pipe", "timeflux_pipe", "raw", "measure", "transport_blocks", "_timing"}
