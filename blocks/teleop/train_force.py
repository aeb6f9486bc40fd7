"""Train the contact-force CNN on recorded (frame, force) pairs: ``flowtact train-force``.

The recipe of White 2023 (§3.1.3): force labels standardised (zero mean, unit variance, from the
training split), a random 90/5/5 train/validation/test split (seeded), Adam, MSE loss plus l1 and
l2 penalties on the conv and dense weights (1e-4 and 1e-2 in the thesis), batch norm after every
convolution, early stopping on the validation loss, at most 400 epochs, mini-batches. By default
the three sensors are pooled (the thesis's "combined" network): every sensor image of every frame is
one sample labelled with that sensor's force.

Data: any flowtact recording with a uint8 frame stream (n, S, H, W) in "DN" and a force stream
(n, S) in "N" — ``flowtact run graphs/tactip_dataset.yaml --fast --record data.h5`` makes one from
the emulated TacTips. When the two streams have the same time stamps they are paired sample by
sample; otherwise the force is linearly interpolated at each frame time (frames outside the force
record are dropped).

torch is imported inside the functions (``import flowtact.blocks.teleop.train_force`` stays torch-free).
"""

from __future__ import annotations

import argparse
import copy
import datetime as _dt
import json
import math
import signal
import sys
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

import flowtact.api as ft
from flowtact.commands import Command
from flowtact.console.command import CommandParser, run_command
from flowtact.console.terminal_bar import TerminalBar
from flowtact.errors import UsageError
from flowtact.inputs.limits import cli_float, cli_int

from .cnn import ARCHS, TORCH_HINT, Arch, Preprocess, build_model, import_torch, n_parameters, save_checkpoint
from .hand import FINGERS

__all__ = [
    "COMMAND",
    "DEFAULT_CROP",
    "Dataset",
    "StopOnInterrupt",
    "TrainConfig",
    "TrainingInterrupted",
    "evaluate",
    "load_dataset",
    "main",
    "split_indices",
    "train_force",
    "train_on_arrays",
]

#: Default crop (x0, y0, w, h) of a 320×240 TacTip frame: the central 240×90 band (the thesis's 90×240 crop).
DEFAULT_CROP = (40, 75, 240, 90)
#: Frame size the default crop applies to (H, W).
DEFAULT_FRAME_HW = (240, 320)


class TrainingInterrupted(KeyboardInterrupt):
    """Training was stopped before it had a model worth saving."""


@dataclass(frozen=True)
class TrainConfig:
    """Training options (defaults: the thesis's recipe, on a small network at quarter resolution).

    ``crop``: (x0, y0, w, h), None (whole frame) or "auto" (:data:`DEFAULT_CROP` on 240×320 frames,
    else the whole frame). ``downsample``: average-pooling factor after the crop. The thesis fed
    whole 90×240 crops to its network on a GPU; on a CPU, 4 (a 22×60 input) trains w16 at ≈ 2.5 s
    per epoch of 8 100 images on one core, 2 (45×120) at ≈ 10 s, 1 at over a minute. On tactip_sim data
    w16 reached a held-out MAE of 0.080 N at 4 (100 epochs, 4 min) and 0.073 N at 2 (60 epochs,
    10 min): the fine detail buys little there.
    ``l2`` 1e-2 is the thesis's value; it is applied, like a Keras ``kernel_regularizer``, to the
    SUM of squared conv and dense weights and added to the mean squared error of standardised labels.
    Batch norm makes the conv weights scale-free, so there it only shrinks them; on the dense layers it
    regularises. It is sane for the small nets too: w8 with l2 1e-2 vs 1e-4 reached held-out MAEs of
    0.105 and 0.120 N (same seed, constant learning rate).
    ``time_limit_s`` stops training early (wall clock: the result then depends on the machine's speed).
    ``threads``: torch intra-op threads while training (None: torch's default, one per core). One
    is the default: a small network on 64-image batches gains little from more, and on a busy
    machine two threads measured 2.5× SLOWER than one (the result depends on the thread count).
    ``lr_plateau``: halve the learning rate after this many epochs without a better validation loss
    (None: a constant rate). The thesis names no schedule; on tactip_sim data a constant 1e-3 left
    the validation loss jumping by 10× from epoch to epoch, and halving on a 5-epoch plateau
    brought the held-out MAE of w8 from 0.105 to 0.084 N (same seed and budget).
    """

    arch: str | Arch = "w16"
    crop: tuple[int, int, int, int] | str | None = "auto"
    downsample: int = 4
    max_epochs: int = 400
    patience: int = 20
    batch_size: int = 64
    lr: float = 1e-3
    l1: float = 1e-4
    l2: float = 1e-2
    split: tuple[float, float, float] = (0.90, 0.05, 0.05)
    sensors: tuple[int, ...] | None = None
    threads: int | None = 1
    time_limit_s: float | None = None
    lr_plateau: int | None = 5

    def __post_init__(self) -> None:
        if isinstance(self.arch, str) and self.arch not in ARCHS:
            raise ValueError(f"unknown arch {self.arch!r} (valid: {', '.join(ARCHS)})")
        if self.max_epochs < 1 or self.patience < 1 or self.batch_size < 2 or self.downsample < 1:
            raise ValueError("max_epochs and patience must be >= 1, batch_size >= 2, downsample >= 1")
        if self.lr <= 0 or self.l1 < 0 or self.l2 < 0:
            raise ValueError("lr must be > 0 and l1, l2 >= 0")
        if len(self.split) != 3 or min(self.split) <= 0 or not math.isclose(sum(self.split), 1.0):
            raise ValueError(f"split must be three positive fractions summing to 1; got {self.split}")
        if isinstance(self.crop, str) and self.crop != "auto":
            raise ValueError(f"crop must be (x0, y0, w, h), None or 'auto'; got {self.crop!r}")

    @property
    def arch_spec(self) -> Arch:
        return ARCHS[self.arch] if isinstance(self.arch, str) else self.arch

    @property
    def arch_name(self) -> str:
        return self.arch if isinstance(self.arch, str) else "custom"

    def resolve_crop(self, frame_hw: tuple[int, int]) -> tuple[int, int, int, int] | None:
        """The crop window for frames of this size."""
        if self.crop == "auto":
            return DEFAULT_CROP if tuple(frame_hw) == DEFAULT_FRAME_HW else None
        return self.crop  # type: ignore[return-value]


