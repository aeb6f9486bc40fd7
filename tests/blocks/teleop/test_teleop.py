"""graphs/teleop.yaml end to end: emulated TacTips and exoskeleton, forces, poses and servo commands.

One real-time run goes through the real serial path (`flowtact sim exo` on a pseudo-terminal and
three worker processes); the Fig. 4.6 check uses the same exoskeleton model behind `port: sim`
on the virtual clock, so it is deterministic.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from flowtact.recording.hdf5 import read_recording
from flowtact.running.launch import load_compiled, run_compiled

ROOT = Path(__file__).resolve().parents[3]
TELEOP = ROOT / "graphs" / "teleop.yaml"
pytestmark = pytest.mark.slow

LIMITS_US = (-300.0, 600.0)  # force_feedback's defaults, which teleop.yaml keeps


def _check_commands(cmd: np.ndarray) -> None:
    assert np.isfinite(cmd).all()
    assert set(np.unique(cmd[:, :, 0])) <= {0.0, 1.0}
    assert cmd[:, :, 1].min() >= LIMITS_US[0] and cmd[:, :, 1].max() <= LIMITS_US[1]
    assert (cmd[cmd[:, :, 0] == 0][:, 1] == 0).all()  # a released servo gets no deviation


@pytest.fixture(scope="module")
def realtime_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("teleop") / "teleop.h5"
    cmd = [sys.executable, "-m", "flowtact.cli", "run", str(TELEOP), "--duration", "10"]
    p = subprocess.run(
        [*cmd, "--record", str(out), "--json", "--quiet"], capture_output=True, text=True, timeout=120
    )
    return p, out


def test_the_default_teleop_graph_runs_for_real_and_records_forces_poses_and_commands(realtime_run):
    p, out = realtime_run
    assert p.returncode == 0, p.stderr
    summary = json.loads(p.stdout)
    assert set(summary["processes"]) == {"exo", "remote", "vision"}
    assert summary["counters"]["exo"]["packets"] >= 900  # 100 Hz from the emulator on the pty
    rec = read_recording(out)
    s = rec.streams
    for name in ("exo.angles", "exo.fsr", "finger.f", "gripper.force", "ssim.y", "force.y", "control.cmd"):
        assert len(s[name].t) > 0, name
    assert len(s["ssim.y"].t) >= 380  # 3 TacTips at 40 FPS for 10 s
    phi1 = s["exo.angles"].data[:, :, 0]
    assert np.ptp(phi1, axis=0).min() > 0.5  # every finger opened and closed
    assert s["gripper.force"].data.max() > 1.0  # the gripper squeezed the objects
    # the SSIM estimate follows the true contact force
    truth = s["gripper.force"]
    est = s["force.y"]
    idx = np.clip(np.searchsorted(truth.t, est.t) - 1, 0, len(truth.t) - 1)
    assert np.corrcoef(truth.data[idx].ravel(), est.data.ravel())[0, 1] > 0.9
    cmd = s["control.cmd"].data
    _check_commands(cmd)
    assert (cmd[:, :, 0] == 1).any(axis=0).all()  # every finger engaged at some point
    assert (s["exo.engaged"].data == 1).any()  # and the device said so over the serial line
    path = summary["paths"]["cams -> exo"]
    assert path["n"] >= 300 and np.isfinite(path["p99_us"])


def _deviation_spread(rec) -> dict[int, float]:
    """5th–95th percentile range of the engaged servo deviations, per object (0 soft, 1 firm)."""
    cmd, obj = rec.streams["control.cmd"].data, rec.streams["gripper.object"].data
    spread = {}
    for o in (0, 1):
        d = cmd[obj == o][:, :, 1][cmd[obj == o][:, :, 0] == 1]
        assert len(d) > 300
        spread[o] = float(np.ptp(np.percentile(d, [5, 95])))
    return spread


@pytest.mark.parametrize("seed", [4, 9])
def test_a_soft_object_lets_the_fingers_deviate_more_than_a_firm_one(tmp_path, seed):
    """White 2023 Fig. 4.6: the strawberry gives a much wider spread of servo deviations than the bottle."""
    graph = tmp_path / "teleop.yaml"
    graph.write_text(TELEOP.read_text().replace("\nseed: 4\n", f"\nseed: {seed}\n"))
    plan = load_compiled(graph, overrides=["exo.port=sim"])
    run_compiled(plan, duration_s=20.0, fast=True, inproc=True, record=tmp_path / "t.h5")
    rec = read_recording(tmp_path / "t.h5")
    _check_commands(rec.streams["control.cmd"].data)
    spread = _deviation_spread(rec)
    assert spread[0] > 1.4 * spread[1], spread


def test_the_ssim_graph_never_imports_torch():
    code = (
        "import sys\n"
        "from flowtact.running.launch import load_compiled, run_compiled\n"
        f"plan = load_compiled({str(TELEOP)!r}, overrides=['exo.port=sim'])\n"
        "run_compiled(plan, duration_s=1.0, fast=True, inproc=True)\n"
        "assert 'torch' not in sys.modules, 'torch was imported'\n"
        "print('ok')\n"
    )
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0 and p.stdout.strip() == "ok", p.stderr


def test_the_cnn_graph_runs_out_of_the_box_with_the_shipped_checkpoint(tmp_path):
    pytest.importorskip("torch")  # the cnn extra; the README's dev install includes it
    plan = load_compiled(ROOT / "graphs" / "teleop_cnn.yaml", overrides=["exo.port=sim"])
    run_compiled(plan, duration_s=4.0, fast=True, inproc=True, record=tmp_path / "c.h5")
    s = read_recording(tmp_path / "c.h5").streams
    truth, est = s["gripper.force"], s["cnn.y"]
    idx = np.clip(np.searchsorted(truth.t, est.t) - 1, 0, None)
    assert len(est.t) >= 150 and np.abs(truth.data[idx] - est.data).mean() < 0.3
    _check_commands(s["control.cmd"].data)


def test_the_training_set_graph_records_frames_with_their_true_force(tmp_path):
    plan = load_compiled(ROOT / "graphs" / "tactip_dataset.yaml")
    run_compiled(plan, duration_s=2.0, fast=True, inproc=True, record=tmp_path / "d.h5")
    s = read_recording(tmp_path / "d.h5").streams
    assert s["sim.frames"].data.shape == (80, 3, 240, 320) and s["sim.frames"].data.dtype == np.uint8
    assert np.array_equal(s["sim.force"].t, s["sim.frames"].t) and s["sim.force"].data.max() > 0.3
