"""Ctrl-C in ``flowtact train-force`` saves the best model so far and exits 0; a second Ctrl-C aborts."""

import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from flowtact import Chunk, StreamSpec
from flowtact.blocks.teleop.cnn import CnnForce, load_checkpoint, read_meta
from flowtact.blocks.teleop.train_force import StopOnInterrupt, TrainConfig, TrainingInterrupted, train_force
from flowtact.recording.hdf5 import Recorder, read_recording
from flowtact.testing import run_offline

pytest.importorskip("torch")


def _recording(path, n=60, hw=(32, 64), seed=0):
    """Frames whose bright square grows with the force: a small learnable training set."""
    rng = np.random.default_rng(seed)
    force = rng.uniform(0.0, 4.0, (n, 3))
    frames = rng.integers(0, 30, (n, 3, *hw)).astype(np.uint8)
    for i in range(n):
        for s in range(3):
            half = 1 + round(float(force[i, s]) * 2.5)
            frames[i, s, hw[0] // 2 - half : hw[0] // 2 + half, hw[1] // 2 - half : hw[1] // 2 + half] = 200
    t = np.arange(n) / 40.0
    specs = {
        "sim.frames": StreamSpec("uint8", frames.shape[1:], "DN", 40.0),
        "sim.force": StreamSpec("float64", (3,), "N", 40.0),
    }
    with Recorder(
        path, specs, {"graph_name": "tiny", "graph_yaml": "name: tiny\n", "command": "test"}
    ) as rec:
        rec.write("sim.frames", Chunk(t, frames))
        rec.write("sim.force", Chunk(t, force))
    return path


def _wait_for(stream, text, timeout=180.0):
    """``(lines, reader)``: lines read from ``stream`` by the ``reader`` thread, which goes on to the
    end of the stream; returns once a line contains ``text``. Join the reader for every line."""
    lines: list[str] = []
    found = threading.Event()

    def read():
        for line in stream:
            lines.append(line)
            if text in line:
                found.set()
        found.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    assert found.wait(timeout), f"no line with {text!r} within {timeout} s"
    return lines, reader


@pytest.mark.cli
def test_ctrl_c_saves_the_best_model_so_far_and_exits_0(tmp_path):
    rec = _recording(tmp_path / "rec.h5")
    out = tmp_path / "model.pt"
    argv = [str(rec), "--arch", "w8", "--epochs", "400", "--patience", "400", "--crop", "none"]
    argv += ["--downsample", "1", "--threads", "1", "--out", str(out)]
    proc = subprocess.Popen(
        [sys.executable, "-m", "flowtact.cli", "train-force", *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        lines, reader = _wait_for(proc.stderr, "epoch 1:")  # the first epoch is done and reported
        assert proc.poll() is None, "".join(lines)
        proc.send_signal(signal.SIGINT)
        stdout = proc.stdout.read()  # to its end: the process has exited (its stdout is small)
        proc.wait(timeout=180)
        reader.join(timeout=60)  # stderr is the reader's alone (communicate would race it for lines)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.stdout.close()
        proc.stderr.close()
    stderr = "".join(lines)
    assert proc.returncode == 0, stderr
    assert "Traceback" not in stderr and "stopping after this batch" in stderr
    meta = read_meta(out)
    k = meta["interrupted_at_epoch"]
    assert meta["stopped"] == "interrupted" and k >= 2 and meta["epochs"] == k - 1 < 400
    assert 1 <= meta["best_epoch"] <= meta["epochs"]
    assert (
        f"interrupted at epoch {k}: saved the best model so far (epoch {meta['best_epoch']}) to {out}"
        in stdout
    )
    _, embedded = load_checkpoint(out)  # loadable, in the normal format, same provenance inside
    assert embedded["stopped"] == "interrupted" and embedded["interrupted_at_epoch"] == k
    frames = read_recording(rec).streams["sim.frames"].data[:5]
    y = run_offline(CnnForce(checkpoint=str(out)), x=frames, rate_hz=40.0, units={"x": "DN"})["y"]
    assert y.data.shape == (5, 3) and np.isfinite(y.data).all()  # the cnn_force block runs it


def test_a_stop_before_the_first_epoch_ends_saves_nothing(tmp_path):
    rec = _recording(tmp_path / "rec.h5")
    config = TrainConfig(arch="w8", crop=None, downsample=1, max_epochs=5, threads=1)
    with pytest.raises(TrainingInterrupted, match="before the first epoch finished"):
        train_force([rec], config=config, out=tmp_path / "m.pt", progress=False, stop=lambda: True)
    assert not (tmp_path / "m.pt").exists()


def test_the_second_interrupt_aborts():
    before = signal.getsignal(signal.SIGINT)  # another library (Brian2) may have installed its own
    with StopOnInterrupt() as stop:
        signal.raise_signal(signal.SIGINT)
        time.sleep(0)  # the handler runs between bytecodes
        assert stop.requested()
        with pytest.raises(KeyboardInterrupt, match="interrupted twice"):
            signal.raise_signal(signal.SIGINT)
            time.sleep(0)
    assert signal.getsignal(signal.SIGINT) is before  # the previous handler is back