@dataclass
class Dataset:
    """Training pairs: cropped uint8 ``images`` (N, h, w), ``force_n`` (N,), ``sensor`` index (N,)."""

    images: np.ndarray
    force_n: np.ndarray
    sensor: np.ndarray
    input_hw: tuple[int, int]
    crop: tuple[int, int, int, int] | None
    n_sensors: int
    sources: list[dict[str, Any]] = field(default_factory=list)

    def __len__(self) -> int:
        return int(self.force_n.shape[0])

    @classmethod
    def from_frames(
        cls,
        frames: np.ndarray,
        force_n: np.ndarray,
        *,
        crop: tuple[int, int, int, int] | None = None,
        sensors: Sequence[int] | None = None,
        sources: list[dict[str, Any]] | None = None,
        input_hw: tuple[int, int] | None = None,
    ) -> Dataset:
        """Pool frames (n, S, H, W) and forces (n, S) into one sample per sensor image.

        ``frames`` may already be cropped (then give ``input_hw``, the size before the crop).
        """
        frames = np.asarray(frames)
        force_n = np.asarray(force_n, np.float64)
        if frames.ndim != 4 or frames.dtype != np.uint8:
            raise ValueError(f"frames must be uint8 (n, sensors, H, W); got {frames.dtype} {frames.shape}")
        n, s = frames.shape[:2]
        if force_n.shape != (n, s):
            raise ValueError(f"force must be (n, sensors) = {(n, s)}; got {force_n.shape}")
        hw = tuple(frames.shape[2:]) if input_hw is None else tuple(input_hw)
        if input_hw is None and crop is not None:
            frames = Preprocess(hw, crop).crop_array(frames)  # type: ignore[arg-type]
        use = list(range(s)) if sensors is None else [int(i) for i in sensors]
        for i in use:
            if not 0 <= i < s:
                raise ValueError(f"sensor index {i} out of range for {s} sensors")
        ok = np.isfinite(force_n)
        imgs, forces, sens = [], [], []
        for i in use:
            keep = ok[:, i]
            imgs.append(frames[keep, i])
            forces.append(force_n[keep, i])
            sens.append(np.full(int(keep.sum()), i, np.int64))
        return cls(
            np.ascontiguousarray(np.concatenate(imgs)),
            np.concatenate(forces),
            np.concatenate(sens),
            hw,  # type: ignore[arg-type]
            crop,
            s,
            list(sources or []),
        )


# -- data ---------------------------------------------------------------------------------------------


def _provenance(path: Path) -> dict[str, Any]:
    """The recording's command, graph seed, creation time, flowtact version and graph name (those it has)."""
    from flowtact.recording.hdf5 import read_recording

    bundle = read_recording(path, streams=()).provenance
    out = {
        key: bundle[key]
        for key in ("command", "graph_seed", "created_utc", "flowtact_version")
        if key in bundle
    }
    if "graph_name" in bundle:
        out["graph"] = bundle["graph_name"]
    return out


