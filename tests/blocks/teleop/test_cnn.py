"""The CNN contact-force estimator: model, checkpoints, training recipe, the cnn_force block."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from flowtact import Chunk, SpecError, StreamSpec
from flowtact.blocks.teleop.cnn import (
    ARCHS,
    Arch,
    CnnForce,
    Preprocess,
    build_model,
    load_checkpoint,
    n_parameters,
    read_meta,
    save_checkpoint,
    shipped_checkpoint,
)
from flowtact.blocks.teleop.hand import FINGERS
from flowtact.blocks.teleop.train_force import (
    DEFAULT_CROP,
    Dataset,
    TrainConfig,
    load_dataset,
    main,
    split_indices,
    train_on_arrays,
)
from flowtact.recording.hdf5 import Recorder
from flowtact.testing import run_offline

torch = pytest.importorskip("torch")

TINY = Arch(n_conv=2, width=8, fc=16)


def _tiny_checkpoint(tmp_path, *, input_hw=(24, 48), crop=None, label_mean=1.0, label_std=0.5, seed=0):
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        model = build_model(TINY, Preprocess(input_hw, crop, 1), pixel_mean=0.2, pixel_std=0.3)
    return save_checkpoint(
        tmp_path / "tiny.pt", model, {"label_mean_n": label_mean, "label_std_n": label_std, "note": "tiny"}
    )


def _synthetic(n=600, hw=(24, 48), seed=0):
    """Frames (n, 3, H, W) whose bright square grows with the force (n, 3): a learnable feature."""
    rng = np.random.default_rng(seed)
    force = rng.uniform(0.0, 4.0, (n, 3))
    frames = rng.integers(0, 30, (n, 3, *hw)).astype(np.uint8)
    for i in range(n):
        for s in range(3):
            half = 1 + round(float(force[i, s]) * 2.5)
            cy, cx = hw[0] // 2 + rng.integers(-2, 3), hw[1] // 2 + rng.integers(-8, 9)
            frames[i, s, cy - half : cy + half, cx - half : cx + half] = 200
    return frames, force


# -- import hygiene --------------------------------------------------------------------------------------


def test_importing_the_modules_does_not_import_torch():
    code = (
        "import sys, flowtact.blocks.teleop.cnn, flowtact.blocks.teleop.train_force\n"
        "from flowtact.blocks.teleop.cnn import CnnForce\n"
        "CnnForce.example()\n"
        "assert 'torch' not in sys.modules, 'torch imported'\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=300)  # a hang guard: 10 s when loaded


def test_train_force_without_torch_says_how_to_install(monkeypatch, capsys, tmp_path):
    monkeypatch.setitem(sys.modules, "torch", None)  # makes `import torch` raise ImportError
    assert main([str(tmp_path / "x.h5")]) == 1
    assert "pip install 'flowtact[cnn]'" in capsys.readouterr().err


# -- the model --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", list(ARCHS))
def test_model_shapes(name):
    pre = Preprocess((240, 320), DEFAULT_CROP, 2)
    model = build_model(name, pre).eval()
    frames = torch.randint(0, 255, (3, 240, 320), dtype=torch.uint8)
    with torch.inference_mode():
        x = model.preprocess(frames)
        assert tuple(x.shape) == (3, 1, 45, 120)
        assert tuple(model(x).shape) == (3,)
        crops = frames[:, 75:165, 40:280]
        assert torch.equal(model.predict(crops, cropped=True), model.predict(frames))
    convs = [m for m in model.modules() if isinstance(m, torch.nn.Conv2d)]
    norms = [m for m in model.modules() if isinstance(m, torch.nn.BatchNorm2d)]
    linears = [m for m in model.modules() if isinstance(m, torch.nn.Linear)]
    arch = ARCHS[name]
    assert len(convs) == len(norms) == arch.n_conv
    assert all(c.out_channels == arch.width for c in convs)
    assert linears[0].out_features == arch.fc and linears[-1].out_features == 1


def test_paper_configuration_is_the_thesis_network():
    assert ARCHS["paper"] == Arch(n_conv=4, width=256, fc=128, kernel=3, batch_norm=True)
    sizes = [
        n_parameters(build_model(a, Preprocess((90, 240), None, 2)))
        for a in ("w8", "w16", "w32", "w64", "paper")
    ]
    assert sizes == sorted(sizes)


def test_too_small_input_for_the_depth_is_refused():
    with pytest.raises(ValueError, match="larger input"):
        build_model("w8", Preprocess((12, 12), None, 1))


# -- checkpoints --------------------------------------------------------------------------------------------


def test_checkpoint_round_trip(tmp_path):
    path = _tiny_checkpoint(tmp_path, crop=(4, 2, 40, 20), input_hw=(24, 48))
    model, meta = load_checkpoint(path)
    side = json.loads(path.with_suffix(".json").read_text())
    assert meta == side == read_meta(path)
    assert meta["note"] == "tiny" and meta["label_mean_n"] == 1.0
    assert meta["preprocess"] == {"input_hw": [24, 48], "crop": [4, 2, 40, 20], "downsample": 1}
    assert meta["arch"] == {"n_conv": 2, "width": 8, "fc": 16, "kernel": 3, "batch_norm": True}
    again, _ = load_checkpoint(path)
    frames = torch.from_numpy(np.random.default_rng(0).integers(0, 255, (3, 24, 48), dtype=np.uint8))
    with torch.inference_mode():
        assert torch.equal(model.predict(frames), again.predict(frames))
    assert not model.training
    (tmp_path / "tiny.json").unlink()  # without the sidecar, the .pt alone gives the metadata
    assert read_meta(path) == meta


def test_checkpoint_needs_label_standardisation(tmp_path):
    model = build_model(TINY, Preprocess((24, 48)))
    with pytest.raises(ValueError, match="label_mean_n"):
        save_checkpoint(tmp_path / "m.pt", model, {"label_std_n": 1.0})


# -- the block ----------------------------------------------------------------------------------------------


def test_wrong_frame_size_is_a_clear_spec_error(tmp_path):
    path = _tiny_checkpoint(tmp_path, input_hw=(24, 48))
    frames = np.zeros((4, 3, 240, 320), np.uint8)
    with pytest.raises(SpecError, match=r"240×320 but checkpoint tiny.pt was trained on 24×48"):
        run_offline(CnnForce(checkpoint=str(path)), x=frames, rate_hz=40.0, units={"x": "DN"})
    with pytest.raises(SpecError, match="uint8"):
        run_offline(
            CnnForce(checkpoint=str(path)), x=frames[:, :, :24, :48].astype(np.float64), units={"x": "DN"}
        )
    with pytest.raises(SpecError, match="DN"):
        run_offline(CnnForce(checkpoint=str(path)), x=frames[:, :, :24, :48], units={"x": "1"})
    with pytest.raises(SpecError, match="not found"):
        CnnForce(checkpoint=str(tmp_path / "missing.pt")).specs(
            {"x": StreamSpec("uint8", (3, 24, 48), "DN", 40.0)}
        )


def test_block_matches_the_model_and_clips_negative_forces(tmp_path):
    frames, _ = _synthetic(12)
    model, _ = load_checkpoint(_tiny_checkpoint(tmp_path))
    with torch.inference_mode():
        z = np.stack([model.predict(torch.from_numpy(f)).numpy() for f in frames]).astype(np.float64)
    mean = -2.0 * float(np.median(z))  # the same weights, de-standardised to straddle 0 N
    path = _tiny_checkpoint(tmp_path, label_mean=mean, label_std=2.0)
    want = z * 2.0 + mean
    raw = run_offline(
        CnnForce(checkpoint=str(path), clip_negative=False), x=frames, rate_hz=40.0, units={"x": "DN"}
    )
    np.testing.assert_array_equal(raw["y"].data, want)
    assert (want < 0).any() and (want > 0).any()
    clipped = run_offline(CnnForce(checkpoint=str(path)), x=frames, rate_hz=40.0, units={"x": "DN"})
    np.testing.assert_array_equal(clipped["y"].data, np.maximum(want, 0.0))
    assert raw["y"].t.tolist() == (np.arange(12) / 40.0).tolist()


def test_output_spec_and_watermark(tmp_path):
    path = _tiny_checkpoint(tmp_path)
    block = CnnForce(checkpoint=str(path))
    out = block.bind({"x": StreamSpec("uint8", (3, 24, 48), "DN", 40.0)})
    assert out["y"] == StreamSpec("float64", (3,), "N", 40.0, labels=("thumb", "index", "middle"))
    frames, _ = _synthetic(2)
    y = block(x=Chunk(np.array([0.0, 0.025]), frames, end=0.05))["y"]
    assert y.data.shape == (2, 3) and y.end == 0.05
    empty = block(x=Chunk(np.empty(0), np.empty((0, 3, 24, 48), np.uint8), end=0.1))["y"]
    assert len(empty) == 0 and empty.data.shape == (0, 3) and empty.end == 0.1


def test_one_call_per_frame_makes_chunking_irrelevant(tmp_path):
    path = _tiny_checkpoint(tmp_path)
    frames, _ = _synthetic(20)
    whole = run_offline(CnnForce(checkpoint=str(path)), x=frames, rate_hz=40.0, units={"x": "DN"})
    for chunk in (1, 7, [3, 11, 1]):
        part = run_offline(
            CnnForce(checkpoint=str(path)), x=frames, chunk=chunk, rate_hz=40.0, units={"x": "DN"}
        )
        np.testing.assert_array_equal(part["y"].data, whole["y"].data)


def test_shipped_checkpoint_estimates_tactip_sim_forces():
    sim = pytest.importorskip("flowtact.blocks.teleop.tactip_sim")
    path = shipped_checkpoint()
    assert path.exists() and path.stat().st_size < 1_000_000
    meta = read_meta(path)
    assert meta["preprocess"]["input_hw"] == [240, 320] and meta["test_mae_n"]["combined"] < 0.3
    rng = np.random.default_rng(5)
    force = np.concatenate([np.zeros((2, 3)), rng.uniform(0.5, 5.0, (10, 3))])
    pos = rng.uniform(-3.0, 3.0, (12, 3, 2))
    frames = sim.render(force, pos, np.arange(12), seed=99)
    out = run_offline(CnnForce(), x=frames, rate_hz=40.0, units={"x": "DN"})
    y = out["y"].data
    assert np.isfinite(y).all() and (y >= 0).all()
    assert np.mean(np.abs(y - force)) < 0.5, np.abs(y - force)
    cropped = run_offline(
        CnnForce(), x=np.ascontiguousarray(frames[:, :, 75:165, 40:280]), rate_hz=40.0, units={"x": "DN"}
    )
    np.testing.assert_array_equal(cropped["y"].data, y)


# -- training -------------------------------------------------------------------------------------------------


def test_split_is_90_5_5_disjoint_and_seeded():
    train, val, test = split_indices(1000, seed=3)
    assert (len(train), len(val), len(test)) == (900, 50, 50)
    assert np.array_equal(np.sort(np.concatenate([train, val, test])), np.arange(1000))
    again = split_indices(1000, seed=3)
    assert all(np.array_equal(a, b) for a, b in zip(again, (train, val, test), strict=True))
    assert not np.array_equal(split_indices(1000, seed=4)[2], test)


def test_training_learns_a_simple_image_feature():
    frames, force = _synthetic(600)
    data = Dataset.from_frames(frames, force)
    cfg = TrainConfig(arch=TINY, crop=None, downsample=1, max_epochs=20, patience=8, l2=1e-4, threads=1)
    _, rep = train_on_arrays(data, cfg, seed=0, progress=False)
    assert (rep["n_train"], rep["n_val"], rep["n_test"]) == (1620, 90, 90)
    std = float(np.std(force))
    assert rep["test_mae_n"]["combined"] < 0.15 * std, (rep["test_mae_n"], std)
    assert set(rep["test_mae_n"]) == {"combined", "thumb", "index", "middle"}
    assert abs(rep["label_mean_n"] - 2.0) < 0.2 and abs(rep["label_std_n"] - std) < 0.2
    # a model that only learnt the mean would score about 0.87 std; the history must go down
    assert rep["history"]["val_mse"][rep["best_epoch"] - 1] < 0.1 * rep["history"]["val_mse"][0]


def test_training_is_deterministic_for_a_seed():
    frames, force = _synthetic(150)
    data = Dataset.from_frames(frames, force)
    cfg = TrainConfig(arch=TINY, crop=None, downsample=1, max_epochs=3, threads=1)
    m1, r1 = train_on_arrays(data, cfg, seed=1, progress=False)
    m2, r2 = train_on_arrays(data, cfg, seed=1, progress=False)
    assert r1["history"] == r2["history"] and r1["test_mae_n"] == r2["test_mae_n"]
    for (k, a), b in zip(m1.state_dict().items(), m2.state_dict().values(), strict=True):
        assert torch.equal(a, b), k
    _, r3 = train_on_arrays(data, cfg, seed=2, progress=False)
    assert r3["history"] != r1["history"]


def _write_recording(path, frames, force, t_force=None):
    n = len(frames)
    t = np.arange(n) / 40.0
    specs = {
        "sim.frames": StreamSpec("uint8", frames.shape[1:], "DN", 40.0),
        "sim.force": StreamSpec("float64", (3,), "N", 40.0),
    }
    with Recorder(
        path, specs, {"graph_name": "tiny", "graph_yaml": "name: tiny\n", "command": "test"}
    ) as rec:
        rec.write("sim.frames", Chunk(t, frames))
        rec.write("sim.force", Chunk(t if t_force is None else t_force, force))


def test_recordings_are_paired_by_time(tmp_path):
    frames, force = _synthetic(40)
    _write_recording(tmp_path / "a.h5", frames, force)
    data = load_dataset([tmp_path / "a.h5"], crop=(8, 4, 32, 16))
    assert data.images.shape == (120, 16, 32) and data.input_hw == (24, 48)
    np.testing.assert_array_equal(data.images[:40], frames[:, 0, 4:20, 8:40])
    np.testing.assert_array_equal(data.force_n, force.T.ravel())
    assert data.sources[0]["graph"] == "tiny" and data.sources[0]["pairing"] == "same time stamps"
    # force sampled at other times: interpolated at the frame times, frames outside dropped
    t_force = np.arange(40) / 40.0 + 0.0125
    _write_recording(tmp_path / "b.h5", frames, force, t_force=t_force)
    data = load_dataset([tmp_path / "b.h5"], crop="auto")
    assert data.sources[0]["pairing"] == "force interpolated at frame times"
    assert len(data) == 3 * 39 and data.crop is None
    np.testing.assert_allclose(data.force_n[:39], 0.5 * (force[:-1, 0] + force[1:, 0]))
    with pytest.raises(KeyError, match=r"no stream 'cam\.frames'"):
        load_dataset([tmp_path / "a.h5"], frames_stream="cam.frames")


def test_train_force_cli_writes_a_checkpoint_the_block_runs(tmp_path, capsys):
    frames, force = _synthetic(60, hw=(32, 64))
    rec = tmp_path / "rec.h5"
    _write_recording(rec, frames, force)
    out = tmp_path / "model.pt"
    argv = [
        str(rec),
        "--arch",
        "w8",
        "--epochs",
        "2",
        "--crop",
        "none",
        "--downsample",
        "1",
        "--out",
        str(out),
    ]
    assert main([*argv, "--no-progress", "--threads", "1", "--heldout", str(rec)]) == 0
    text = capsys.readouterr().out
    assert "test MAE" in text and "held-out MAE" in text and "model.pt" in text
    meta = read_meta(out)
    assert meta["command"].startswith("flowtact train-force") and meta["epochs"] == 2
    assert meta["sources"][0]["command"] == "test" and meta["train_config"]["arch"] == "w8"
    assert (meta["n_train"], meta["n_val"], meta["n_test"]) == (162, 9, 9)
    assert meta["heldout"]["samples"] == 180 and set(meta["heldout"]["mae_n"]) == {"combined", *FINGERS}
    y = run_offline(CnnForce(checkpoint=str(out)), x=frames[:5], rate_hz=40.0, units={"x": "DN"})["y"]
    assert y.data.shape == (5, 3) and np.isfinite(y.data).all()
    assert main([str(rec), "--frames-stream", "nope.frames", "--out", str(out), "--no-progress"]) == 2
    assert "no stream 'nope.frames'" in capsys.readouterr().err
