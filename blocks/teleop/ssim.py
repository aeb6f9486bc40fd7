"""SSIM of each sensor's image against a reference image (White 2023, eq. 3.2), numba kernels.

The thesis's metric is scikit-image's ``structural_similarity(ref, cur, win_size=7,
gaussian_weights=False, data_range=255)``: a uniform 7×7 window, c1 = (0.01·255)²,
c2 = (0.03·255)², sample (co)variances (N − 1 = 48) and the mean over the *valid* windows
((H − 6)·(W − 6) of them, no border windows). For uint8 images every window sum is an exact
integer, so the metric can be computed exactly up to the last few floating-point operations
(../shared/NUMERICS.md §2.1): with A = Σx, B = Σy over a window (x the reference),

    SSIM = (2AB + C1)·(2D + C2) / ((A² + B² + C1)·(Vx + Vy + C2)),
    D = 49·Σxy − AB,  Vx = 49·Σx² − A²,  Vy = 49·Σy² − B²,  C1 = 49²·c1,  C2 = 49·48·c2,

where every product and difference of window sums fits in an int32 (|·| ≤ 3.2e8) and is exact
in integer and in float64 arithmetic. This module never imports OpenCV, scikit-image or torch.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numba import njit

import flowtact.api as ft

from .hand import FINGERS

__all__ = [
    "C1",
    "C2",
    "WIN",
    "Ssim",
    "SsimConfig",
    "SsimReference",
    "ssim_exact_numpy",
    "ssim_frames",
]

#: Window side (the thesis's N = 7) and the regularisation constants for L = 255.
WIN = 7
C1 = (0.01 * 255) ** 2
C2 = (0.03 * 255) ** 2
_NP = WIN * WIN
#: The constants scaled to the integer formulation: C1·49², C2·49·48.
C1W = C1 * _NP * _NP
C2W = C2 * _NP * (_NP - 1)


# -- numpy twin (the exact integer formulation, the test reference) -----------------------------------


def _window_sums(a: np.ndarray) -> np.ndarray:
    """Sums of every valid 7×7 window of a 2-D integer array, exactly (int64)."""
    c = np.zeros((a.shape[0] + 1, a.shape[1] + 1), np.int64)
    c[1:, 1:] = a.astype(np.int64).cumsum(0).cumsum(1)
    return c[WIN:, WIN:] - c[:-WIN, WIN:] - c[WIN:, :-WIN] + c[:-WIN, :-WIN]


def ssim_exact_numpy(ref: np.ndarray, cur: np.ndarray, *, full: bool = False) -> float | np.ndarray:
    """Mean SSIM of two uint8 images (or the (H−6, W−6) map with ``full``), plain numpy.

    Window sums are exact int64 integral-image differences; only the final formula is floating
    point. Equal to scikit-image's box-7 ``structural_similarity`` to ~1e-14 (NUMERICS §2.1).
    """
    x = np.asarray(ref)
    y = np.asarray(cur)
    if x.shape != y.shape or x.ndim != 2 or min(x.shape) < WIN:
        raise ValueError(f"need two 2-D images of the same shape, at least 7×7; got {x.shape}, {y.shape}")
    x64, y64 = x.astype(np.int64), y.astype(np.int64)
    a, b = _window_sums(x64), _window_sums(y64)
    sxx, syy, sxy = _window_sums(x64 * x64), _window_sums(y64 * y64), _window_sums(x64 * y64)
    ab = a * b
    d = _NP * sxy - ab
    vx = _NP * sxx - a * a
    vy = _NP * syy - b * b
    m = ((2 * ab + C1W) * (2 * d + C2W)) / ((a * a + b * b + C1W) * (vx + vy + C2W))
    return m if full else float(m.mean())


# -- numba kernels ------------------------------------------------------------------------------------


# The SSIM kernel, per frame and sensor: column sums over the 7 rows of the current window row, for
# y, y² and x·y, exact int32, updated by one row in and one row out; int64 prefix sums of those
# along the row, so each window sum is one subtraction; the reference terms A, P = A² + C1,
# Q = Vx + C2 cached by SsimReference (measured ~10 % faster than forming P and Q from int32 A and
# Vx per window); each window's value added into a per-column float64 accumulator and the columns
# summed in order at the end (a fixed order, whatever the chunking). The final formula runs in the
# float type of the cached P and Q: numba compiles one version for float64 and one for float32.


@njit(cache=True, inline="always")
def _sliding_buffers(ww):  # type: ignore[no-untyped-def]
    """Column sums of y, y², x·y (int32) and their row prefix sums (int64, leading 0) for rows of
    ``ww`` pixels."""
    columns = (np.empty(ww, np.int32), np.empty(ww, np.int32), np.empty(ww, np.int32))
    prefixes = (np.zeros(ww + 1, np.int64), np.zeros(ww + 1, np.int64), np.zeros(ww + 1, np.int64))
    return columns + prefixes


@njit(cache=True, inline="always")
def _start_columns(y, x, cy, cyy, cxy):
    """Column sums of y, y² and x·y over the first 7 rows (exact int32)."""
    cy[:] = 0
    cyy[:] = 0
    cxy[:] = 0
    for r in range(WIN):
        for j in range(y.shape[1]):
            yv = np.int32(y[r, j])
            cy[j] += yv
            cyy[j] += yv * yv
            cxy[j] += np.int32(x[r, j]) * yv


@njit(cache=True, inline="always")
def _row_prefix(y, x, i, cy, cyy, cxy, py, pyy, pxy):
    """Slide the column sums to window row ``i`` (one row in, one out), then prefix-sum them."""
    ww = y.shape[1]
    if i > 0:
        for j in range(ww):
            y_in = np.int32(y[i + WIN - 1, j])
            y_out = np.int32(y[i - 1, j])
            cy[j] += y_in - y_out
            cyy[j] += y_in * y_in - y_out * y_out
            cxy[j] += np.int32(x[i + WIN - 1, j]) * y_in - np.int32(x[i - 1, j]) * y_out
    sy = 0
    syy = 0
    sxy = 0
    for j in range(ww):
        sy += cy[j]
        syy += cyy[j]
        sxy += cxy[j]
        py[j + 1] = sy
        pyy[j + 1] = syy
        pxy[j + 1] = sxy


@njit(cache=True)
def _reference_terms(ref, a_out, vx_out):
    """Per-window reference sums A = Σx and Vx = 49·Σx² − A² (both exact int32).

    ``ref`` (n, H, W) uint8; outputs (n, H−6, W−6), from which :class:`SsimReference` caches
    P = A² + C1 and Q = Vx + C2 in the kernel's float type. The kernel's own sliding sums, with the
    reference as both images (its x·x sums are Σx² again, unused: this runs once per reference).
    """
    n, hh, ww = ref.shape
    h, w = hh - WIN + 1, ww - WIN + 1
    cx, cxx, cxx2, px, pxx, pxx2 = _sliding_buffers(ww)
    for s in range(n):
        x = ref[s]
        _start_columns(x, x, cx, cxx, cxx2)
        for i in range(h):
            _row_prefix(x, x, i, cx, cxx, cxx2, px, pxx, pxx2)
            for j in range(w):
                sa = px[j + WIN] - px[j]
                a_out[s, i, j] = sa
                vx_out[s, i, j] = _NP * (pxx[j + WIN] - pxx[j]) - sa * sa


@njit(cache=True)
def _ssim(frames, ref, a_ref, p_ref, q_ref, out):
    """Mean SSIM of ``frames`` (k, n, H, W) uint8 against ``ref`` (n, H, W) into ``out`` (k, n).

    The final formula is in the float type of ``p_ref``/``q_ref`` (float64 or float32); the sums
    are exact and the mean is float64 either way.
    """
    ft = p_ref.dtype.type
    k, n, hh, ww = frames.shape
    h, w = hh - WIN + 1, ww - WIN + 1
    cy, cyy, cxy, py, pyy, pxy = _sliding_buffers(ww)
    acc = np.empty(w, np.float64)
    c1w = ft(C1W)
    c2w = ft(C2W)
    for f in range(k):
        for s in range(n):
            y, x = frames[f, s], ref[s]
            a_s, p_s, q_s = a_ref[s], p_ref[s], q_ref[s]
            acc[:] = 0.0
            _start_columns(y, x, cy, cyy, cxy)
            for i in range(h):
                _row_prefix(y, x, i, cy, cyy, cxy, py, pyy, pxy)
                for j in range(w):
                    sb = py[j + WIN] - py[j]
                    sbb = pyy[j + WIN] - pyy[j]
                    sab = pxy[j + WIN] - pxy[j]
                    ab = a_s[i, j] * sb
                    bb = sb * sb
                    num = (ft(2 * ab) + c1w) * (ft(2 * (_NP * sab - ab)) + c2w)
                    den = (p_s[i, j] + ft(bb)) * (q_s[i, j] + ft(_NP * sbb - bb))
                    acc[j] += np.float64(num / den)
            tot = 0.0
            for j in range(w):
                tot += acc[j]
            out[f, s] = tot / (h * w)


# -- the reference, cached ----------------------------------------------------------------------------


class SsimReference:
    """A reference image stack (n, H, W) uint8 with its per-window terms cached for one precision.

    ``compare(frames)`` returns the mean SSIM of each frame (k, n, H, W) against it, (k, n) float64.
    """

    def __init__(self, ref: np.ndarray, precision: Literal["float64", "float32"] = "float64") -> None:
        ref = np.ascontiguousarray(ref, dtype=np.uint8)
        if ref.ndim != 3 or ref.shape[1] < WIN or ref.shape[2] < WIN:
            raise ValueError(f"reference must be (n, H, W) uint8 with H, W >= {WIN}; got shape {ref.shape}")
        self.image = ref
        self.precision = precision
        n, hh, ww = ref.shape
        shape = (n, hh - WIN + 1, ww - WIN + 1)
        self._a = np.empty(shape, np.int32)
        vx = np.empty(shape, np.int32)
        _reference_terms(ref, self._a, vx)
        ft = np.float64 if precision == "float64" else np.float32
        # P = A² + C1 and Q = Vx + C2: A² < 2**53 is exact in float64, so one rounding each
        self._p = (self._a.astype(np.float64) ** 2 + C1W).astype(ft)
        self._q = (vx.astype(np.float64) + C2W).astype(ft)

    def compare(self, frames: np.ndarray) -> np.ndarray:
        """Mean SSIM (k, n) of frames (k, n, H, W) uint8 against the reference."""
        frames = np.ascontiguousarray(frames, dtype=np.uint8)
        if frames.shape[1:] != self.image.shape:
            raise ValueError(f"frames of shape {frames.shape[1:]} against a reference of {self.image.shape}")
        out = np.empty(frames.shape[:2], np.float64)
        if len(frames):
            _ssim(frames, self.image, self._a, self._p, self._q, out)
        return out


def ssim_frames(
    ref: np.ndarray, frames: np.ndarray, precision: Literal["float64", "float32"] = "float64"
) -> np.ndarray:
    """Mean SSIM of ``frames`` (k, n, H, W) against ``ref`` (n, H, W), both uint8: (k, n) float64.

    Also accepts a single image pair: ``ref`` (H, W), ``frames`` (H, W) → a float.
    """
    ref, frames = np.asarray(ref), np.asarray(frames)
    if ref.ndim == 2 and frames.ndim == 2:
        return float(SsimReference(ref[None], precision).compare(frames[None, None])[0, 0])
    return SsimReference(ref, precision).compare(frames)


def _mean_reference(frames: list[np.ndarray]) -> np.ndarray:
    """Pixel-wise mean of uint8 stacks, rounded half up to uint8 (exact integer arithmetic)."""
    k = len(frames)
    if k == 1:
        return np.array(frames[0], np.uint8)
    total = np.zeros(frames[0].shape, np.int64)
    for f in frames:  # sequential integer sum: the same whatever the chunking
        total += f
    return ((2 * total + k) // (2 * k)).astype(np.uint8)


# -- the block ----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SsimConfig(ft.BadDataConfig):
    """Parameters of :class:`Ssim`."""

    precision: Literal["float64", "float32"] = ft.param(
        "float64",
        doc="final formula in float64 (equals scikit-image to ~1e-14) or float32 (within 1e-6, a little faster)",
    )
    reference_frames: int = ft.param(
        1,
        doc="the reference is the rounded mean of this many frames from the start (and after a recapture)",
        ge=1,
    )

    def state_bytes(self) -> dict[str, float]:
        """The frames collected for the reference (uint8 copies, then their float64 mean)."""
        return {"reference_frames": self.reference_frames * ft.NOMINAL_FRAME_BYTES * 2.0}


class Ssim(ft.Block):
    """Mean SSIM of each sensor's image against a reference captured at start-up (White 2023, eq. 3.2).

    Config
    ------
    See :class:`SsimConfig`: ``precision`` (float64 default, float32 fast mode) and
    ``reference_frames`` (1: the first frame is the reference, as in the thesis).

    Notes
    -----
    The metric is exactly scikit-image's ``structural_similarity(ref, cur, win_size=7,
    gaussian_weights=False, data_range=255)``: 7×7 uniform window, c1 = (0.01·255)²,
    c2 = (0.03·255)², sample covariance (N − 1 = 48), mean over the valid windows (no border
    windows). Float64 agrees with it to ~1e-14 (tests require 1e-10), float32 to ~1e-8 (tests
    require 1e-6). Window sums are exact integers; the reference's window terms are computed
    once per reference (NUMERICS §2.2, "fused v2"). Identical images give exactly 1.0 in float64.

    Reference: the thesis captures one undeformed frame at start-up. ``reference_frames: k``
    takes the pixel-wise mean of the first k frames, rounded half up to uint8 (so the reference
    stays an image and the metric stays skimage's on it); those k frames are held back until the
    reference is complete and then compared against it (a one-off start-up latency of k − 1
    frames; no frame is lost). A stream shorter than k uses the frames it has, at flush.

    Recapture: a ``recapture`` sample > 0.5 at time t makes the first frame with time >= t start
    a new reference (of ``reference_frames`` frames). The input is level-triggered: every sample
    > 0.5 requests a recapture, so feed pulses, not a held level. A recapture arriving while a
    reference is still being collected completes the current one with the frames it has. With
    ``recapture`` connected a frame is released only once the recapture stream has reached its
    time (a recapture sample with time >= the frame's, or a watermark ``end`` beyond it), so the
    output does not depend on how the two streams are chunked; the latency is then that of the
    recapture stream. Without it, latency 0. (This is :class:`flowtact.streams.merge.LatestMerger`'s
    release rule; the merger itself is not used because it pairs each frame with the *latest*
    recapture sample only, which would lose a pulse followed by a 0 before the next frame, and
    because it carries the driving stream as float64.)

    ``y.end`` is the frames' watermark, held back to the first frame still pending.

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.teleop.ssim import Ssim
    >>> from flowtact.testing import run_offline
    >>> rng = np.random.default_rng(0)
    >>> frames = rng.integers(0, 256, (3, 2, 16, 16), dtype=np.uint8)   # 3 samples, 2 sensors
    >>> frames[1] = frames[0]
    >>> y = run_offline(Ssim(), x=frames, rate_hz=40.0, units={"x": "DN"})["y"].data
    >>> y[:2].tolist()                  # the first frame is the reference: itself, and its copy
    [[1.0, 1.0], [1.0, 1.0]]
    >>> bool((y[2] < 0.2).all())        # an unrelated random image
    True
    """

    name = "ssim"
    config_cls = SsimConfig
    inputs = {
        "x": ft.Port(
            dtype="uint8",
            units="DN",
            ndim=(2, 3),
            require_rate=True,
            doc=(
                "frames (n, H, W) (n sensors; H, W ≥ 7) or (H, W): raw, cropped, thresholded or masked "
                "images (any uint8 image with range 0..255)"
            ),
        ),
        "recapture": ft.Port(
            dtype="float64",
            shape=(),
            units="1",
            optional=True,
            doc="a sample > 0.5 makes the next frame (time >= its time) the new reference",
        ),
    }
    outputs = {
        "y": ft.Port(
            dtype="float64",
            units="1",
            doc=(
                "mean SSIM of each sensor's frame against its reference, shape (n,) (or () for (H, W) "
                "frames), one sample per frame, same times; labels thumb, index, middle for n = 3"
            ),
        )
    }
    counter_docs = {
        "recaptures": "frames that started a new reference after a recapture request: expected when "
        "recapture pulses are sent",
        "reference_short": "the stream ended while a reference was still being collected: it is the "
        "mean of fewer than reference_frames frames",
        **ft.nonfinite_counter_docs("recapture samples"),
    }

    def specs(self, inputs: Mapping[str, ft.StreamSpec]) -> dict[str, ft.StreamSpec]:
        x = inputs["x"]
        if min(x.shape[-2:]) < WIN:
            raise ft.SpecError(
                "x", f"input 'x' frames must be at least {WIN}×{WIN} pixels (the window); got {x.shape}"
            )
        shape = x.shape[:1] if len(x.shape) == 3 else ()
        labels = FINGERS if shape == (len(FINGERS),) else None
        return {"y": ft.StreamSpec(dtype="float64", shape=shape, units="1", rate_hz=x.rate_hz, labels=labels)}

    def reset(self) -> None:
        x = self.input_specs["x"]
        self._single = len(x.shape) == 2
        self._frame_shape = ((1,) if self._single else ()) + tuple(x.shape)
        self._ref: SsimReference | None = None
        self._collect: list[tuple[float, np.ndarray]] | None = []  # start-up capture
        self._has_rc = "recapture" in self.input_specs
        self._rc_t = np.empty(0)
        self._rc_v = np.empty(0)
        self._rc_last = -np.inf  # time of the last recapture sample seen
        self._rc_end = -np.inf  # the recapture stream's watermark
        self._rc_hold: np.ndarray | None = None
        self._pend_t = np.empty(0)
        self._pend_f = np.empty((0, *self._frame_shape), np.uint8)
        self._x_end: float | None = None

    # -- the stream logic ------------------------------------------------------------------------
    def step(self, x: ft.Chunk, recapture: ft.Chunk | None = None) -> dict[str, ft.Chunk]:
        if x.end is not None:
            self._x_end = x.end if self._x_end is None else max(self._x_end, x.end)
        if recapture is not None:
            self._add_recapture(recapture)
        if len(x):
            frames = x.data.reshape(len(x), *self._frame_shape)
            t = x.t
        else:
            t, frames = np.empty(0), np.empty((0, *self._frame_shape), np.uint8)
        if self._has_rc:
            if len(t):
                self._pend_t = np.concatenate([self._pend_t, t])
                self._pend_f = np.concatenate([self._pend_f, frames])
            ready = (self._pend_t <= self._rc_last) | (self._pend_t < self._rc_end)
            n = int(np.argmin(ready)) if not ready.all() else len(ready)
            t, frames = self._pend_t[:n], self._pend_f[:n]
            self._pend_t, self._pend_f = self._pend_t[n:], self._pend_f[n:]
        return {"y": self._emit(*self._process(t, frames))}

    def flush(self) -> dict[str, ft.Chunk]:
        t_out, y_out = self._process(self._pend_t, self._pend_f)
        self._pend_t, self._pend_f = np.empty(0), self._pend_f[:0]
        if self._collect:
            self.count("reference_short", 1)
            t2, y2 = self._finish_reference()
            t_out, y_out = np.concatenate([t_out, t2]), np.concatenate([y_out, y2])
        return {"y": self._emit(t_out, y_out)} if len(t_out) else {}

    def _add_recapture(self, c: ft.Chunk) -> None:
        if c.end is not None:
            self._rc_end = max(self._rc_end, c.end)
        if not len(c):
            return
        c, self._rc_hold = ft.screen_nonfinite(self, c, self.config.on_bad_data, "recapture", self._rc_hold)
        if len(c):
            self._rc_t = np.concatenate([self._rc_t, c.t])
            self._rc_v = np.concatenate([self._rc_v, c.data])
            self._rc_last = max(self._rc_last, float(c.t[-1]))

    def _recapture_flags(self, t: np.ndarray) -> np.ndarray:
        """For each released frame: did a recapture sample (> 0.5) arrive since the previous one?"""
        flags = np.zeros(len(t), bool)
        if not self._has_rc or not len(t):
            return flags
        # recapture sample j applies to the first frame with time >= its time
        idx = np.searchsorted(t, self._rc_t, side="left")
        used = idx < len(t)
        hit = used & (self._rc_v > 0.5)
        flags[idx[hit]] = True
        self._rc_t, self._rc_v = self._rc_t[~used], self._rc_v[~used]
        return flags

    def _process(self, t: np.ndarray, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """SSIM of released frames, in order: (times, values (m, n)) of what can be emitted now."""
        flags = self._recapture_flags(t)
        n_s = self._frame_shape[0]
        outs_t: list[np.ndarray] = []
        outs_y: list[np.ndarray] = []
        k = self.config.reference_frames
        i, m = 0, len(t)
        while i < m:
            if flags[i]:
                self.count("recaptures", 1)
                if self._collect:
                    ot, oy = self._finish_reference()
                    outs_t.append(ot)
                    outs_y.append(oy)
                self._collect = []
            if self._collect is not None:
                self._collect.append((float(t[i]), np.array(frames[i], np.uint8)))
                if len(self._collect) == k:
                    ot, oy = self._finish_reference()
                    outs_t.append(ot)
                    outs_y.append(oy)
                i += 1
                continue
            j = i + 1  # a run of frames against the current reference
            while j < m and not flags[j]:
                j += 1
            assert self._ref is not None
            outs_t.append(t[i:j])
            outs_y.append(self._ref.compare(frames[i:j]))
            i = j
        if not outs_t:
            return np.empty(0), np.empty((0, n_s))
        return np.concatenate(outs_t), np.concatenate(outs_y)

    def _finish_reference(self) -> tuple[np.ndarray, np.ndarray]:
        assert self._collect
        tt = np.array([c[0] for c in self._collect])
        ff = np.stack([c[1] for c in self._collect])
        self._collect = None
        self._ref = SsimReference(_mean_reference(list(ff)), self.config.precision)
        return tt, self._ref.compare(ff)

    def _emit(self, t: np.ndarray, y: np.ndarray) -> ft.Chunk:
        end = self._x_end
        held = [float(self._pend_t[0])] if len(self._pend_t) else []
        if self._collect:
            held.append(self._collect[0][0])
        if end is not None and held:
            end = min(end, *held)
        data = y[:, 0] if self._single else y
        return ft.Chunk(np.asarray(t, np.float64), np.ascontiguousarray(data, np.float64), end)

    @classmethod
    def example(cls) -> ft.Example:
        rng = np.random.default_rng(7)
        base = rng.integers(20, 60, (3, 24, 32)).astype(np.int16)
        base[:, 8:16:3, 4:28:4] = 220  # a few bright "pins"
        frames = np.empty((5, 3, 24, 32), np.uint8)
        for i in range(5):
            shifted = np.roll(base, i % 3, axis=2) + rng.integers(-3, 4, base.shape)
            frames[i] = np.clip(shifted, 0, 255)
        recapture = np.array([0.0, 0.0, 0.0, 1.0, 0.0])
        return ft.Example(
            params={"reference_frames": 2},
            inputs={"x": frames, "recapture": recapture},
            rate_hz=40.0,
            units={"x": "DN"},
            duration_s=5 / 40.0,
        )