def load_recording_pairs(
    path: str | Path,
    frames_stream: str = "sim.frames",
    force_stream: str = "sim.force",
    crop: tuple[int, int, int, int] | str | None = "auto",
    *,
    block_frames: int = 256,
) -> tuple[np.ndarray, np.ndarray, tuple[int, int], tuple[int, int, int, int] | None, dict[str, Any]]:
    """``(cropped frames (n, S, h, w) uint8, force (n, S) N, frame (H, W), crop, info)`` from a recording.

    Frames are read and cropped slice by slice, so the whole-frame stream never sits in memory.
    """
    from flowtact.recording.hdf5 import open_verified, stream_specs

    path = Path(path)
    specs = stream_specs(path)
    for name in (frames_stream, force_stream):
        if name not in specs:
            raise KeyError(f"{path}: no stream '{name}' (available: {', '.join(specs) or 'none'})")
    fspec, _ = specs[frames_stream]
    pspec, _ = specs[force_stream]
    if fspec.dtype != "uint8" or len(fspec.shape) != 3:
        raise ValueError(
            f"{path}: '{frames_stream}' must be uint8 frames (S, H, W); it is {fspec.describe()}"
        )
    if pspec.units != "N" or pspec.shape != fspec.shape[:1]:
        raise ValueError(
            f"{path}: '{force_stream}' must be a force in N of shape ({fspec.shape[0]},) to pair with "
            f"'{frames_stream}'; it is {pspec.describe()}"
        )
    hw = (int(fspec.shape[1]), int(fspec.shape[2]))
    window = TrainConfig(crop=crop).resolve_crop(hw)
    pre = Preprocess(hw, window)
    with open_verified(path) as f:  # every checksum first: a damaged file is refused naming the dataset
        g_frames, g_force = f["streams"][frames_stream], f["streams"][force_stream]
        n = int(min(g_frames["t"].shape[0], g_frames["data"].shape[0]))
        m = int(min(g_force["t"].shape[0], g_force["data"].shape[0]))
        t = g_frames["t"][:n]
        tf, force = g_force["t"][:m], np.asarray(g_force["data"][:m], np.float64)
        if m == n and np.array_equal(t, tf):
            keep = np.arange(n)
            paired = force
            how = "same time stamps"
        else:
            if m < 2:
                raise ValueError(f"{path}: '{force_stream}' has {m} sample(s); cannot pair it with frames")
            keep = np.flatnonzero((t >= tf[0]) & (t <= tf[-1]))
            paired = np.stack([np.interp(t[keep], tf, force[:, k]) for k in range(force.shape[1])], axis=1)
            how = "force interpolated at frame times"
        ch, cw = pre.crop_hw
        frames = np.empty((len(keep), fspec.shape[0], ch, cw), np.uint8)
        data = g_frames["data"]
        for a in range(0, len(keep), block_frames):
            idx = keep[a : a + block_frames]
            if len(idx) == 0:
                break
            lo, hi = int(idx[0]), int(idx[-1]) + 1
            block = pre.crop_array(data[lo:hi])
            frames[a : a + len(idx)] = block[idx - lo]
    info = {
        "path": str(path),
        "frames_stream": frames_stream,
        "force_stream": force_stream,
        "frames": len(keep),
        "duration_s": float(t[-1] - t[0]) if n else 0.0,
        "pairing": how,
        **_provenance(path),
    }
    return frames, paired, hw, window, info


def load_dataset(
    recordings: Sequence[str | Path],
    frames_stream: str = "sim.frames",
    force_stream: str = "sim.force",
    crop: tuple[int, int, int, int] | str | None = "auto",
    sensors: Sequence[int] | None = None,
) -> Dataset:
    """All (image, force) samples of one or more recordings, pooled over the chosen sensors."""
    if not recordings:
        raise ValueError("give at least one recording")
    parts, sources = [], []
    hw0, crop0, s0 = None, None, None
    for rec in recordings:
        frames, force, hw, window, info = load_recording_pairs(rec, frames_stream, force_stream, crop)
        if hw0 is None:
            hw0, crop0, s0 = hw, window, frames.shape[1]
        elif (hw, window, frames.shape[1]) != (hw0, crop0, s0):
            raise ValueError(
                f"{rec}: frames {hw} × {frames.shape[1]} sensors differ from the first recording's"
            )
        parts.append((frames, force))
        sources.append(info)
    frames = np.concatenate([p[0] for p in parts])
    force = np.concatenate([p[1] for p in parts])
    assert hw0 is not None
    return Dataset.from_frames(frames, force, crop=crop0, sensors=sensors, sources=sources, input_hw=hw0)


