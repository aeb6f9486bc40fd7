"""Contact force from TacTip images with a small CNN (White 2023, §3.1.3): the model and ``cnn_force``.

The network is the thesis's shape — ``n_conv`` blocks of 3×3 convolution, batch norm, ReLU and 2×2
max-pool, then one fully connected layer and a linear regression head giving one standardised force
per image — in named sizes (:data:`ARCHS`): ``paper`` is the thesis's 4 conv × 256 filters + FC 128;
``w64`` … ``w8`` keep the depth and shrink the filters. Preprocessing is part of the model and of
its checkpoint: crop the frame, scale uint8 → [0, 1], average-pool by ``downsample``, normalise by
the training pixels' mean and standard deviation.

torch is an optional extra (``pip install 'flowtact[cnn]'``): importing this module does NOT import
it. :func:`force_cnn_class` / :func:`build_model` / :func:`load_checkpoint` and the block's
``open``/``reset`` import it on first use. Training lives in :mod:`flowtact.blocks.teleop.train_force`.

Checkpoint format (``flowtact train-force --out model.pt``): ``model.pt`` is a ``torch.save``'d dict
``{"format": "flowtact-force-cnn", "format_version": 1, "meta": <JSON text>, "state_dict": {...}}``
read back with ``torch.load(weights_only=True)`` (no pickled code), and ``model.json`` beside it
holds the same metadata as plain JSON, so a graph can be checked (frame size) without torch.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

import flowtact.api as ft
from flowtact.inputs.bounded_files import open_regular, regular_file
from flowtact.inputs.safe_text import shown

from .hand import FINGERS
from .image import example_frames

__all__ = [
    "ARCHS",
    "CHECKPOINT_FORMAT",
    "SHIPPED_CHECKPOINT",
    "Arch",
    "CnnForce",
    "CnnForceConfig",
    "Preprocess",
    "build_model",
    "force_cnn_class",
    "import_torch",
    "load_checkpoint",
    "read_meta",
    "save_checkpoint",
    "shipped_checkpoint",
]

CHECKPOINT_FORMAT = "flowtact-force-cnn"
CHECKPOINT_VERSION = 1
#: File name of the checkpoint shipped in the package (flowtact/blocks/teleop/models/).
SHIPPED_CHECKPOINT = "force_cnn_w16.pt"
TORCH_HINT = "the CNN force estimator needs PyTorch: pip install 'flowtact[cnn]'"

# -- bounds on what a checkpoint may ask for (checked before torch reads it or a network is built) --
MAX_CHECKPOINT_BYTES = 256 << 20
"""Largest checkpoint file read (the shipped w16 is 60 kB, the thesis's network about 10 MB)."""
MAX_META_BYTES = 1 << 20
"""Largest metadata (.json beside the checkpoint, or embedded) read."""
MAX_CONV = 8
"""Most conv/pool stages."""
MAX_WIDTH = 1024
"""Most filters per conv stage (the thesis uses 256)."""
MAX_FC = 4096
"""Widest fully connected layer."""
MAX_KERNEL = 15
"""Largest convolution kernel side."""
MAX_INPUT_SIDE = 4096
"""Largest frame side (pixels) a checkpoint may declare."""
MAX_DOWNSAMPLE = 64
"""Largest average-pooling factor."""
MAX_CNN_BYTES = ft.STATE_BUDGET_BYTES
"""Most memory a network may need (float32 parameters twice, as built and as loaded, plus two
activations of one 3-image call): a block's state budget (1 GiB), checked from the metadata
before the network is built."""


def import_torch() -> Any:
    """``import torch``, or an ImportError that says how to install the extra."""
    try:
        import torch
    except ImportError as e:  # pragma: no cover - torch is installed in the dev environment
        raise ImportError(f"{TORCH_HINT} ({e})") from None
    return torch


# -- configuration (plain Python: no torch) ----------------------------------------------------------


@dataclass(frozen=True)
class Arch:
    """Network shape: ``n_conv`` × [conv k×k (``width`` filters), batch norm, ReLU, max-pool 2] → FC → 1."""

    n_conv: int = 4
    width: int = 16
    fc: int = 128
    kernel: int = 3
    batch_norm: bool = True

    def __post_init__(self) -> None:
        if self.n_conv < 1 or self.width < 1 or self.fc < 1:
            raise ValueError(f"n_conv, width and fc must be >= 1; got {self}")
        if self.kernel < 1 or self.kernel % 2 == 0:
            raise ValueError(f"kernel must be odd and >= 1; got {self.kernel}")


#: Named configurations: the thesis's network and narrower ones of the same depth.
ARCHS: dict[str, Arch] = {
    "paper": Arch(n_conv=4, width=256, fc=128),
    "w64": Arch(n_conv=4, width=64, fc=128),
    "w32": Arch(n_conv=4, width=32, fc=128),
    "w16": Arch(n_conv=4, width=16, fc=128),
    "w8": Arch(n_conv=4, width=8, fc=128),
}


@dataclass(frozen=True)
class Preprocess:
    """How a frame becomes the network's input.

    ``input_hw``: the (H, W) of the frames the model was trained on (the recorded stream's);
    ``crop``: (x0, y0, w, h) window in those frames, or None for the whole frame; ``downsample``:
    average-pooling factor after the crop (1: none).
    """

    input_hw: tuple[int, int]
    crop: tuple[int, int, int, int] | None = None
    downsample: int = 1

    def __post_init__(self) -> None:
        object.__setattr__(self, "input_hw", tuple(int(v) for v in self.input_hw))
        if self.crop is not None:
            object.__setattr__(self, "crop", tuple(int(v) for v in self.crop))
            x0, y0, w, h = self.crop
            H, W = self.input_hw
            if x0 < 0 or y0 < 0 or w < 1 or h < 1 or x0 + w > W or y0 + h > H:
                raise ValueError(f"crop (x0, y0, w, h) = {self.crop} does not fit in {H}×{W} frames")
        if self.downsample < 1:
            raise ValueError(f"downsample must be >= 1; got {self.downsample}")

    @property
    def crop_hw(self) -> tuple[int, int]:
        """(H, W) after the crop."""
        return self.input_hw if self.crop is None else (self.crop[3], self.crop[2])

    @property
    def model_hw(self) -> tuple[int, int]:
        """(H, W) the convolutions see (after the crop and the average pooling)."""
        h, w = self.crop_hw
        return h // self.downsample, w // self.downsample

    def crop_array(self, frames: np.ndarray) -> np.ndarray:
        """Crop uint8 frames (..., H, W) with numpy (a view)."""
        if self.crop is None:
            return frames
        x0, y0, w, h = self.crop
        return frames[..., y0 : y0 + h, x0 : x0 + w]


# -- the network (built lazily: torch is imported on first use) ------------------------------------


@functools.cache
def force_cnn_class() -> type:
    """The ``ForceCNN`` torch module class (imports torch). Also reachable as ``cnn.ForceCNN``."""
    torch = import_torch()
    nn = torch.nn
    F = torch.nn.functional

    class ForceCNN(nn.Module):
        """Contact-force regression CNN: uint8 frames (N, H, W) → standardised force (N,).

        ``preprocess`` turns uint8 frames into the normalised (N, 1, h, w) float32 input;
        ``forward`` takes that input; ``predict`` does both. De-standardise with the checkpoint's
        ``label_mean_n`` / ``label_std_n``.
        """

        def __init__(self, arch: Arch, pre: Preprocess, pixel_mean: float = 0.0, pixel_std: float = 1.0):
            super().__init__()
            self.arch, self.pre = arch, pre
            h, w = pre.model_hw
            layers: list[Any] = []
            channels = 1
            for i in range(arch.n_conv):
                if h < 2 or w < 2:
                    raise ValueError(
                        f"{arch.n_conv} conv/pool stages need a larger input than {pre.model_hw} "
                        f"(stage {i + 1} sees {h}×{w}); use fewer layers or less downsampling"
                    )
                pad = arch.kernel // 2
                layers.append(
                    nn.Conv2d(channels, arch.width, arch.kernel, padding=pad, bias=not arch.batch_norm)
                )
                if arch.batch_norm:
                    layers.append(nn.BatchNorm2d(arch.width))
                layers += [nn.ReLU(), nn.MaxPool2d(2)]
                channels, h, w = arch.width, h // 2, w // 2
            self.features = nn.Sequential(*layers)
            self.head = nn.Sequential(
                nn.Flatten(), nn.Linear(channels * h * w, arch.fc), nn.ReLU(), nn.Linear(arch.fc, 1)
            )
            self.register_buffer("pixel_mean", torch.tensor(float(pixel_mean), dtype=torch.float32))
            self.register_buffer("pixel_std", torch.tensor(float(pixel_std), dtype=torch.float32))

        def preprocess(self, frames: Any, *, cropped: bool = False) -> Any:
            """uint8 frames (N, H, W) → float32 (N, 1, h, w); ``cropped``: already cropped."""
            x = frames
            if not cropped and self.pre.crop is not None:
                x0, y0, cw, ch = self.pre.crop
                x = x[:, y0 : y0 + ch, x0 : x0 + cw]
            x = x.to(torch.float32).unsqueeze(1) / 255.0
            if self.pre.downsample > 1:
                x = F.avg_pool2d(x, self.pre.downsample)
            return (x - self.pixel_mean) / self.pixel_std

        def forward(self, x: Any) -> Any:
            return self.head(self.features(x)).squeeze(1)

        def predict(self, frames: Any, *, cropped: bool = False) -> Any:
            """Standardised force for uint8 frames (N, H, W)."""
            return self.forward(self.preprocess(frames, cropped=cropped))

        def weights(self) -> list[Any]:
            """Conv and linear weight tensors (what l1/l2 regularisation applies to; no biases, no BN)."""
            return [m.weight for m in self.modules() if isinstance(m, (nn.Conv2d, nn.Linear))]

    return ForceCNN


def __getattr__(name: str) -> Any:
    if name == "ForceCNN":
        return force_cnn_class()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def build_model(arch: Arch | str, pre: Preprocess, pixel_mean: float = 0.0, pixel_std: float = 1.0) -> Any:
    """A fresh ``ForceCNN`` (``arch``: an :class:`Arch` or a name in :data:`ARCHS`)."""
    if isinstance(arch, str):
        if arch not in ARCHS:
            raise ValueError(f"unknown arch {arch!r} (valid: {', '.join(ARCHS)})")
        arch = ARCHS[arch]
    return force_cnn_class()(arch, pre, pixel_mean, pixel_std)


def n_parameters(model: Any) -> int:
    """Number of trainable parameters."""
    return int(sum(p.numel() for p in model.parameters()))


# -- checkpoints --------------------------------------------------------------------------------------


def shipped_checkpoint() -> Path:
    """Path of the checkpoint shipped with the package (``flowtact/blocks/teleop/models/``)."""
    return Path(str(resources.files("flowtact.blocks.teleop").joinpath("models", SHIPPED_CHECKPOINT)))


def _sidecar(path: Path) -> Path:
    return path.with_suffix(".json")


def save_checkpoint(path: str | Path, model: Any, meta: Mapping[str, Any]) -> Path:
    """Write ``path`` (.pt: weights + metadata) and the metadata as ``path`` with suffix .json."""
    torch = import_torch()
    path = Path(path)
    meta = {
        "format": CHECKPOINT_FORMAT,
        "format_version": CHECKPOINT_VERSION,
        "arch": asdict(model.arch),
        "preprocess": {
            "input_hw": list(model.pre.input_hw),
            "crop": None if model.pre.crop is None else list(model.pre.crop),
            "downsample": model.pre.downsample,
        },
        "pixel_mean": float(model.pixel_mean),
        "pixel_std": float(model.pixel_std),
        **dict(meta),
    }
    for key in ("label_mean_n", "label_std_n"):
        if key not in meta:
            raise ValueError(f"checkpoint metadata needs '{key}' (the label standardisation)")
    text = json.dumps(meta, indent=1, sort_keys=True, default=_json_default)
    path.parent.mkdir(parents=True, exist_ok=True)
    state = {k: v.detach().cpu().clone() for k, v in model.state_dict().items()}
    torch.save(
        {
            "format": CHECKPOINT_FORMAT,
            "format_version": CHECKPOINT_VERSION,
            "meta": text,
            "state_dict": state,
        },
        path,
    )
    _sidecar(path).write_text(text + "\n")
    return path


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON-serialisable: {type(obj).__name__}")


def _check_meta(meta: Any, path: Path) -> dict[str, Any]:
    """The metadata, after checking its format and every architecture field against the bounds
    above (a checkpoint cannot make flowtact build a network of gigabytes); ValueError otherwise."""
    if not isinstance(meta, Mapping):
        raise ValueError(
            f"{shown(path)}: not a flowtact force-CNN checkpoint (metadata is not a JSON object)"
        )
    if meta.get("format") != CHECKPOINT_FORMAT:
        got = shown(repr(meta.get("format")), limit=80)
        raise ValueError(f"{shown(path)}: not a flowtact force-CNN checkpoint (format {got})")
    version = meta.get("format_version", -1)
    if not isinstance(version, int) or isinstance(version, bool):
        raise ValueError(f"{shown(path)}: format_version must be an integer")
    if version > CHECKPOINT_VERSION:
        raise ValueError(f"{shown(path)}: checkpoint format version {version} is newer than this flowtact")
    _check_shape(meta, path)
    return dict(meta)


def _int_in(value: Any, low: int, high: int, what: str, path: Path) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise ValueError(
            f"{shown(path)}: {what} must be an integer in {low}..{high}; got {shown(repr(value), limit=80)}"
        )
    return value


def _check_shape(meta: Mapping[str, Any], path: Path) -> None:
    """Range-check the architecture and preprocessing, then the memory the network would need."""
    arch, pre = meta.get("arch"), meta.get("preprocess")
    if not isinstance(arch, Mapping) or not isinstance(pre, Mapping):
        raise ValueError(f"{shown(path)}: metadata needs 'arch' and 'preprocess' objects")
    n_conv = _int_in(arch.get("n_conv", 4), 1, MAX_CONV, "arch.n_conv", path)
    width = _int_in(arch.get("width", 16), 1, MAX_WIDTH, "arch.width", path)
    fc = _int_in(arch.get("fc", 128), 1, MAX_FC, "arch.fc", path)
    kernel = _int_in(arch.get("kernel", 3), 1, MAX_KERNEL, "arch.kernel", path)
    hw = pre.get("input_hw")
    if not isinstance(hw, (list, tuple)) or len(hw) != 2:
        raise ValueError(f"{shown(path)}: preprocess.input_hw must be [height, width]")
    h, w = (_int_in(v, 1, MAX_INPUT_SIDE, "preprocess.input_hw", path) for v in hw)
    crop = pre.get("crop")
    if crop is not None:
        if not isinstance(crop, (list, tuple)) or len(crop) != 4:
            raise ValueError(f"{shown(path)}: preprocess.crop must be null or [x0, y0, w, h]")
        _, _, cw, ch = (_int_in(v, 0, MAX_INPUT_SIDE, "preprocess.crop", path) for v in crop)
        h, w = ch, cw
    down = _int_in(pre.get("downsample", 1), 1, MAX_DOWNSAMPLE, "preprocess.downsample", path)
    h, w = h // down, w // down
    params = acts = 0
    channels = 1
    for _ in range(n_conv):
        params += channels * width * kernel * kernel + 4 * width
        acts = max(acts, 2 * 3 * width * h * w)  # conv and batch-norm outputs of 3 images
        channels, h, w = width, h // 2, w // 2
    params += channels * h * w * fc + 2 * fc + 1
    need = 4 * (2 * params + acts)
    if need > MAX_CNN_BYTES:
        raise ValueError(
            f"{shown(path)}: the network it describes would need about {ft.format_bytes(need)} "
            f"(at most {ft.format_bytes(MAX_CNN_BYTES)}): width {width}, {n_conv} stages, fc {fc}"
        )


def _read_json(path: Path) -> Any:
    """A JSON file of at most :data:`MAX_META_BYTES` (a regular file), or ValueError."""
    with open_regular(path) as fh:
        raw = fh.read(MAX_META_BYTES + 1)
    if len(raw) > MAX_META_BYTES:
        raise ValueError(f"{shown(path)}: metadata larger than {ft.format_bytes(MAX_META_BYTES)}")
    return _loads(raw, path)


def _loads(raw: str | bytes, path: Path) -> Any:
    try:
        return json.loads(raw)
    except (ValueError, RecursionError) as e:
        raise ValueError(f"{shown(path)}: metadata is not JSON ({shown(e, limit=200)})") from None


def _checkpoint_file(path: Path) -> None:
    """Refuse a missing, non-regular or too large checkpoint before torch opens it."""
    try:
        size = regular_file(path).st_size
    except FileNotFoundError:
        raise FileNotFoundError(f"checkpoint not found: {shown(path)}") from None
    if size > MAX_CHECKPOINT_BYTES:
        raise ValueError(
            f"{shown(path)}: checkpoint of {ft.format_bytes(size)} (at most {ft.format_bytes(MAX_CHECKPOINT_BYTES)})"
        )


def _torch_reason(e: BaseException) -> str:
    """torch's refusal in one line: the unpickler's own reason when it gives one, else its first line."""
    text = str(e) if not isinstance(e, KeyError) else f"{type(e).__name__}: {e}"
    marker = "WeightsUnpickler error:"
    if marker in text:
        text = text.split(marker, 1)[1].split(" Please use", 1)[0]
    return shown(text.strip().splitlines()[0] if text.strip() else type(e).__name__, limit=200)


def _torch_load(path: Path) -> dict[str, Any]:
    """The checkpoint's dict, read by torch with ``weights_only=True`` (no pickled code); any
    refusal is one line naming the file (torch's own text is several lines and advises
    ``weights_only=False``, which flowtact never does)."""
    torch = import_torch()
    _checkpoint_file(path)
    with open_regular(path) as fh:
        try:
            blob = torch.load(fh, map_location="cpu", weights_only=True)
        except Exception as e:  # noqa: BLE001 - torch raises many types for a foreign file
            raise ValueError(
                f"{shown(path)}: not a flowtact CNN checkpoint (torch refused it: {_torch_reason(e)})"
            ) from None
    if not isinstance(blob, dict) or blob.get("format") != CHECKPOINT_FORMAT:
        raise ValueError(f"{shown(path)}: not a flowtact force-CNN checkpoint")
    if not isinstance(blob.get("meta"), str) or len(blob["meta"]) > MAX_META_BYTES:
        raise ValueError(f"{shown(path)}: not a flowtact force-CNN checkpoint (no metadata text)")
    return blob


def read_meta(path: str | Path) -> dict[str, Any]:
    """A checkpoint's metadata: from the .json beside it (no torch), else from the .pt itself;
    range-checked (:func:`_check_meta`) before anything uses it."""
    path = Path(path)
    _checkpoint_file(path)
    side = _sidecar(path)
    if side.exists() and side != path:
        return _check_meta(_read_json(side), path)
    if path.suffix == ".json":
        raise ValueError(f"{shown(path)}: give the .pt checkpoint, not its metadata")
    return _check_meta(_loads(_torch_load(path)["meta"], path), path)


def model_from_meta(meta: Mapping[str, Any]) -> Any:
    """An untrained ``ForceCNN`` with the architecture and preprocessing a checkpoint describes."""
    pre = meta["preprocess"]
    crop = pre.get("crop")
    return build_model(
        Arch(**meta["arch"]),
        Preprocess(tuple(pre["input_hw"]), None if crop is None else tuple(crop), int(pre["downsample"])),
        float(meta.get("pixel_mean", 0.0)),
        float(meta.get("pixel_std", 1.0)),
    )


def load_checkpoint(path: str | Path) -> tuple[Any, dict[str, Any]]:
    """``(model in eval mode, metadata)`` from a checkpoint written by :func:`save_checkpoint`.

    The metadata embedded in the .pt is authoritative (the .json beside it is a copy for tools);
    it is range-checked before the network is built, and the file is read by torch with
    ``weights_only=True``.
    """
    path = Path(path)
    blob = _torch_load(path)
    meta = _check_meta(_loads(blob["meta"], path), path)
    model = model_from_meta(meta)
    model.load_state_dict(blob["state_dict"])
    model.eval()
    return model, meta


# -- the block --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CnnForceConfig(ft.Config):
    """Parameters of :class:`CnnForce`."""

    checkpoint: str | None = ft.param(
        None,
        doc="checkpoint (.pt) written by 'flowtact train-force' (relative: to the graph file); null: the "
        "small model shipped with flowtact",
        path=True,
    )
    clip_negative: bool = ft.param(
        True, doc="clip estimates below 0 N to 0 (a pressed fingertip pushes, never pulls)"
    )


class CnnForce(ft.Block):
    """Contact force per TacTip from its camera frame with a trained CNN (one batched call per frame).

    Config
    ------
    See :class:`CnnForceConfig`. ``checkpoint: null`` uses the shipped model
    (``flowtact/blocks/teleop/models/force_cnn_w16.pt``; its .json says how it was trained and its test MAE).

    Notes
    -----
    Each frame is ONE forward call on a batch of its S sensor images (the thesis's "querying the
    network with a batch comprised of one image from each sensor"), in eval mode (batch norm uses
    its running statistics) under ``torch.inference_mode``. Frames are never batched across time:
    torch's CPU kernels round differently for another batch size (measured: one batch of 16 frames'
    48 images vs 16 calls of 3 differ in the last float32 bit in 6–13 of the 48 outputs, for w16 to
    the paper's width), and one call per frame keeps the output bit-for-bit independent of how
    frames are chunked. The network's float32 output is de-standardised in float64
    (``y = z·label_std + label_mean``) and, with ``clip_negative``, clipped at 0 N. Stateless
    across frames; latency: one forward pass (``flowtact bench force_estimation`` measures it per
    width: ≈ 0.7 ms per 3-frame call for the shipped w16 on one core of the project machine).

    The shipped model (w16, 13 585 parameters, 22×60 input: the 90×240 crop pooled by 4) was trained
    on ``graphs/tactip_dataset.yaml`` (3 000 tactip_sim frames × 3 sensors): MAE 0.022 N on its
    random 5 % test split, 0.081 N on a held-out tactip_sim run (new contact positions). It knows
    emulated TacTips only: train your own on real recordings.

    torch is imported in ``open``/``reset``, never at module import, and the block calls
    ``torch.set_num_threads(1)``: a 3-image batch of a small network gains nothing from more
    threads, and the setting is process-wide (other torch users in the same worker get one
    intra-op thread too). The frame size is checked against the checkpoint's metadata when the
    graph is compiled (from the .json beside the .pt, without torch).

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.teleop.cnn import CnnForce
    >>> from flowtact.testing import run_offline
    >>> frames = CnnForce.example().inputs["x"]                 # (n, 3, 90, 240) uint8
    >>> out = run_offline(CnnForce(), x=frames, rate_hz=40.0, units={"x": "DN"})
    >>> out["y"].data.shape, bool(np.isfinite(out["y"].data).all())
    ((40, 3), True)
    """

    name = "cnn_force"
    config_cls = CnnForceConfig
    requires = {"torch": "cnn"}
    inputs = {
        "x": ft.Port(
            dtype="uint8",
            units="DN",
            ndim=(3,),
            require_rate=True,
            doc=(
                "one gray frame per sensor (S = 3: thumb, index, middle). Either whole frames of the size"
                " the checkpoint was trained on (its preprocess.input_hw; the block applies the "
                "checkpoint's crop) or frames already cropped to the checkpoint's crop size (e.g. from a "
                "crop node with the same window: the block then trusts that the window is the same)"
            ),
        )
    }
    outputs = {
        "y": ft.Port(
            dtype="float64",
            shape=None,
            units="N",
            doc=(
                "estimated contact force per sensor, shape (S,), at x's rate, stamped like the frame; "
                "labels thumb, index, middle when S = 3; end follows x's watermark"
            ),
        )
    }

    def __init__(self, *args: Any, **kw: Any) -> None:
        super().__init__(*args, **kw)
        self._model: Any = None
        self._meta: dict[str, Any] | None = None

    def checkpoint_path(self) -> Path:
        """The checkpoint this block uses (the configured one, or the shipped one)."""
        c = self.config.checkpoint
        return shipped_checkpoint() if c is None else Path(c).expanduser()

    def _read_meta(self) -> dict[str, Any]:
        """The checkpoint's metadata: as loaded by ``open``, else read now (and not kept: specs() is pure)."""
        if self._meta is not None:
            return self._meta
        try:
            return read_meta(self.checkpoint_path())
        except (FileNotFoundError, ValueError, KeyError, TypeError, OSError) as e:
            raise ft.SpecError(None, f"{self.node} ({self.name}): checkpoint: {shown(e)}") from None

    def specs(self, inputs: Mapping[str, ft.StreamSpec]) -> dict[str, ft.StreamSpec]:
        x = inputs["x"]
        self._check_size(self._read_meta(), tuple(x.shape[1:]))
        s = x.shape[0]
        labels = FINGERS if s == len(FINGERS) else None
        return {"y": ft.StreamSpec(dtype="float64", shape=(s,), units="N", rate_hz=x.rate_hz, labels=labels)}

    def _check_size(self, meta: Mapping[str, Any], hw: tuple[int, ...]) -> bool:
        """Whether frames of size ``hw`` come cropped already; SpecError if the checkpoint cannot take them."""
        pre = meta["preprocess"]
        full = tuple(pre["input_hw"])
        crop = pre.get("crop")
        cropped = full if crop is None else (crop[3], crop[2])
        if hw not in (full, cropped):
            sizes = f"{full[0]}×{full[1]}" + (
                "" if cropped == full else f" (or {cropped[0]}×{cropped[1]} crops)"
            )
            raise ft.SpecError(
                "x",
                f"{self.node} ({self.name}): frames are {hw[0]}×{hw[1]} but checkpoint "
                f"{self.checkpoint_path().name} was trained on {sizes} frames; feed frames of that size "
                "or train a model on yours (flowtact train-force)",
            )
        return hw != full

    def open(self) -> None:
        self._load()

    def _load(self) -> None:
        if self._model is not None:
            return
        torch = import_torch()
        torch.set_num_threads(1)
        path = self.checkpoint_path()
        try:
            self._model, meta = load_checkpoint(path)
        except (FileNotFoundError, ValueError, KeyError, TypeError, RuntimeError, OSError) as e:
            raise ft.SpecError(
                None,
                f"{self.node} ({self.name}): cannot load checkpoint {shown(path)}: {shown(e, limit=500)}",
            ) from None
        self._meta = meta

    def reset(self) -> None:
        self._load()
        self._torch = import_torch()
        torch = self._torch
        torch.set_num_threads(1)
        meta = self._meta
        assert meta is not None
        spec = self.input_specs["x"]
        self._n = spec.shape[0]
        self._cropped = self._check_size(meta, tuple(spec.shape[1:]))  # the .pt's own metadata
        self._std = float(meta["label_std_n"])
        self._mean = float(meta["label_mean_n"])

    def close(self) -> None:
        self._model = None

    def step(self, x: ft.Chunk) -> dict[str, ft.Chunk]:
        n = len(x)
        z = np.empty((n, self._n), np.float32)
        torch, model = self._torch, self._model
        with torch.inference_mode():
            for i in range(n):
                frame = torch.from_numpy(np.array(x.data[i], copy=True))
                z[i] = model.predict(frame, cropped=self._cropped).numpy()
        y = z.astype(np.float64) * self._std + self._mean
        if self.config.clip_negative:
            np.maximum(y, 0.0, out=y)
        return {"y": ft.Chunk(x.t, y, x.end)}

    @classmethod
    def example(cls) -> ft.Example:
        return ft.Example(
            params={}, inputs={"x": _example_frames()}, rate_hz=40.0, units={"x": "DN"}, duration_s=1.0
        )


def _example_frames(n: int = 40) -> np.ndarray:
    """``n`` cropped (3, 90, 240) frames of the emulated TacTips under one press rising to 5 N and
    back (``tactip_sim``'s renderer, which the shipped model was trained on)."""
    press = 0.5 - 0.5 * np.cos(np.linspace(0.0, 2 * np.pi, n))
    return example_frames(5.0 * press, seed=1)
