"""TacTip image processing (White 2023, §3.1.1): crop, Gaussian adaptive threshold, blob detection, blob mask.

Frames are uint8 stacks (n, H, W), one grayscale image per sensor (thumb, index, middle), units
``"DN"``; every block maps one frame stack to one output sample with the same time stamp and
passes the frames' watermark on (``out.end = in.end``). Per-sensor parameters are tuples with one
value per sensor (or a single value used for every sensor).

OpenCV (``cv2``, the ``vision`` extra) is imported lazily inside the blocks that need it, never at
module import: ``crop`` and ``blob_mask`` are numpy/numba only.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Literal

import numpy as np
from numba import njit

from flowtact import Block, Chunk, Config, Example, Port, SpecError, StreamSpec, param
from flowtact.inputs.limits import MAX_TICK_S
from flowtact.streams.align import Aligner

from .hand import FINGERS
from .tactip_sim import pressed_frames

__all__ = [
    "TABLE_3_1",
    "AdaptiveThreshold",
    "AdaptiveThresholdConfig",
    "BlobDetect",
    "BlobDetectConfig",
    "BlobMask",
    "BlobMaskConfig",
    "Crop",
    "CropConfig",
    "blob_mask_numpy",
    "centre_crop",
    "example_frames",
]

#: Camera frame of the thesis's TacTips: 320 wide × 240 high, cropped to 240 wide × 90 high.
FRAME_W, FRAME_H = 320, 240
CROP_W, CROP_H = 240, 90

#: White 2023, Table 3.1: "optimal blob detection parameters found by the cross-entropy
#: optimisation procedure" (objective 30 − number of blobs), per sensor. The table's columns are
#: Index, Middle, Thumb; here they are re-ordered to flowtact's finger order (thumb, index, middle).
TABLE_3_1: dict[str, tuple[float, float, float]] = {
    #                  thumb  index  middle
    "min_threshold": (25.8, 20.3, 48.1),
    "max_threshold": (161.2, 176.3, 235.4),
    "min_area": (33.4, 23.2, 42.0),
    "max_area": (156.9, 131.2, 109.8),
    "min_circularity": (0.453, 0.495, 0.475),
    "min_inertia": (0.553, 0.453, 0.537),
    "min_convexity": (0.382, 0.71, 0.658),
}


# -- shared helpers ----------------------------------------------------------------------------------


def _per_sensor(block: Block, field: str, values: Sequence[Any], n: int) -> list[Any]:
    """A per-sensor tuple expanded to ``n`` values (one value is used for every sensor)."""
    if len(values) == 1:
        return list(values) * n
    if len(values) != n:
        raise SpecError(
            None,
            f"{block.node} ({block.name}): '{field}' has {len(values)} values but the frames have {n} "
            "sensors (give one value per sensor, or a single value for all)",
        )
    return list(values)


def _labels(n: int) -> tuple[str, ...] | None:
    return FINGERS if n == len(FINGERS) else None


def _frames_out(x: Chunk, data: np.ndarray) -> Chunk:
    return Chunk(x.t, data, x.end)


# -- example frames: emulated TacTips (examples, tests and benches) ----------------------------------


def centre_crop(frames: np.ndarray) -> np.ndarray:
    """The thesis's 240 × 90 window centred in (…, 240, 320) frames (the :class:`Crop` default), a view."""
    x0, y0 = (FRAME_W - CROP_W) // 2, (FRAME_H - CROP_H) // 2
    return frames[..., y0 : y0 + CROP_H, x0 : x0 + CROP_W]


def example_frames(forces_n: Sequence[float], *, crop: bool = True, seed: int = 11) -> np.ndarray:
    """Frame stacks (n, 3, H, W) of the three emulated TacTips (``tactip_sim``) pressed with one
    normal force per frame, in N, cropped to the thesis window unless ``crop=False``.

    A fresh copy of a cached render: the conformance suite asks for block examples many times.
    """
    return _example_frames_cached(tuple(float(f) for f in forces_n), crop, seed).copy()


@lru_cache(maxsize=8)
def _example_frames_cached(forces_n: tuple[float, ...], crop: bool, seed: int) -> np.ndarray:
    frames = pressed_frames(forces_n, seed)
    return np.ascontiguousarray(centre_crop(frames)) if crop else frames


