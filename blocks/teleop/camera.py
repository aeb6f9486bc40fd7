"""Cameras: gray frames from OpenCV devices, video files or image folders, one per tactile sensor.

``camera`` is the hardware twin of ``tactip_sim``: the same ``frames`` stream (n_sensors, 240,
320) uint8 "DN" at a set frame rate, read from the TacTips' USB cameras (OpenCV ``VideoCapture``
on a device index), from recorded videos, or from folders of images. OpenCV is imported when the
devices are opened, never at module import.
"""

from __future__ import annotations

import os
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from flowtact.block import Example, Port, Source, example_folder
from flowtact.chunk import Chunk, StreamSpec
from flowtact.errors import FlowtactError
from flowtact.inputs.limits import MAX_TICK_S
from flowtact.params import Config, param

from .hand import FINGERS

__all__ = ["IMAGE_SUFFIXES", "Camera", "CameraConfig", "CameraError"]

#: Files of an image folder that are read (sorted by name), case-insensitive.
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".webp")

_BACKENDS = {
    "any": "CAP_ANY",
    "v4l2": "CAP_V4L2",
    "dshow": "CAP_DSHOW",
    "msmf": "CAP_MSMF",
    "avfoundation": "CAP_AVFOUNDATION",
    "gstreamer": "CAP_GSTREAMER",
    "ffmpeg": "CAP_FFMPEG",
}


class CameraError(FlowtactError, RuntimeError):
    """A device could not be opened, or stopped delivering frames."""


@dataclass(frozen=True)
class CameraConfig(Config):
    devices: tuple[int | str, ...] = param(
        (0, 1, 2),
        doc="one entry per sensor (thumb, index, middle): a device index, a video file, or an image folder "
        "(relative: to the graph file)",
        ge=0,
        min_len=1,
        max_len=3,
        path=True,
    )
    fps: float = param(
        40.0, doc="frame rate of the output (graph time); each due frame reads every device", gt=0, le=1000
    )
    size: tuple[int, ...] = param(
        (320, 240),
        doc="output frame width, height in px (frames of another size are resized)",
        gt=0,
        min_len=2,
        max_len=2,
    )
    loop: bool = param(
        False, doc="video files and image folders start again at their end (else: stop emitting)"
    )
    backend: Literal["any", "v4l2", "dshow", "msmf", "avfoundation", "gstreamer", "ffmpeg"] = param(
        "any", doc="OpenCV capture backend for device indices and video files"
    )

    def state_bytes(self) -> dict[str, float]:
        """A frame per device and its resize buffers, and a longest tick of frames."""
        frame = float(self.size[0]) * self.size[1] * len(self.devices)
        return {"size": frame * (16 + self.fps * MAX_TICK_S)}


class _Folder:
    """Sorted image files of a folder read one by one (gray, 8 bit)."""

    def __init__(self, cv2: Any, path: Path, fps: float) -> None:
        self.cv2, self.path, self.fps = cv2, path, fps
        self.files = sorted(p for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file())
        if not self.files:
            raise CameraError(
                f"image folder {str(path)!r} holds no image files ({', '.join(IMAGE_SUFFIXES)})"
            )
        self.k = 0
        self.live = False

    def rewind(self) -> None:
        self.k = 0

    def read(self) -> tuple[np.ndarray | None, float]:
        if self.k >= len(self.files):
            return None, float("nan")
        f = self.files[self.k]
        img = self.cv2.imread(str(f), self.cv2.IMREAD_GRAYSCALE)
        if img is None:
            raise CameraError(f"cannot read image {str(f)!r} (not an image OpenCV can decode?)")
        t = self.k / self.fps
        self.k += 1
        return img, t

    def release(self) -> None:
        """Nothing to release."""


class _Capture:
    """An OpenCV VideoCapture on a device index, a device path or a video file."""

    def __init__(self, cv2: Any, source: int | str, api: int, live: bool, config: CameraConfig) -> None:
        self.cv2, self.source, self.live = cv2, source, live
        self.cap = cv2.VideoCapture(source, api)
        if not self.cap.isOpened():
            self.cap.release()
            kind = "camera device" if live else "video file"
            raise CameraError(
                f"cannot open {kind} {source!r} (cv2.VideoCapture failed): check that it is plugged in / "
                "readable and not used by another program; to run without cameras use the tactip_sim "
                "block (emulated TacTips) instead"
            )
        if live:  # best effort: drivers ignore what they cannot do
            self.cap.set(cv2.CAP_PROP_FRAME_WIDTH, config.size[0])
            self.cap.set(cv2.CAP_PROP_FRAME_HEIGHT, config.size[1])
            self.cap.set(cv2.CAP_PROP_FPS, config.fps)

    def rewind(self) -> None:
        if not self.live:
            self.cap.set(self.cv2.CAP_PROP_POS_FRAMES, 0)

    def read(self) -> tuple[np.ndarray | None, float]:
        ok, img = self.cap.read()
        if not ok or img is None:
            return None, float("nan")
        ms = float(self.cap.get(self.cv2.CAP_PROP_POS_MSEC))
        # a live driver without time stamps: stamp the arrival (see the block's Notes)
        return img, (time.monotonic() if self.live and not ms > 0 else ms / 1000.0)

    def release(self) -> None:
        self.cap.release()