def split_indices(
    n: int, seed: int = 0, fractions: tuple[float, float, float] = (0.90, 0.05, 0.05)
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Seeded random (train, validation, test) index arrays, sorted: 90/5/5 by default.

    Validation and test get ``round(fraction · n)`` samples (at least 1 each when n >= 3); train the rest.
    """
    if n < 3:
        raise ValueError(f"need at least 3 samples to split into train/validation/test; got {n}")
    perm = np.random.default_rng(seed).permutation(n)
    n_val = max(1, round(fractions[1] * n))
    n_test = max(1, round(fractions[2] * n))
    test, val, train = perm[:n_test], perm[n_test : n_test + n_val], perm[n_test + n_val :]
    return np.sort(train), np.sort(val), np.sort(test)


# -- training -------------------------------------------------------------------------------------------


def _sensor_names(n_sensors: int) -> list[str]:
    return list(FINGERS) if n_sensors == len(FINGERS) else [f"sensor{i}" for i in range(n_sensors)]


def _preprocess_all(model: Any, images: np.ndarray, torch: Any, batch: int = 512) -> Any:
    out = []
    with torch.inference_mode():
        for a in range(0, len(images), batch):
            out.append(
                model.preprocess(torch.from_numpy(np.ascontiguousarray(images[a : a + batch])), cropped=True)
            )
    return torch.cat(out).clone()


def _predict(model: Any, x: Any, torch: Any, batch: int = 256) -> np.ndarray:
    model.eval()
    with torch.inference_mode():
        return (
            torch.cat([model(x[a : a + batch]) for a in range(0, len(x), batch)]).numpy().astype(np.float64)
        )


def train_on_arrays(
    data: Dataset,
    config: TrainConfig = TrainConfig(),
    *,
    seed: int = 0,
    progress: bool = True,
    log: Callable[[str], None] | None = None,
    stop: Callable[[], bool] | None = None,
) -> tuple[Any, dict[str, Any]]:
    """Train a ``ForceCNN`` on a :class:`Dataset`; returns ``(model in eval mode, report)``.

    The report holds everything the checkpoint metadata records (see :func:`train_force`).
    ``stop`` is asked after every batch: when it says so, training ends there with the best model
    of the epochs completed (``stopped: "interrupted"``, ``interrupted_at_epoch``); it raises
    :class:`TrainingInterrupted` when no epoch was completed.
    Deterministic for a given seed, data and thread count (weights are initialised from
    ``seed`` without touching torch's global random state; the split and the batch order are
    seeded too).
    """
    torch = import_torch()
    threads = torch.get_num_threads()
    if config.threads is not None:
        torch.set_num_threads(int(config.threads))
    try:
        return _train(torch, data, config, seed, progress, log, stop)
    finally:
        torch.set_num_threads(threads)  # the setting is process-wide: give it back


def _epoch(
    torch: Any,
    model: Any,
    opt: Any,
    x_tr: Any,
    y_tr: Any,
    perm: Any,
    config: TrainConfig,
    weights: Any,
    stop: Callable[[], bool] | None,
) -> tuple[float, int, bool]:
    """One pass over the training set in ``perm`` order: (sum of batch MSE × size, samples, completed?).

    ``stop`` is asked after each batch; when it says so the pass ends there, incomplete.
    """
    model.train()
    total, count = 0.0, 0
    for a in range(0, len(perm), config.batch_size):
        idx = perm[a : a + config.batch_size]
        if len(idx) < 2:  # batch norm needs two samples in training mode
            continue
        mse = torch.mean((model(x_tr[idx]) - y_tr[idx]) ** 2)
        loss = mse
        if config.l1:
            loss = loss + config.l1 * sum(w.abs().sum() for w in weights)
        if config.l2:
            loss = loss + config.l2 * sum((w * w).sum() for w in weights)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        total += float(mse.detach()) * len(idx)
        count += len(idx)
        if stop is not None and stop():
            return total, count, False
    return total, count, True


def _train(
    torch: Any,
    data: Dataset,
    config: TrainConfig,
    seed: int,
    progress: bool,
    log: Callable[[str], None] | None,
    stop: Callable[[], bool] | None = None,
) -> tuple[Any, dict[str, Any]]:
    n = len(data)
    train, val, test = split_indices(n, seed, config.split)
    pre = Preprocess(data.input_hw, data.crop, config.downsample)
    arch = config.arch_spec
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        model = build_model(arch, pre)
    x_all = _preprocess_all(model, data.images, torch)
    pix_mean = float(x_all[torch.from_numpy(train)].mean())
    pix_std = float(x_all[torch.from_numpy(train)].std()) or 1.0
    x_all = (x_all - pix_mean) / pix_std
    model.pixel_mean.fill_(pix_mean)
    model.pixel_std.fill_(pix_std)
    y = data.force_n
    y_mean = float(np.mean(y[train]))
    y_std = float(np.std(y[train])) or 1.0
    y_all = torch.from_numpy(((y - y_mean) / y_std).astype(np.float32))
    x_tr, y_tr = x_all[torch.from_numpy(train)], y_all[torch.from_numpy(train)]
    x_va, y_va = x_all[torch.from_numpy(val)], y_all[torch.from_numpy(val)]
    x_te = x_all[torch.from_numpy(test)]

    opt = torch.optim.Adam(model.parameters(), lr=config.lr)
    sched = (
        None
        if config.lr_plateau is None
        else torch.optim.lr_scheduler.ReduceLROnPlateau(opt, factor=0.5, patience=config.lr_plateau)
    )
    gen = torch.Generator().manual_seed(seed)
    weights = model.weights()
    best_val, best_state, best_epoch, bad = math.inf, copy.deepcopy(model.state_dict()), 0, 0
    history: dict[str, list[float]] = {"train_mse": [], "val_mse": []}
    stopped = "max_epochs"
    interrupted_at: int | None = None
    t0 = time.perf_counter()
    bar = TerminalBar("train-force", config.max_epochs, show=progress)
    try:
        for epoch in range(1, config.max_epochs + 1):
            perm = torch.randperm(len(train), generator=gen)
            total, count, complete = _epoch(torch, model, opt, x_tr, y_tr, perm, config, weights, stop)
            if not complete:  # interrupted: this epoch is partial, keep the best of those before it
                interrupted_at, stopped = epoch, "interrupted"
                break
            val_mse = float(np.mean((_predict(model, x_va, torch) - y_va.numpy()) ** 2))
            train_mse = total / max(count, 1)
            if sched is not None:
                sched.step(val_mse)
            history["train_mse"].append(round(train_mse, 6))
            history["val_mse"].append(round(val_mse, 6))
            if val_mse < best_val:
                best_val, best_epoch, bad = val_mse, epoch, 0
                best_state = copy.deepcopy(model.state_dict())
            else:
                bad += 1
            text = f"loss {train_mse:.4f} val {val_mse:.4f} best {best_val:.4f} (epoch {best_epoch})"
            bar.update(advance=1, description=text)
            if log is not None:
                log(f"epoch {epoch}: {text}")
            if bad >= config.patience:
                stopped = "early_stopping"
                break
            if config.time_limit_s is not None and time.perf_counter() - t0 > config.time_limit_s:
                stopped = "time_limit"
                break
    finally:
        bar.close()
    train_s = time.perf_counter() - t0
    if interrupted_at is not None and not history["val_mse"]:
        raise TrainingInterrupted("interrupted before the first epoch finished")
    model.load_state_dict(best_state)
    model.eval()

    def mae(idx: np.ndarray, pred_z: np.ndarray) -> dict[str, float]:
        err = np.abs(pred_z * y_std + y_mean - y[idx])
        out = {"combined": float(err.mean())}
        for k, name in enumerate(_sensor_names(data.n_sensors)):
            sel = data.sensor[idx] == k
            if sel.any():
                out[name] = float(err[sel].mean())
        return out

    report = {
        "arch_name": config.arch_name,
        "n_parameters": n_parameters(model),
        "label_mean_n": y_mean,
        "label_std_n": y_std,
        "units": "N",
        "sensors": [_sensor_names(data.n_sensors)[i] for i in sorted(set(data.sensor.tolist()))],
        "n_sensors": data.n_sensors,
        "n_samples": n,
        "n_train": len(train),
        "n_val": len(val),
        "n_test": len(test),
        "test_mae_n": mae(test, _predict(model, x_te, torch)),
        "val_mae_n": mae(val, _predict(model, x_va, torch)),
        "test_force_std_n": float(np.std(y[test])),
        "epochs": len(history["val_mse"]),
        "best_epoch": best_epoch,
        "best_val_mse": best_val,
        "stopped": stopped,
        **({"interrupted_at_epoch": interrupted_at} if interrupted_at is not None else {}),
        "train_s": round(train_s, 2),
        "seed": seed,
        "threads": torch.get_num_threads(),
        "train_config": asdict(config),
        "torch_version": torch.__version__,
        "sources": data.sources,
        "history": history,
        "created_utc": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
    }
    from flowtact import __version__

    report["flowtact_version"] = __version__
    return model, report


def evaluate(model: Any, meta: Mapping[str, Any], data: Dataset, batch: int = 256) -> dict[str, float]:
    """Mean absolute error in N (per sensor and combined) of a trained model on a :class:`Dataset`.

    ``data`` must hold images cropped like the model's training images (same ``crop``).
    """
    torch = import_torch()
    model.eval()
    z = []
    with torch.inference_mode():
        for a in range(0, len(data), batch):
            imgs = torch.from_numpy(np.ascontiguousarray(data.images[a : a + batch]))
            z.append(model.predict(imgs, cropped=True))
    pred = torch.cat(z).numpy().astype(np.float64) * float(meta["label_std_n"]) + float(meta["label_mean_n"])
    err = np.abs(pred - data.force_n)
    out = {"combined": float(err.mean())}
    for k, name in enumerate(_sensor_names(data.n_sensors)):
        sel = data.sensor == k
        if sel.any():
            out[name] = float(err[sel].mean())
    return out


def train_force(
    recordings: Sequence[str | Path],
    frames_stream: str = "sim.frames",
    force_stream: str = "sim.force",
    config: TrainConfig = TrainConfig(),
    out: str | Path | None = "force_cnn.pt",
    seed: int = 0,
    progress: bool = True,
    *,
    heldout: Sequence[str | Path] = (),
    meta: Mapping[str, Any] | None = None,
    log: Callable[[str], None] | None = None,
    stop: Callable[[], bool] | None = None,
) -> dict[str, Any]:
    """Train the force CNN on recordings, save the checkpoint (if ``out``), return the report.

    The report (also the checkpoint's metadata, with ``meta`` added) holds: the architecture and
    preprocessing, the label mean/std, train/validation/test sizes, test and validation MAE in N per
    sensor and combined, epochs run, the best epoch, why training stopped, the seed, torch and
    flowtact versions, the source recordings (with their own recording command) and the loss history.
    ``heldout`` recordings (none of whose frames are trained on) are scored after training:
    ``report["heldout"] = {"mae_n": {...}, "sources": [...]}``. The random split's test frames have
    near-identical neighbours (the next frame of the same tap) in the training split; a held-out
    recording is the honest measure of how the model does on new contacts.
    ``log`` gets one line per epoch; ``stop`` ends training early (see :func:`train_on_arrays`).
    """
    data = load_dataset(recordings, frames_stream, force_stream, config.crop, config.sensors)
    model, report = train_on_arrays(data, config, seed=seed, progress=progress, log=log, stop=stop)
    if heldout:
        held = load_dataset(heldout, frames_stream, force_stream, data.crop, config.sensors)
        if held.input_hw != data.input_hw:
            raise ValueError(f"held-out frames are {held.input_hw}, training frames {data.input_hw}")
        report["heldout"] = {
            "mae_n": evaluate(model, report, held),
            "samples": len(held),
            "sources": held.sources,
        }
    report.update(dict(meta or {}))
    if out is not None:
        report["checkpoint"] = str(save_checkpoint(out, model, report))
    return report


# -- command line -----------------------------------------------------------------------------------------


# The documented ranges of the flags: a value outside is a one-line usage error (exit 2).
MAX_EPOCHS = 100_000
"""Most epochs, patience or plateau length (the recipe's 400 epochs take about 20 min on a CPU)."""
MAX_DOWNSAMPLE = 64
"""Largest pooling factor (a 240×320 frame pooled by 64 is 3×5 pixels)."""
MAX_BATCH = 65_536
"""Largest mini-batch (the recipe's is 64)."""
MAX_LR = 10.0
"""Largest learning rate (Adam's usual is 1e-3)."""
MAX_PENALTY = 1e6
"""Largest l1 or l2 weight penalty."""
MAX_THREADS = 1024
"""Most torch threads."""
MAX_TIME_LIMIT_S = 1e7
"""Longest ``--time-limit`` (about 4 months)."""
MAX_CROP_PX = 100_000
"""Largest crop corner, width or height in pixels (frames are 240×320)."""


def _crop_arg(text: str) -> tuple[int, int, int, int] | str | None:
    if text in ("auto", "none"):
        return None if text == "none" else "auto"
    try:
        parts = tuple(int(v) for v in text.split(","))
    except ValueError:
        parts = ()
    if len(parts) != 4:
        raise argparse.ArgumentTypeError(f"expected x0,y0,w,h (4 integers), 'auto' or 'none'; got {text!r}")
    if min(parts[:2]) < 0 or min(parts[2:]) < 1 or max(parts) > MAX_CROP_PX:
        raise argparse.ArgumentTypeError(
            f"x0, y0 must be in [0, {MAX_CROP_PX}] and w, h in [1, {MAX_CROP_PX}] pixels; got {text!r}"
        )
    return parts  # type: ignore[return-value]


def _sensors_arg(text: str) -> tuple[int, ...]:
    out = []
    for part in text.split(","):
        part = part.strip()
        if part in FINGERS:
            out.append(FINGERS.index(part))
        elif part.isdigit() and int(part) < len(FINGERS):
            out.append(int(part))
        else:
            raise argparse.ArgumentTypeError(
                f"sensor {part!r}: use {', '.join(FINGERS)} or an index in [0, {len(FINGERS) - 1}]"
            )
    return tuple(out)


def build_parser() -> argparse.ArgumentParser:
    """The ``flowtact train-force`` argument parser."""
    d = TrainConfig()
    p = CommandParser(
        prog="flowtact train-force",
        description="Train the TacTip contact-force CNN on recorded (frame, force) pairs and save a checkpoint "
        "for the cnn_force block. Make a training set with: "
        "flowtact run graphs/tactip_dataset.yaml --fast --record data.h5",
    )
    p.add_argument(
        "recordings", nargs="+", metavar="REC.h5", help="flowtact recordings with frames and force"
    )
    p.add_argument("--arch", choices=list(ARCHS), default=d.arch, help=f"network size (default {d.arch})")
    p.add_argument(
        "--out",
        default="force_cnn.pt",
        help="checkpoint to write (.pt; a .json copy of the metadata beside it)",
    )
    p.add_argument(
        "--epochs",
        type=cli_int(1, MAX_EPOCHS),
        default=d.max_epochs,
        help=f"maximum epochs (default {d.max_epochs})",
    )
    p.add_argument(
        "--patience",
        type=cli_int(1, MAX_EPOCHS),
        default=d.patience,
        help=f"early-stopping patience in epochs (default {d.patience})",
    )
    p.add_argument(
        "--frames-stream", default="sim.frames", help="frame stream NODE.PORT (default sim.frames)"
    )
    p.add_argument("--force-stream", default="sim.force", help="force stream NODE.PORT (default sim.force)")
    p.add_argument(
        "--crop", type=_crop_arg, default=d.crop, help="x0,y0,w,h crop window, 'auto' (default) or 'none'"
    )
    p.add_argument(
        "--downsample",
        type=cli_int(1, MAX_DOWNSAMPLE),
        default=d.downsample,
        help=f"average-pool factor after the crop (default {d.downsample})",
    )
    p.add_argument(
        "--batch-size",
        type=cli_int(2, MAX_BATCH),
        default=d.batch_size,
        help=f"mini-batch size (default {d.batch_size})",
    )
    p.add_argument(
        "--lr",
        type=cli_float(0, MAX_LR, lo_open=True),
        default=d.lr,
        help=f"Adam learning rate (default {d.lr:g})",
    )
    p.add_argument(
        "--lr-plateau",
        type=cli_int(0, MAX_EPOCHS),
        default=d.lr_plateau,
        metavar="N",
        help=f"halve the learning rate after N epochs without progress (default {d.lr_plateau}; 0: never)",
    )
    p.add_argument(
        "--l1", type=cli_float(0, MAX_PENALTY), default=d.l1, help=f"l1 penalty on weights (default {d.l1:g})"
    )
    p.add_argument(
        "--l2", type=cli_float(0, MAX_PENALTY), default=d.l2, help=f"l2 penalty on weights (default {d.l2:g})"
    )
    p.add_argument(
        "--sensors", type=_sensors_arg, default=None, help="train on these sensors only, e.g. thumb or 0,2"
    )
    p.add_argument(
        "--seed",
        type=cli_int(0, ft.MAX_SEED),
        default=0,
        help="seed of the split, initial weights and batch order",
    )
    p.add_argument(
        "--threads",
        type=cli_int(0, MAX_THREADS),
        default=d.threads,
        help=f"torch threads (default {d.threads}; 0: torch's choice)",
    )
    p.add_argument(
        "--time-limit",
        type=cli_float(0, MAX_TIME_LIMIT_S, "s", lo_open=True),
        default=None,
        metavar="S",
        help="stop after S seconds of training",
    )
    p.add_argument(
        "--heldout",
        action="append",
        default=[],
        metavar="REC.h5",
        help="score the trained model on this recording too (repeatable; e.g. the dataset graph with another seed)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """``flowtact train-force``: returns the exit status (:func:`flowtact.console.command.run_command`:
    0 ok, 2 a bad flag or input, 1 failed)."""
    return run_command(
        lambda: _command(list(sys.argv[1:] if argv is None else argv)), prog="flowtact train-force"
    )


def _command(argv: list[str]) -> int:
    args = build_parser().parse_args(argv)
    try:
        import_torch()
    except ImportError:
        raise ImportError(TORCH_HINT) from None
    try:
        config = TrainConfig(
            arch=args.arch,
            crop=args.crop,
            downsample=args.downsample,
            max_epochs=args.epochs,
            patience=args.patience,
            batch_size=args.batch_size,
            lr=args.lr,
            l1=args.l1,
            l2=args.l2,
            sensors=args.sensors,
            threads=args.threads or None,
            time_limit_s=args.time_limit,
            lr_plateau=args.lr_plateau or None,
        )
        command = "flowtact train-force " + " ".join(argv)
        quiet = args.no_progress or sys.stderr.isatty()  # a terminal has the progress bar instead
        with StopOnInterrupt() as interrupt:
            report = train_force(
                args.recordings,
                args.frames_stream,
                args.force_stream,
                config,
                out=args.out,
                seed=args.seed,
                progress=not args.no_progress,
                heldout=args.heldout,
                meta={"command": command},
                log=None if quiet else _log,
                stop=interrupt.requested,
            )
    except (ValueError, KeyError) as e:  # settings, streams or frames that do not fit: the input's fault
        raise UsageError(str(e.args[0] if isinstance(e, KeyError) and e.args else e)) from e
    except KeyboardInterrupt as e:
        print(f"flowtact train-force: {e or 'aborted'}; nothing saved", file=sys.stderr)
        return 130
    if args.json:
        print(json.dumps({k: v for k, v in report.items() if k != "history"}, indent=1))
        return 0
    mae = report["test_mae_n"]
    per = ", ".join(f"{k} {v:.3f}" for k, v in mae.items() if k != "combined")
    print(
        f"{report['arch_name']} ({report['n_parameters']} parameters): {report['epochs']} epochs "
        f"({report['stopped']}, best {report['best_epoch']}) in {report['train_s']:.0f} s; "
        f"{report['n_train']}/{report['n_val']}/{report['n_test']} train/val/test images"
    )
    print(
        f"test MAE {mae['combined']:.3f} N ({per}); test force std {report['test_force_std_n']:.3f} N; "
        "thesis: 0.101 N combined (Table 4.1)"
    )
    if "heldout" in report:
        h = report["heldout"]["mae_n"]
        per = ", ".join(f"{k} {v:.3f}" for k, v in h.items() if k != "combined")
        print(f"held-out MAE {h['combined']:.3f} N ({per}) on {report['heldout']['samples']} images")
    print(f"checkpoint: {report['checkpoint']} (+ {Path(report['checkpoint']).with_suffix('.json').name})")
    if report["stopped"] == "interrupted":
        print(
            f"interrupted at epoch {report['interrupted_at_epoch']}: saved the best model so far "
            f"(epoch {report['best_epoch']}) to {report['checkpoint']}"
        )
    return 0


def _log(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


class StopOnInterrupt:
    """Ctrl-C (SIGINT) asks training to stop after its current batch; a second Ctrl-C aborts.

    ``requested()`` says whether the first came. Used as a context manager; the previous handler
    comes back on exit. Outside the main thread it does nothing (Python delivers signals there only).
    """

    def __init__(self) -> None:
        self.count = 0
        self.previous: Any = None

    def requested(self) -> bool:
        return self.count > 0

    def _on_sigint(self, _signum: int, _frame: Any) -> None:
        self.count += 1
        if self.count > 1:
            raise KeyboardInterrupt("interrupted twice: aborted")
        print(
            "\nflowtact train-force: stopping after this batch and saving the best model so far "
            "(Ctrl-C again aborts)",
            file=sys.stderr,
            flush=True,
        )

    def __enter__(self) -> StopOnInterrupt:
        if threading.current_thread() is threading.main_thread():
            self.previous = signal.signal(signal.SIGINT, self._on_sigint)
        return self

    def __exit__(self, *exc: object) -> None:
        if self.previous is not None:
            signal.signal(signal.SIGINT, self.previous)


COMMAND = Command(main=main)
"""``flowtact train-force``: parses its own arguments (entry-point group ``flowtact.commands``)."""


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