# -- crop ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CropConfig(Config):
    """Parameters of :class:`Crop`."""

    x0_px: tuple[int, ...] = param(
        ((FRAME_W - CROP_W) // 2,) * 3,
        doc="left column of each sensor's crop (one per sensor, or one for all)",
        ge=0,
        min_len=1,
    )
    y0_px: tuple[int, ...] = param(
        ((FRAME_H - CROP_H) // 2,) * 3,
        doc="top row of each sensor's crop (one per sensor, or one for all)",
        ge=0,
        min_len=1,
    )
    width_px: int = param(CROP_W, doc="crop width in pixels (the thesis: 240)", ge=1)
    height_px: int = param(CROP_H, doc="crop height in pixels (the thesis: 90)", ge=1)


class Crop(Block):
    """Crop each sensor's frame to a window (White 2023: 320×240 → 90×240 around the pins).

    Ports
    -----
    x : uint8, shape (n, H, W), units "DN" — frames, one per sensor
    y : uint8, shape (n, height_px, width_px), units "DN" — the crops (contiguous copies)

    Config
    ------
    See :class:`CropConfig`. Default: the thesis's 240 wide × 90 high crop, centred in a
    320 × 240 frame (origin x0 = 40, y0 = 75 for every sensor); set ``x0_px``/``y0_px`` per
    sensor to follow where each TacTip's pins sit in its camera image.

    Notes
    -----
    Stateless, latency 0, numpy only. The compiler checks that every crop fits in the frame.

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.teleop.image import Crop
    >>> from flowtact.testing import run_offline
    >>> frames = np.arange(2 * 3 * 240 * 320, dtype=np.int64).reshape(2, 3, 240, 320).astype(np.uint8)
    >>> y = run_offline(Crop(), x=frames, rate_hz=40.0, units={"x": "DN"})["y"].data
    >>> y.shape, bool((y[1, 2] == frames[1, 2, 75:165, 40:280]).all())
    ((2, 3, 90, 240), True)
    """

    name = "crop"
    config_cls = CropConfig
    inputs = {
        "x": Port(dtype="uint8", units="DN", ndim=(3,), require_rate=True, doc="frames (sensors, H, W)")
    }
    outputs = {
        "y": Port(
            dtype="uint8",
            units="DN",
            ndim=(3,),
            require_rate=True,
            doc="cropped frames (sensors, height_px, width_px)",
        )
    }

    def specs(self, inputs: Mapping[str, StreamSpec]) -> dict[str, StreamSpec]:
        n, h, w = inputs["x"].shape
        c = self.config
        for s, (x0, y0) in enumerate(
            zip(_per_sensor(self, "x0_px", c.x0_px, n), _per_sensor(self, "y0_px", c.y0_px, n), strict=True)
        ):
            if x0 + c.width_px > w or y0 + c.height_px > h:
                raise SpecError(
                    "x",
                    f"crop of sensor {s} (x0={x0}, y0={y0}, {c.width_px}×{c.height_px}) does not fit in "
                    f"the {w}×{h} frames (x0 + width_px <= {w} and y0 + height_px <= {h} needed)",
                )
        return {"y": inputs["x"].with_(shape=(n, c.height_px, c.width_px), labels=None)}

    def reset(self) -> None:
        n = self.input_specs["x"].shape[0]
        c = self.config
        self._x0 = _per_sensor(self, "x0_px", c.x0_px, n)
        self._y0 = _per_sensor(self, "y0_px", c.y0_px, n)

    def step(self, x: Chunk) -> dict[str, Chunk]:
        c = self.config
        n = len(self._x0)
        out = np.empty((len(x), n, c.height_px, c.width_px), np.uint8)
        for s in range(n):
            x0, y0 = self._x0[s], self._y0[s]
            out[:, s] = x.data[:, s, y0 : y0 + c.height_px, x0 : x0 + c.width_px]
        return {"y": _frames_out(x, out)}

    @classmethod
    def example(cls) -> Example:
        return Example(
            params={"x0_px": [40, 38, 42], "y0_px": [75]},
            inputs={"x": example_frames(range(5), crop=False)},
            rate_hz=40.0,
            units={"x": "DN"},
            duration_s=5 / 40.0,
        )


# -- adaptive_threshold --------------------------------------------------------------------------------


@dataclass(frozen=True)
class AdaptiveThresholdConfig(Config):
    """Parameters of :class:`AdaptiveThreshold`."""

    c_dn: float = param(-25.0, doc="constant C subtracted from the Gaussian local mean (the thesis: -25)")
    radius_px: int = param(
        15, doc="radius of the local region (the thesis: 15); block size 2·radius + 1", ge=1
    )


class AdaptiveThreshold(Block):
    """Gaussian adaptive threshold of each sensor's frame (White 2023, eq. 3.1: T = mean_G(I_L) − C).

    Ports
    -----
    x : uint8, shape (n, H, W), units "DN" — frames
    y : uint8, same shape, units "DN" — 255 where the pixel exceeds its threshold T, else 0

    Config
    ------
    See :class:`AdaptiveThresholdConfig`: the thesis's C = −25 and radius 15.

    Notes
    -----
    Exactly ``cv2.adaptiveThreshold(img, 255, cv2.ADAPTIVE_THRESH_GAUSSIAN_C,
    cv2.THRESH_BINARY, 2·radius_px + 1, c_dn)`` per image: T is the Gaussian-weighted mean of
    the (2r+1)² neighbourhood (σ from OpenCV's rule for that size, replicated borders) minus C;
    with C = −25 a pixel is set (255) when it is 25 DN brighter than its surroundings, which
    keeps the bright pins and drops the skin. Stateless, latency 0. Needs the ``vision`` extra.

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.teleop.image import AdaptiveThreshold
    >>> from flowtact.testing import run_offline
    >>> frames = np.full((1, 1, 40, 40), 30, np.uint8)
    >>> frames[0, 0, 18:22, 18:22] = 200                  # one bright pin on dark skin
    >>> y = run_offline(AdaptiveThreshold(), x=frames, rate_hz=40.0, units={"x": "DN"})["y"].data
    >>> int(y.sum() // 255), int(y[0, 0, 20, 20])
    (16, 255)
    """

    name = "adaptive_threshold"
    config_cls = AdaptiveThresholdConfig
    requires = {"cv2": "vision"}
    inputs = {
        "x": Port(dtype="uint8", units="DN", ndim=(3,), require_rate=True, doc="frames (sensors, H, W)")
    }
    outputs = {
        "y": Port(dtype="uint8", units="DN", ndim=(3,), require_rate=True, doc="binary images (0 or 255)")
    }

    def specs(self, inputs: Mapping[str, StreamSpec]) -> dict[str, StreamSpec]:
        return {"y": inputs["x"].with_(labels=None)}

    def reset(self) -> None:
        import cv2

        self._cv2 = cv2
        self._block = 2 * self.config.radius_px + 1

    def step(self, x: Chunk) -> dict[str, Chunk]:
        cv2, c = self._cv2, self.config
        out = np.empty(x.data.shape, np.uint8)
        for i in range(len(x)):
            for s in range(x.data.shape[1]):
                img = np.ascontiguousarray(x.data[i, s])
                out[i, s] = cv2.adaptiveThreshold(
                    img, 255, cv2.ADAPTIVE_THRESH_GAUSSIAN_C, cv2.THRESH_BINARY, self._block, float(c.c_dn)
                )
        return {"y": _frames_out(x, out)}

    @classmethod
    def example(cls) -> Example:
        return Example(
            inputs={"x": example_frames(range(5))}, rate_hz=40.0, units={"x": "DN"}, duration_s=5 / 40.0
        )


# -- blob_detect ---------------------------------------------------------------------------------------


def _t31(key: str) -> tuple[float, ...]:
    return tuple(TABLE_3_1[key])


#: The fields of :class:`BlobDetectConfig` that take one value per sensor (or one for all).
_PER_SENSOR = (
    "min_threshold_dn",
    "max_threshold_dn",
    "min_area_px2",
    "max_area_px2",
    "min_circularity",
    "min_inertia_ratio",
    "min_convexity",
)


@dataclass(frozen=True)
class BlobDetectConfig(Config):
    """Parameters of :class:`BlobDetect` (per-sensor tuples default to White 2023, Table 3.1)."""

    min_threshold_dn: tuple[float, ...] = param(
        _t31("min_threshold"),
        doc="lowest binarisation threshold per sensor (Table 3.1)",
        ge=0,
        le=255,
        min_len=1,
    )
    max_threshold_dn: tuple[float, ...] = param(
        _t31("max_threshold"),
        doc="highest binarisation threshold per sensor (Table 3.1)",
        ge=0,
        le=256,
        min_len=1,
    )
    threshold_step_dn: float = param(
        10.0, doc="step between thresholds (OpenCV default; not in the thesis)", gt=0
    )
    min_area_px2: tuple[float, ...] = param(
        _t31("min_area"), doc="smallest blob area in px² per sensor (Table 3.1)", ge=0, min_len=1
    )
    max_area_px2: tuple[float, ...] = param(
        _t31("max_area"), doc="largest blob area in px² per sensor (Table 3.1)", gt=0, min_len=1
    )
    min_circularity: tuple[float, ...] = param(
        _t31("min_circularity"), doc="smallest 4πA/p² per sensor (Table 3.1)", ge=0, le=1, min_len=1
    )
    min_inertia_ratio: tuple[float, ...] = param(
        _t31("min_inertia"),
        doc="smallest minor/major axis ratio per sensor (Table 3.1 'Min Inertia')",
        ge=0,
        le=1,
        min_len=1,
    )
    min_convexity: tuple[float, ...] = param(
        _t31("min_convexity"),
        doc="smallest area / convex-hull area per sensor (Table 3.1)",
        ge=0,
        le=1,
        min_len=1,
    )
    min_dist_between_blobs_px: float = param(
        10.0, doc="blob centres closer than this are merged (OpenCV default; not in the thesis)", ge=0
    )
    min_repeatability: int = param(
        2, doc="thresholds a blob must appear at to count (OpenCV default; not in the thesis)", ge=1
    )
    blob_color: Literal["bright", "dark"] = param(
        "bright", doc="pins are bright on dark skin in TacTip images"
    )
    max_pins: int = param(30, doc="rows of the pins output (the TacTip's 30 pins)", ge=1)

    def state_bytes(self) -> dict[str, float]:
        """The pins output of a longest tick at 100 frames/s: (frames, sensors, max_pins, 3) float64."""
        sensors = max(len(getattr(self, f)) for f in _PER_SENSOR)
        return {"max_pins": 100 * MAX_TICK_S * sensors * self.max_pins * 3 * 8.0}

    def check(self) -> None:
        n = next((len(getattr(self, f)) for f in _PER_SENSOR if len(getattr(self, f)) > 1), 1)
        for f in _PER_SENSOR:
            if len(getattr(self, f)) not in (1, n):
                raise self.error(
                    f,
                    f"per-sensor lists must have the same length (or a single value); got {len(getattr(self, f))} "
                    f"values here and {n} in another list",
                )
        for lo, hi in (("min_threshold_dn", "max_threshold_dn"), ("min_area_px2", "max_area_px2")):
            a = self.per_sensor(lo, n)
            b = self.per_sensor(hi, n)
            for s in range(n):
                if not a[s] < b[s]:
                    raise self.error(
                        hi, f"must exceed {lo} for every sensor; sensor {s} has {a[s]:g} >= {b[s]:g}"
                    )

    def per_sensor(self, field: str, n: int) -> tuple[float, ...]:
        """The per-sensor list ``field`` for ``n`` sensors (a single value serves every sensor)."""
        v = getattr(self, field)
        return v * n if len(v) == 1 else v

    def n_sensors(self) -> int:
        """Sensors the per-sensor lists describe (1 if every list has a single value)."""
        return max(len(getattr(self, f)) for f in _PER_SENSOR)


class BlobDetect(Block):
    """Pin positions by OpenCV's SimpleBlobDetector with the thesis's per-sensor parameters (Table 3.1).

    Ports
    -----
    x : uint8, shape (n, H, W), units "DN" — raw (cropped) grayscale frames
    pins : float64, shape (n, max_pins, 3), units "px"
        Rows (x, y, diameter) of the detected blobs in the input image's pixel coordinates
        (pixel centres at integers, x = column, y = row), sorted by y then x; NaN rows after
        the last blob when fewer than ``max_pins`` were found.
    count : float64, shape (n,), units "1" — blobs detected per sensor (may exceed max_pins)

    Config
    ------
    See :class:`BlobDetectConfig`. Thresholds, area, circularity, inertia ratio and convexity
    default to Table 3.1 (columns re-ordered thumb, index, middle; ``TABLE_3_1``); the other
    detector settings are OpenCV's defaults, which the thesis does not mention changing.

    Notes
    -----
    Input: the thesis detects on the *unprocessed grayscale* image — Fig. 3.1 c shows "the
    unprocessed image with the detected blobs overlaid", and its threshold ranges (20–48 up to
    161–235 DN) only make sense on gray levels; on a 0/255 thresholded image every threshold
    gives the same binary image. Feed ``crop.y`` (or raw frames). ``blob_color: bright`` looks
    for bright pins (OpenCV ``blobColor = 255``) — TacTip pins are white tips on black skin.
    Each blob's diameter is OpenCV's keypoint ``size``. When more than ``max_pins`` blobs are
    found, the largest ``max_pins`` are kept (counted as ``pins_dropped``). Stateless, latency 0.
    About 0.6–1.3 ms per 90×240 image on one core. Needs the ``vision`` extra.

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.teleop.image import BlobDetect, example_frames
    >>> from flowtact.testing import run_offline
    >>> frames = example_frames([2.0])   # one sample: 3 emulated TacTips pressed with 2 N, cropped
    >>> out = run_offline(BlobDetect(), x=frames, rate_hz=40.0, units={"x": "DN"})
    >>> out["count"].data.tolist()
    [[30.0, 30.0, 30.0]]
    """

    name = "blob_detect"
    config_cls = BlobDetectConfig
    requires = {"cv2": "vision"}
    inputs = {
        "x": Port(
            dtype="uint8", units="DN", ndim=(3,), require_rate=True, doc="grayscale frames (sensors, H, W)"
        )
    }
    outputs = {
        "pins": Port(
            dtype="float64", units="px", doc="(sensors, max_pins, 3) rows x, y, diameter; NaN rows unused"
        ),
        "count": Port(dtype="float64", units="1", doc="number of blobs detected per sensor"),
    }
    counter_docs = {
        "pins_dropped": "blobs beyond max_pins in an image: the smallest left out of 'pins' ('count' "
        "includes them); if frequent, raise max_pins or tighten the detector",
    }

    def specs(self, inputs: Mapping[str, StreamSpec]) -> dict[str, StreamSpec]:
        n = inputs["x"].shape[0]
        if self.config.n_sensors() not in (1, n):
            raise SpecError(
                "x",
                f"the per-sensor parameters describe {self.config.n_sensors()} sensors but the frames have "
                f"{n} (give one value per sensor, or a single value for all)",
            )
        rate = inputs["x"].rate_hz
        return {
            "pins": StreamSpec(dtype="float64", shape=(n, self.config.max_pins, 3), units="px", rate_hz=rate),
            "count": StreamSpec(dtype="float64", shape=(n,), units="1", rate_hz=rate, labels=_labels(n)),
        }

    def reset(self) -> None:
        import cv2

        c = self.config
        n = self.input_specs["x"].shape[0]
        self._detectors = []
        for s in range(n):
            p = cv2.SimpleBlobDetector_Params()
            p.minThreshold = float(c.per_sensor("min_threshold_dn", n)[s])
            p.maxThreshold = float(c.per_sensor("max_threshold_dn", n)[s])
            p.thresholdStep = float(c.threshold_step_dn)
            p.minDistBetweenBlobs = float(c.min_dist_between_blobs_px)
            p.minRepeatability = int(c.min_repeatability)
            p.filterByColor = True
            p.blobColor = 255 if c.blob_color == "bright" else 0
            p.filterByArea = True
            p.minArea = float(c.per_sensor("min_area_px2", n)[s])
            p.maxArea = float(c.per_sensor("max_area_px2", n)[s])
            p.filterByCircularity = True
            p.minCircularity = float(c.per_sensor("min_circularity", n)[s])
            p.maxCircularity = 1e30  # OpenCV's default upper bounds: no limit
            p.filterByInertia = True
            p.minInertiaRatio = float(c.per_sensor("min_inertia_ratio", n)[s])
            p.maxInertiaRatio = 1e30
            p.filterByConvexity = True
            p.minConvexity = float(c.per_sensor("min_convexity", n)[s])
            p.maxConvexity = 1e30
            self._detectors.append(cv2.SimpleBlobDetector_create(p))

    def detect(self, image: np.ndarray, sensor: int) -> np.ndarray:
        """All blobs of one image as rows (x, y, diameter), sorted by y then x."""
        kps = self._detectors[sensor].detect(np.ascontiguousarray(image))
        rows = np.array([(k.pt[0], k.pt[1], k.size) for k in kps], np.float64).reshape(-1, 3)
        return rows[np.lexsort((rows[:, 0], rows[:, 1]))]

    def step(self, x: Chunk) -> dict[str, Chunk]:
        m, n = len(x), x.data.shape[1]
        p = self.config.max_pins
        pins = np.full((m, n, p, 3), np.nan)
        count = np.zeros((m, n))
        for i in range(m):
            for s in range(n):
                rows = self.detect(x.data[i, s], s)
                count[i, s] = len(rows)
                if len(rows) > p:
                    self.count("pins_dropped", len(rows) - p)
                    keep = np.sort(np.argsort(-rows[:, 2], kind="stable")[:p])
                    rows = rows[keep]
                pins[i, s, : len(rows)] = rows
        out = {"pins": Chunk(x.t, pins, x.end), "count": Chunk(x.t, count, x.end)}
        return {k: v for k, v in out.items() if k in self.demanded}

    @classmethod
    def example(cls) -> Example:
        return Example(
            inputs={"x": example_frames(range(5))}, rate_hz=40.0, units={"x": "DN"}, duration_s=5 / 40.0
        )


# -- blob_mask -----------------------------------------------------------------------------------------


@njit(cache=True)
def _mask_kernel(frames, pins, scale, out):
    """``out`` = ``frames`` inside any pin circle (radius scale·d/2 about (x, y)), 0 elsewhere."""
    k, n, hh, ww = frames.shape
    npins = pins.shape[2]
    for f in range(k):
        for s in range(n):
            for i in range(hh):
                for j in range(ww):
                    out[f, s, i, j] = 0
            for q in range(npins):
                x = pins[f, s, q, 0]
                y = pins[f, s, q, 1]
                d = pins[f, s, q, 2]
                if not (np.isfinite(x) and np.isfinite(y) and np.isfinite(d)) or d <= 0.0:
                    continue
                r = scale * d / 2.0
                r2 = r * r
                i0 = max(int(np.floor(y - r)) - 1, 0)
                i1 = min(int(np.ceil(y + r)) + 1, hh - 1)
                j0 = max(int(np.floor(x - r)) - 1, 0)
                j1 = min(int(np.ceil(x + r)) + 1, ww - 1)
                for i in range(i0, i1 + 1):
                    dy = i - y
                    for j in range(j0, j1 + 1):
                        dx = j - x
                        if dx * dx + dy * dy <= r2:
                            out[f, s, i, j] = frames[f, s, i, j]


def blob_mask_numpy(frames: np.ndarray, pins: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """Plain-numpy twin of the mask kernel: frames (k, n, H, W) uint8, pins (k, n, P, 3)."""
    k, n, hh, ww = frames.shape
    ii = np.arange(hh, dtype=np.float64)[:, None]
    jj = np.arange(ww, dtype=np.float64)[None, :]
    out = np.zeros_like(frames)
    for f in range(k):
        for s in range(n):
            keep = np.zeros((hh, ww), bool)
            for x, y, d in pins[f, s]:
                if not (np.isfinite(x) and np.isfinite(y) and np.isfinite(d)) or d <= 0.0:
                    continue
                r = scale * d / 2.0
                dy, dx = ii - y, jj - x
                keep |= dx * dx + dy * dy <= r * r
            out[f, s][keep] = frames[f, s][keep]
    return out


@dataclass(frozen=True)
class BlobMaskConfig(Config):
    """Parameters of :class:`BlobMask`."""

    scale: float = param(
        1.0, doc="circle diameter kept around each pin, as a multiple of the blob diameter", gt=0
    )


class BlobMask(Block):
    """Keep only the pins: each frame masked to circles at the detected blobs (White 2023, Fig. 3.1 d).

    Ports
    -----
    x : uint8, shape (n, H, W), units "DN" — frames (the ones the blobs were detected on)
    pins : float64, shape (n, P, 3), units "px" — ``blob_detect.pins`` rows (x, y, diameter)
    y : uint8, shape (n, H, W), units "DN" — the frame inside the circles, 0 elsewhere

    Config
    ------
    See :class:`BlobMaskConfig`: ``scale`` 1 keeps a disc of the blob's own diameter.

    Notes
    -----
    A pixel (row i, column j) is kept when (j − x)² + (i − y)² <= (scale·d/2)² for some pin
    (pixel centres at integer coordinates, OpenCV's keypoint convention). Rows with a
    non-finite value or a diameter <= 0 are no pin (``blob_detect`` pads with NaN rows), so
    there is no bad-data policy here. ``x`` and ``pins`` are paired sample by sample (they come
    from one camera stream, ``pins`` through ``blob_detect``) and must carry the same times;
    the output's watermark is the earlier of the two inputs'. Latency: that of the later input.
    numba kernel, numpy twin ``blob_mask_numpy``.

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.teleop.image import BlobMask
    >>> from flowtact.testing import run_offline
    >>> frames = np.full((1, 1, 9, 9), 50, np.uint8)
    >>> pins = np.array([[[[4.0, 4.0, 3.0], [np.nan, np.nan, np.nan]]]])   # one pin, one empty row
    >>> y = run_offline(BlobMask(), x=frames, pins=pins, rate_hz=40.0, units={"x": "DN", "pins": "px"})
    >>> int((y["y"].data > 0).sum())                      # the 3×3 disc of radius 1.5 about (4, 4)
    9
    """

    name = "blob_mask"
    config_cls = BlobMaskConfig
    inputs = {
        "x": Port(dtype="uint8", units="DN", ndim=(3,), require_rate=True, doc="frames (sensors, H, W)"),
        "pins": Port(
            dtype="float64",
            units="px",
            ndim=(3,),
            require_rate=True,
            doc="pin rows (x, y, diameter) per sensor, NaN rows ignored",
        ),
    }
    outputs = {
        "y": Port(dtype="uint8", units="DN", ndim=(3,), require_rate=True, doc="frames masked to the pins")
    }
    counter_docs = {
        "unpaired_at_end": "frames or pin rows with no partner on the other input when the stream ended: "
        "not masked ('x' and 'pins' delivered different numbers of samples)",
    }

    def specs(self, inputs: Mapping[str, StreamSpec]) -> dict[str, StreamSpec]:
        n = inputs["x"].shape[0]
        pins = inputs["pins"]
        if pins.shape[2] != 3:
            raise SpecError(
                "pins", f"input 'pins' must be rows (x, y, diameter): (sensors, pins, 3); got {pins.shape}"
            )
        if pins.shape[0] != n:
            raise SpecError("pins", f"'pins' has {pins.shape[0]} sensors but the frames have {n}")
        if pins.units != "px":
            raise SpecError("pins", f"input 'pins' must be in 'px', got '{pins.units}'")
        if not math.isclose(pins.rate_hz or 0.0, inputs["x"].rate_hz or 0.0, rel_tol=1e-9):
            raise SpecError(
                "pins", f"'pins' is {pins.rate_hz} Hz but the frames are {inputs['x'].rate_hz} Hz"
            )
        return {"y": inputs["x"].with_(labels=None)}

    def reset(self) -> None:
        rate = self.input_specs["x"].rate_hz or 1.0
        self._align = Aligner(self.node, self.input_specs, ["x", "pins"], tol_s=1e-6 / rate)
        self._ends: dict[str, float] = {}
        self._shape = tuple(self.input_specs["x"].shape)

    def step(self, **inputs: Chunk) -> dict[str, Chunk]:
        for p, c in inputs.items():
            if c.end is not None:
                self._ends[p] = max(self._ends.get(p, -math.inf), c.end)
        t, data = self._align.push(inputs)
        frames = np.ascontiguousarray(data["x"], np.uint8).reshape(len(t), *self._shape)
        pins = np.ascontiguousarray(data["pins"], np.float64)
        out = np.empty(frames.shape, np.uint8)
        if len(t):
            _mask_kernel(frames, pins, float(self.config.scale), out)
        end = min(self._ends.values()) if len(self._ends) == 2 else None
        return {"y": Chunk(t, out, end)}

    def flush(self) -> dict[str, Chunk]:
        self.count("unpaired_at_end", sum(self._align.pending().values()))
        return {}

    @classmethod
    def example(cls) -> Example:
        frames = example_frames(range(5))
        rng = np.random.default_rng(3)
        pins = np.full((5, 3, 30, 3), np.nan)
        for i in range(5):
            for s in range(3):
                k = 20 + i
                pins[i, s, :k, 0] = rng.uniform(0, 240, k)
                pins[i, s, :k, 1] = rng.uniform(0, 90, k)
                pins[i, s, :k, 2] = rng.uniform(6, 10, k)
        return Example(
            inputs={"x": frames, "pins": pins},
            rate_hz=40.0,
            units={"x": "DN", "pins": "px"},
            duration_s=5 / 40.0,
        )