class Camera(Source):
    """Gray frames from 1–3 cameras, video files or image folders (the TacTips' cameras), at a set FPS.

    Ports
    -----
    frames : uint8 (n, H, W), units "DN"
        One gray frame per device (axis 0 in ``devices`` order: thumb, index, middle for three),
        ``(H, W) = (size[1], size[0])``, default (240, 320): the ``tactip_sim`` stream.
    device_t : float64 (n,), units "s"
        Each frame's own time stamp: a video's position (``CAP_PROP_POS_MSEC``), an image
        folder's frame index / ``fps``, a live camera's driver time stamp (or ``time.monotonic()``
        at the read when the driver gives none).

    Config
    ------
    See the field docs (``flowtact blocks camera``).

    Notes
    -----
    *Devices.* An integer opens that camera index (``cv2.VideoCapture(i, backend)``; the block
    asks for ``size`` and ``fps`` and resizes whatever comes). A string names a video file (any
    format OpenCV reads, e.g. MJPG .avi), a capture device path such as ``/dev/video2``, a stream
    URL (``://``), or a folder of images read in name order (``IMAGE_SUFFIXES``). Colour frames
    are converted to gray (``cv2.COLOR_BGR2GRAY``; folders are read with
    ``cv2.IMREAD_GRAYSCALE``) and resized with ``cv2.INTER_AREA`` when their size differs. A
    device that cannot be opened fails at ``open()`` (or at the first step when the block is
    driven offline without ``open``) with a message naming it and pointing to ``tactip_sim``.

    *Timing.* The graph clock sets the frame times, ``t = k / fps`` (the Source counter); each
    due frame reads the next frame of every device, so a live camera should run at ``fps`` or
    faster (a read waits for the device's next frame: this is the only blocking, inside
    ``VideoCapture.read``; no sleep, no thread). ``device_t`` carries the device's own time
    stamps for latency and drift checks; live cameras read ``time.monotonic()`` only when their
    driver gives no time stamp. Every step sets ``end = now``.

    *End of data.* Video files and folders either start again (``loop: true``) or end: from the
    first device that runs out, the block emits no more frames (counted as ``ended``; the
    watermark still advances). A live camera that stops delivering (unplugged) raises
    :class:`CameraError` naming the device and the frame count. ``reset`` rewinds files and folders.

    Example
    -------
    >>> from flowtact.testing import run_source
    >>> ex = Camera.example()  # three small image folders written for the example
    >>> out = run_source(Camera(**ex.params), 0.5)
    >>> out["frames"].data.shape
    (20, 3, 240, 320)
    """

    config_cls = CameraConfig
    requires = {"cv2": "vision"}
    outputs = {
        "frames": Port(dtype="uint8", units="DN", doc="gray frames, one per device, (n, H, W)"),
        "device_t": Port(units="s", doc="each frame's own time stamp (video position, driver stamp)"),
    }
    counter_docs = {
        "ended": "a video file or image folder ran out of frames (loop: false): no frames after that; "
        "expected when playing a finite recording",
    }

    def __init__(self, config: Config | None = None, /, **kw: Any) -> None:
        super().__init__(config, **kw)
        self.sources: list[_Folder | _Capture] = []

    def specs(self, inputs: Mapping[str, StreamSpec]) -> dict[str, StreamSpec]:  # noqa: ARG002 — a source: its outputs come from its config
        c = self.config
        n = len(c.devices)
        w, h = c.size
        return {
            "frames": StreamSpec(dtype="uint8", shape=(n, h, w), units="DN", rate_hz=c.fps),
            "device_t": StreamSpec(
                shape=(n,), units="s", rate_hz=c.fps, labels=FINGERS if n == len(FINGERS) else None
            ),
        }

    # -- devices ----------------------------------------------------------------------------------
    def open(self) -> None:
        if self.sources:
            return
        try:
            import cv2
        except ImportError as e:  # pragma: no cover - the extra is installed in development
            raise CameraError(
                "the camera block needs OpenCV: pip install 'flowtact[vision]' (or use tactip_sim)"
            ) from e
        c = self.config
        api = getattr(cv2, _BACKENDS[c.backend])
        opened: list[_Folder | _Capture] = []
        try:
            for k, dev in enumerate(c.devices):
                opened.append(self._open_one(cv2, dev, api, k))
        except BaseException:
            for s in opened:
                s.release()
            raise
        self.sources = opened
        self._cv2 = cv2

    def _open_one(self, cv2: Any, dev: int | str, api: int, k: int) -> _Folder | _Capture:
        c = self.config
        who = f"{self.node}: sensor {k} ({FINGERS[k] if len(c.devices) == len(FINGERS) else k})"
        try:
            if isinstance(dev, int):
                return _Capture(cv2, dev, api, True, c)
            if "://" in dev:
                return _Capture(cv2, dev, api, True, c)
            path = Path(os.path.expanduser(dev))
            if path.is_dir():
                return _Folder(cv2, path, c.fps)
            if path.exists():
                live = not path.is_file()  # a character device such as /dev/video0
                return _Capture(cv2, str(path), api, live, c)
            raise CameraError(
                f"no such device, video file or image folder: {dev!r}; to run without cameras use the "
                "tactip_sim block (emulated TacTips) instead"
            )
        except CameraError as e:
            raise CameraError(f"{who}: {e}") from None

    def close(self) -> None:
        for s in self.sources:
            s.release()
        self.sources = []

    # -- streaming --------------------------------------------------------------------------------
    def reset(self) -> None:
        self.i = 0
        self.ended = False
        for s in self.sources:
            s.rewind()

    def _read(self, k: int, s: _Folder | _Capture) -> tuple[np.ndarray | None, float]:
        img, t = s.read()
        if img is None and not s.live and self.config.loop:
            s.rewind()
            img, t = s.read()
            if img is None:
                raise CameraError(f"{self.node}: device {self.config.devices[k]!r} delivers no frame at all")
        if img is None and s.live:
            raise CameraError(
                f"{self.node}: device {self.config.devices[k]!r} stopped delivering frames after "
                f"{self.i} frame(s) (VideoCapture.read failed: unplugged or stalled?)"
            )
        return img, t

    def _gray(self, img: np.ndarray) -> np.ndarray:
        cv2 = self._cv2
        if img.ndim == 3:
            img = cv2.cvtColor(img, cv2.COLOR_BGRA2GRAY if img.shape[2] == 4 else cv2.COLOR_BGR2GRAY)
        if img.dtype != np.uint8:
            img = cv2.convertScaleAbs(img, alpha=255.0 / max(float(np.iinfo(img.dtype).max), 1.0))
        w, h = self.config.size
        if img.shape != (h, w):
            img = cv2.resize(img, (w, h), interpolation=cv2.INTER_AREA)
        return img

    def step(self, now: float) -> dict[str, Chunk]:
        c = self.config
        if not self.sources:
            self.open()  # driven offline (run_source) without the runtime's open()
            self.reset()
        n_dev = len(c.devices)
        w, h = c.size
        due = self.due(now, c.fps)
        start = self.i
        frames: list[np.ndarray] = []
        stamps: list[np.ndarray] = []
        while self.i < due and not self.ended:
            stack = np.empty((n_dev, h, w), np.uint8)
            dev_t = np.empty(n_dev)
            for k, s in enumerate(self.sources):
                img, t = self._read(k, s)
                if img is None:
                    self.ended = True
                    self.count("ended")
                    break
                stack[k] = self._gray(img)
                dev_t[k] = t
            if self.ended:
                break
            frames.append(stack)
            stamps.append(dev_t)
            self.i += 1
        n = len(frames)
        t = (start + np.arange(n)) / c.fps
        data = np.stack(frames) if n else np.empty((0, n_dev, h, w), np.uint8)
        out: dict[str, Chunk] = {}
        if "frames" in self.demanded:
            out["frames"] = Chunk(t, data, now)
        if "device_t" in self.demanded:
            out["device_t"] = Chunk(t, np.stack(stamps) if n else np.empty((0, n_dev)), now)
        return out

    @classmethod
    def example(cls) -> Example:
        return Example(params={"devices": _example_folders(), "loop": True}, rate_hz=40.0, duration_s=0.5)


def _example_folders() -> list[str]:
    """Three small image folders (8 emulated TacTip frames each, 160×120 PGM) in this process's
    private example folder (:func:`flowtact.block.example_folder`; never a fixed name in the shared
    temp directory, which another user could plant as a symlink), written once per process.

    Written with numpy only (no OpenCV needed to write them); a rest frame then taps of rising
    force, so the example shows moving pins and exercises the resize.
    """
    from .tactip_sim import render, scenario_contacts

    root = example_folder() / "camera"
    names = [str(root / f) for f in FINGERS]
    if all((Path(d) / "frame_007.pgm").is_file() for d in names):
        return names
    t = np.arange(8) / 8.0
    truth = scenario_contacts({"tap_period_s": 0.25, "tap_s": 0.2, "onset_s": 0.0, "levels": 4}, 1, t)
    frames = render(truth.force, truth.position, np.arange(8), 1, shear=truth.shear, size=truth.size)
    small = frames.reshape(8, 3, 120, 2, 160, 2).mean(axis=(3, 5)).round().astype(np.uint8)
    for s, d in enumerate(names):
        Path(d).mkdir(parents=True, exist_ok=True)
        for k in range(8):
            (Path(d) / f"frame_{k:03d}.pgm").write_bytes(b"P5\n160 120\n255\n" + small[k, s].tobytes())
    return names
