"""An emulated set of three TacTip optical tactile sensors (White 2023): 30 pins on a dark membrane.

``tactip_sim`` renders what the fingertip cameras of the teleoperation rig see (thumb, index,
middle; 320×240 gray at 40 FPS) while a scenario (taps of rising force, grasps of a soft and a
firm object, rest) or an upstream gripper simulator presses on each fingertip, and emits the true
contact force next to the frames so that force estimators (SSIM + linear fit, CNN) can be
trained and scored against the truth. :func:`render` draws frames without a graph (and
:func:`pressed_frames` those of a press at the centre: the image blocks' examples and tests).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Literal

import numpy as np
from numba import njit

from flowtact.block import BadDataConfig, Example, Port, Source, nonfinite_counter_docs, screen_nonfinite
from flowtact.blocks.signal.shapes import raised_cosine
from flowtact.chunk import Chunk, StreamSpec
from flowtact.errors import SpecError
from flowtact.inputs.limits import MAX_TICK_S
from flowtact.params import param

from .hand import FINGERS, N_FINGERS

__all__ = [
    "HEIGHT",
    "N_PINS",
    "PX_PER_MM",
    "WIDTH",
    "Contacts",
    "TactipSim",
    "TactipSimConfig",
    "pin_layout",
    "pins_px",
    "pressed_frames",
    "render",
    "render_reference",
    "scenario_contacts",
]

HEIGHT, WIDTH = 240, 320
#: Pins per TacTip (3 staggered rows of 10).
N_PINS = 30
#: Image scale of the membrane at the pin tips (a 3 mm pin pitch is 21 px).
PX_PER_MM = 7.0
PIN_PITCH_MM = 3.0
ROW_PITCH_MM = 3.4
PIN_RADIUS_MM = 0.7
#: Width of a pin tip's soft (logistic) edge.
PIN_EDGE_PX = 0.6
#: Tangential skin displacement per newton of shear at the contact centre.
SHEAR_MM_PER_N = 0.3
MASK64 = (1 << 64) - 1
GOLDEN = 0x9E3779B97F4A7C15


@dataclass(frozen=True)
class TactipSimConfig(BadDataConfig):
    scenario: Literal["taps", "grasp", "rest"] = param(
        "taps",
        doc="force drive without a force input: taps of rising force, soft/firm grasps, or no contact",
    )
    fps: float = param(40.0, doc="frame rate of every output (the paper's cameras run at 40 FPS)", gt=0)
    onset_s: float = param(0.25, doc="time of the first tap or grasp", ge=0)
    force_min_n: float = param(0.5, doc="taps: peak force of the first tap at each position", ge=0)
    force_max_n: float = param(5.0, doc="taps: peak force of the last tap at each position", gt=0)
    levels: int = param(10, doc="taps: taps of rising peak force at one position before it moves", ge=1)
    tap_s: float = param(
        0.5, doc="taps: contact time of one tap (raised-cosine rise, hold, fall: thirds)", gt=0
    )
    tap_period_s: float = param(1.0, doc="taps: time between the onsets of successive taps", gt=0)
    position_mm: tuple[float, ...] = param(
        (9.0, 3.0),
        doc="taps: contact positions are drawn uniformly within ±x, ±y mm of the pin-array centre",
        ge=0,
        min_len=2,
        max_len=2,
    )
    jitter_mm: float = param(0.3, doc="taps: extra per-tap jitter of the contact position", ge=0)
    level_jitter: float = param(
        0.5,
        doc="taps: peak-force jitter as a fraction of one level step (covers the range densely)",
        ge=0,
        le=1,
    )
    shear_ratio: float = param(
        0.3,
        doc="taps: tangential force up to this fraction of the normal force, random direction per tap",
        ge=0,
    )
    size_spread: float = param(
        0.3,
        doc="contact-size factor exp(±size_spread) per tap position (±half per grasp): object curvature",
        ge=0,
    )
    grasp_period_s: float = param(4.0, doc="grasp: time between grasp onsets (soft and firm alternate)", gt=0)
    soft_force_n: float = param(2.5, doc="grasp: thumb peak force on the soft object", ge=0)
    firm_force_n: float = param(4.0, doc="grasp: thumb peak force on the firm object", ge=0)
    soft_rise_s: float = param(1.2, doc="grasp: force rise time on the soft object (slow)", gt=0)
    firm_rise_s: float = param(0.15, doc="grasp: force rise time on the firm object (fast)", gt=0)
    hold_s: float = param(1.0, doc="grasp: time the peak force is held", ge=0)
    release_s: float = param(0.3, doc="grasp: force fall time at release", gt=0)
    contact_mm: tuple[float, ...] = param(
        (0.0, 0.0),
        doc="contact (x, y mm) under an input-driven force: 2 values for all sensors, or x, y per sensor",
        min_len=2,
        max_len=6,
    )
    displacement_mm: float = param(0.85, doc="largest radial pin displacement at 5 N (grows as F^0.75)", ge=0)
    noise_dn: float = param(3.0, doc="sensor noise standard deviation in gray levels (DN)", ge=0)
    vignette: float = param(0.6, doc="lens vignetting depth: 0 none, 1 pure cos^4 falloff", ge=0, le=1)
    unit_seed: int = param(
        2023,
        doc="which physical TacTips: fixes each sensor's pin layout, lighting and lens (not the noise)",
        ge=0,
    )

    def state_bytes(self) -> dict[str, float]:
        """A longest tick of frames: three uint8 frames each, rendered through float64 scratch."""
        return {"fps": self.fps * MAX_TICK_S * 3 * HEIGHT * WIDTH * 9}

    def check(self) -> None:
        if self.force_max_n < self.force_min_n:
            raise self.error(
                "force_max_n", f"must be >= force_min_n ({self.force_min_n:g}); got {self.force_max_n:g}"
            )
        if self.tap_s > self.tap_period_s:
            raise self.error(
                "tap_s",
                f"must be <= tap_period_s ({self.tap_period_s:g}): taps cannot overlap; got {self.tap_s:g}",
            )
        longest = max(self.soft_rise_s, self.firm_rise_s) + self.hold_s + self.release_s
        if longest > self.grasp_period_s:
            raise self.error(
                "grasp_period_s",
                f"must be >= the longest grasp (rise + hold_s + release_s = {longest:g} s); "
                f"got {self.grasp_period_s:g}",
            )
        if len(self.contact_mm) not in (2, 2 * N_FINGERS):
            raise self.error(
                "contact_mm",
                f"must have 2 values (x, y) or {2 * N_FINGERS} (x, y per sensor); got {len(self.contact_mm)}",
            )


# -- counter-based randomness (the same numbers whatever the chunking) -----------------------------


def _mix64_int(x: int) -> int:
    """splitmix64 finaliser on a Python int (exact, no numpy overflow warnings)."""
    x &= MASK64
    x = ((x ^ (x >> 30)) * 0xBF58476D1CE4E5B9) & MASK64
    x = ((x ^ (x >> 27)) * 0x94D049BB133111EB) & MASK64
    return x ^ (x >> 31)


def _key(seed: int, *counters: int) -> int:
    """A 64-bit key from a seed and integer counters (splitmix64 chain)."""
    h = _mix64_int(int(seed) + GOLDEN)
    for c in counters:
        h = _mix64_int(h + (int(c) + 1) * GOLDEN)
    return h


def _mix64_arr(x: np.ndarray) -> np.ndarray:
    x = x ^ (x >> np.uint64(30))
    x = x * np.uint64(0xBF58476D1CE4E5B9)
    x = x ^ (x >> np.uint64(27))
    x = x * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


def _uniform(key: int, *counters: np.ndarray) -> np.ndarray:
    """Uniform [0, 1) numbers, one per element of the (broadcast) integer counter arrays."""
    arrays = np.broadcast_arrays(*[np.asarray(c, np.int64) for c in counters])
    h = np.full(arrays[0].shape, key, np.uint64)
    gold = np.uint64(GOLDEN)
    for c in arrays:
        h = _mix64_arr(h + (c.astype(np.uint64) + np.uint64(1)) * gold)
    return (h >> np.uint64(11)).astype(np.float64) * (1.0 / 9007199254740992.0)


# -- the physical sensors ----------------------------------------------------------------------------


@dataclass(frozen=True)
class _Units:
    """Fixed properties of the three physical sensors (from ``unit_seed``)."""

    pins_mm: np.ndarray  # (3, 30, 2) rest positions of the pin tips on the membrane, mm
    radius_px: np.ndarray  # (3, 30) rest pin-tip radius
    bright: np.ndarray  # (3, 30) pin-tip brightness (DN above the skin, before vignetting)
    rot: np.ndarray  # (3, 2, 2) membrane-to-image rotation
    centre_px: np.ndarray  # (3, 2) image position of the array centre (x, y)
    background: np.ndarray  # (3, H, W) float64 skin and housing, vignetted and lit
    vig: np.ndarray  # (3, H, W) float64 lens vignetting factor


def pin_layout() -> np.ndarray:
    """Nominal membrane positions (30, 2) in mm of the pin tips: 3 staggered rows of 10."""
    out = np.empty((N_PINS, 2))
    k = 0
    for row in (-1, 0, 1):
        shift = 0.25 * PIN_PITCH_MM if row == 0 else -0.25 * PIN_PITCH_MM
        for col in range(10):
            out[k] = ((col - 4.5) * PIN_PITCH_MM + shift, row * ROW_PITCH_MM)
            k += 1
    return out


@lru_cache(maxsize=8)
def _units(unit_seed: int, vignette: float) -> _Units:
    layout = pin_layout()
    yy, xx = np.mgrid[0:HEIGHT, 0:WIDTH].astype(np.float64)
    pins = np.empty((N_FINGERS, N_PINS, 2))
    radius = np.empty((N_FINGERS, N_PINS))
    bright = np.empty((N_FINGERS, N_PINS))
    rot = np.empty((N_FINGERS, 2, 2))
    centre = np.empty((N_FINGERS, 2))
    background = np.empty((N_FINGERS, HEIGHT, WIDTH))
    vig = np.empty((N_FINGERS, HEIGHT, WIDTH))
    focal_px = 160.0  # 90° field of view across 320 px
    for s in range(N_FINGERS):
        g = np.random.default_rng([unit_seed, s])
        pins[s] = layout + g.uniform(-0.08, 0.08, (N_PINS, 2))
        radius[s] = PIN_RADIUS_MM * PX_PER_MM * g.uniform(0.95, 1.05) * g.uniform(0.95, 1.05, N_PINS)
        bright[s] = 165.0 * g.uniform(0.85, 1.1) * g.uniform(0.94, 1.06, N_PINS)
        th = math.radians(g.uniform(-1.0, 1.0))
        rot[s] = [[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]]
        centre[s] = (WIDTH / 2 + g.uniform(-3.0, 3.0), HEIGHT / 2 + g.uniform(-2.0, 2.0))
        lens = (WIDTH / 2 + g.uniform(-4.0, 4.0), HEIGHT / 2 + g.uniform(-4.0, 4.0))
        depth = min(1.0, vignette * g.uniform(0.9, 1.1))
        r2 = (xx - lens[0]) ** 2 + (yy - lens[1]) ** 2
        cos4 = (focal_px**2 / (focal_px**2 + r2)) ** 2
        vig[s] = (1.0 - depth) + depth * cos4
        skin = g.uniform(25.0, 38.0) * (1.0 + g.uniform(-0.12, 0.12) * (xx - WIDTH / 2) / (WIDTH / 2))
        # the membrane fills an ellipse; the lens rim around it is darker
        rho = np.sqrt(((xx - lens[0]) / 150.0) ** 2 + ((yy - lens[1]) / 105.0) ** 2)
        inside = 1.0 / (1.0 + np.exp((rho - 1.0) * 40.0))
        background[s] = vig[s] * (skin * inside + 6.0 * (1.0 - inside))
    for a in (pins, radius, bright, rot, centre, background, vig):
        a.flags.writeable = False
    return _Units(pins, radius, bright, rot, centre, background, vig)


def _as_config(params: TactipSimConfig | Mapping[str, Any] | None) -> TactipSimConfig:
    if isinstance(params, TactipSimConfig):
        return params
    return TactipSimConfig.build(dict(params or {}), owner="tactip_sim")


def pins_px(
    forces: np.ndarray,
    positions: np.ndarray,
    params: TactipSimConfig | Mapping[str, Any] | None = None,
    *,
    shear: np.ndarray | None = None,
    size: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Image pin centres (n, 3, 30, 2) px (x, y), radii (n, 3, 30) px and brightness (n, 3, 30) DN.

    ``forces`` (n, 3) N are the normal contact forces and ``positions`` (n, 3, 2) the contact
    centres (x, y mm from the pin-array centre, x along the finger) of each sensor; ``shear``
    (n, 3, 2) N the tangential force (default none) and ``size`` (n, 3) the contact-size factor of
    the object's curvature (default 1).
    """
    c = _as_config(params)
    u = _units(c.unit_seed, c.vignette)
    f = np.maximum(np.asarray(forces, np.float64), 0.0)[..., None]  # (n, 3, 1)
    n = f.shape[0]
    pos = np.asarray(positions, np.float64)
    kappa = (
        np.ones((n, N_FINGERS, 1)) if size is None else np.asarray(size, np.float64).reshape(n, N_FINGERS, 1)
    )
    d = u.pins_mm[None] - pos[:, :, None, :]  # (n, 3, 30, 2) from contact to pin, mm
    r2 = d[..., 0] ** 2 + d[..., 1] ** 2
    r = np.sqrt(r2)
    # Hertz-like: contact radius a ∝ F^(1/3); the membrane bulges pins outward over a wider zone
    cube = np.cbrt(f) * kappa
    a = 2.5 * cube  # mm
    width = 2.0 + 1.6 * cube  # mm: distance of the largest displacement
    peak = c.displacement_mm * (f / 5.0) ** 0.75
    shift = peak * (r / width) * np.exp(0.5 * (1.0 - r2 / width**2))
    unit = d / np.maximum(r, 1e-12)[..., None]
    moved = u.pins_mm[None] + unit * shift[..., None]
    if shear is not None:
        # the skin under the contact is dragged along the tangential force (stuck contact)
        drag = (
            np.exp(-r2 / (2.0 * width**2))[..., None]
            * (SHEAR_MM_PER_N * np.asarray(shear, np.float64))[:, :, None, :]
        )
        moved = moved + drag
    # membrane -> image: element-wise (not einsum/BLAS) so every frame gets the same arithmetic
    rot = u.rot[None, :, None]  # (1, 3, 1, 2, 2)
    mx, my = moved[..., 0] * PX_PER_MM, moved[..., 1] * PX_PER_MM
    xy = np.empty_like(moved)
    xy[..., 0] = rot[..., 0, 0] * mx + rot[..., 0, 1] * my + u.centre_px[None, :, None, 0]
    xy[..., 1] = rot[..., 1, 0] * mx + rot[..., 1, 1] * my + u.centre_px[None, :, None, 1]
    # pin tips under the contact are pressed towards the lens: larger and brighter
    press = np.exp(-r2 / (2.0 * np.maximum(a, 1e-9) ** 2)) * (f / (f + 1.5))
    radius = u.radius_px[None] * (1.0 + 0.15 * press)
    bright = u.bright[None] * (1.0 + 0.25 * press)
    return xy, radius, bright


# -- rasterisation: numba kernel and its numpy twin -------------------------------------------------


@njit(cache=True, inline="always")
def _mix64(x):
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


@njit(cache=True)
def _render_kernel(out, background, vig, xy, radius, bright, keys, noise_dn, buf):  # pragma: no cover
    n, ns, h, w = out.shape
    npins = xy.shape[2]
    gold = np.uint64(0x9E3779B97F4A7C15)
    m16 = np.uint64(0xFFFF)
    s16 = np.uint64(16)
    s32 = np.uint64(32)
    s48 = np.uint64(48)
    for k in range(n):
        for s in range(ns):
            for y in range(h):
                for x in range(w):
                    buf[y, x] = background[s, y, x]
            for p in range(npins):
                px = xy[k, s, p, 0]
                py = xy[k, s, p, 1]
                rad = radius[k, s, p]
                amp = bright[k, s, p]
                reach = rad + 6.0 * PIN_EDGE_PX + 1.0
                x0 = max(int(np.floor(px - reach)), 0)
                x1 = min(int(np.ceil(px + reach)), w - 1)
                y0 = max(int(np.floor(py - reach)), 0)
                y1 = min(int(np.ceil(py + reach)), h - 1)
                for y in range(y0, y1 + 1):
                    dy = y - py
                    for x in range(x0, x1 + 1):
                        dx = x - px
                        d = np.sqrt(dx * dx + dy * dy)
                        q = min(d, rad) / rad
                        edge = 1.0 / (1.0 + np.exp((d - rad) / PIN_EDGE_PX))
                        buf[y, x] += amp * (1.0 - 0.3 * q * q) * edge * vig[s, y, x]
            key = keys[k, s]
            for y in range(h):
                for x in range(w):
                    i = np.uint64(y * w + x + 1)
                    hsh = _mix64(key + i * gold)
                    tot = (hsh & m16) + ((hsh >> s16) & m16) + ((hsh >> s32) & m16) + (hsh >> s48)
                    # a sum of four 16-bit fields (Irwin–Hall): mean 131070, sd ≈ 37837.2268
                    z = (np.float64(tot) - 131070.0) / 37837.2268
                    v = np.floor(buf[y, x] + noise_dn * z + 0.5)
                    if v < 0.0:
                        v = 0.0
                    elif v > 255.0:
                        v = 255.0
                    out[k, s, y, x] = np.uint8(v)


def _render_numpy(out, background, vig, xy, radius, bright, keys, noise_dn) -> None:
    """Plain-numpy twin of :func:`_render_kernel` (the test reference; same operations per pixel)."""
    n, ns, h, w = out.shape
    idx = np.arange(1, h * w + 1, dtype=np.uint64).reshape(h, w)
    m16 = np.uint64(0xFFFF)
    for k in range(n):
        for s in range(ns):
            buf = background[s].copy()
            for p in range(xy.shape[2]):
                px, py = xy[k, s, p]
                rad, amp = radius[k, s, p], bright[k, s, p]
                reach = rad + 6.0 * PIN_EDGE_PX + 1.0
                x0, x1 = max(math.floor(px - reach), 0), min(math.ceil(px + reach), w - 1)
                y0, y1 = max(math.floor(py - reach), 0), min(math.ceil(py + reach), h - 1)
                yy, xx = np.mgrid[y0 : y1 + 1, x0 : x1 + 1]
                dx, dy = xx - px, yy - py
                d = np.sqrt(dx * dx + dy * dy)
                q = np.minimum(d, rad) / rad
                edge = 1.0 / (1.0 + np.exp((d - rad) / PIN_EDGE_PX))
                buf[y0 : y1 + 1, x0 : x1 + 1] += (
                    amp * (1.0 - 0.3 * q * q) * edge * vig[s, y0 : y1 + 1, x0 : x1 + 1]
                )
            hsh = _mix64_arr(np.uint64(keys[k, s]) + idx * np.uint64(GOLDEN))
            tot = (
                (hsh & m16)
                + ((hsh >> np.uint64(16)) & m16)
                + ((hsh >> np.uint64(32)) & m16)
                + (hsh >> np.uint64(48))
            )
            z = (tot.astype(np.float64) - 131070.0) / 37837.2268
            out[k, s] = np.clip(np.floor(buf + noise_dn * z + 0.5), 0.0, 255.0).astype(np.uint8)


def _frame_keys(seed: int, frame_indices: np.ndarray) -> np.ndarray:
    return np.array(
        [[_key(seed, int(i), s) for s in range(N_FINGERS)] for i in frame_indices], dtype=np.uint64
    ).reshape(len(frame_indices), N_FINGERS)


def render(
    forces: np.ndarray,
    positions: np.ndarray,
    frame_indices: np.ndarray,
    seed: int,
    params: TactipSimConfig | Mapping[str, Any] | None = None,
    *,
    shear: np.ndarray | None = None,
    size: np.ndarray | None = None,
    engine: Literal["numba", "numpy"] = "numba",
) -> np.ndarray:
    """Frames uint8 (n, 3, 240, 320) of the three TacTips under the given contacts.

    ``forces`` (n, 3) N, ``positions`` (n, 3, 2) contact centres in mm (x along the finger, y
    across, from the pin-array centre), ``frame_indices`` (n,) integers that, with ``seed``, fix
    the sensor noise of each frame (a frame's noise depends only on ``(seed, index, sensor)``).
    Optional ``shear`` (n, 3, 2) N tangential forces and ``size`` (n, 3) contact-size factors
    (object curvature; 1 = default). ``params`` is a :class:`TactipSimConfig` or a mapping of
    its fields (rendering fields matter: ``displacement_mm``, ``noise_dn``, ``vignette``,
    ``unit_seed``). ``engine="numpy"`` runs the slow reference twin.
    """
    c = _as_config(params)
    forces = np.asarray(forces, np.float64).reshape(-1, N_FINGERS)
    n = len(forces)
    positions = np.asarray(positions, np.float64).reshape(n, N_FINGERS, 2)
    frame_indices = np.asarray(frame_indices, np.int64).reshape(n)
    u = _units(c.unit_seed, c.vignette)
    xy, radius, bright = pins_px(forces, positions, c, shear=shear, size=size)
    keys = _frame_keys(seed, frame_indices)
    out = np.empty((n, N_FINGERS, HEIGHT, WIDTH), np.uint8)
    if engine == "numba":
        buf = np.empty((HEIGHT, WIDTH))
        _render_kernel(out, u.background, u.vig, xy, radius, bright, keys, float(c.noise_dn), buf)
    else:
        _render_numpy(out, u.background, u.vig, xy, radius, bright, keys, float(c.noise_dn))
    return out


def pressed_frames(
    forces_n: np.ndarray | Sequence[float],
    seed: int = 1,
    params: TactipSimConfig | Mapping[str, Any] | None = None,
) -> np.ndarray:
    """Frames uint8 (n, 3, 240, 320) of the three TacTips pressed at the pin-array centre.

    ``forces_n``: the normal force of each frame in N, (n,) for every sensor or (n, 3) per sensor;
    frame ``i``'s noise comes from ``(seed, i)``. The test, example and bench images of the image,
    SSIM and CNN blocks.
    """
    f = np.asarray(forces_n, np.float64)
    n = len(f)
    f = np.broadcast_to(f.reshape(n, -1), (n, N_FINGERS))
    return render(f, np.zeros((n, N_FINGERS, 2)), np.arange(n), seed, params)


def render_reference(
    seed: int, params: TactipSimConfig | Mapping[str, Any] | None = None, frame_index: int = 0
) -> np.ndarray:
    """One no-contact frame stack (3, 240, 320): what an SSIM block captures at start-up."""
    return render(np.zeros((1, N_FINGERS)), np.zeros((1, N_FINGERS, 2)), [frame_index], seed, params)[0]


# -- scenarios (pure functions of the frame times) --------------------------------------------------


@dataclass(frozen=True)
class Contacts:
    """What presses on the three sensors at a run of frame times."""

    force: np.ndarray  # (n, 3) normal force, N
    position: np.ndarray  # (n, 3, 2) contact centre, mm
    shear: np.ndarray  # (n, 3, 2) tangential force, N
    size: np.ndarray  # (n, 3) contact-size factor (object curvature)


def scenario_contacts(
    params: TactipSimConfig | Mapping[str, Any] | None, seed: int, t: np.ndarray
) -> Contacts:
    """The scenario's contacts at times ``t`` (a pure function of the config, ``seed`` and ``t``)."""
    c = _as_config(params)
    t = np.asarray(t, np.float64)
    n = len(t)
    f = np.zeros((n, N_FINGERS))
    pos = np.zeros((n, N_FINGERS, 2))
    shear = np.zeros((n, N_FINGERS, 2))
    size = np.ones((n, N_FINGERS))
    if c.scenario == "rest" or n == 0:
        return Contacts(f, pos, shear, size)
    sensors = np.arange(N_FINGERS)[None, :]
    if c.scenario == "taps":
        k = np.maximum(np.floor((t - c.onset_s) / c.tap_period_s), 0.0).astype(np.int64)
        u = t - c.onset_s - k * c.tap_period_s
        third = c.tap_s / 3.0
        shape = raised_cosine(u / third) - raised_cosine((u - 2.0 * third) / third)
        shape = np.where(t < c.onset_s, 0.0, shape)
        level = k % c.levels
        group = k // c.levels
        step_n = (c.force_max_n - c.force_min_n) / max(c.levels - 1, 1)
        kk, gg = k[:, None], group[:, None]
        jit = (_uniform(seed, kk, sensors, 0) - 0.5) * (c.level_jitter * step_n)
        peak = np.maximum(c.force_min_n + step_n * level[:, None] + jit, 0.0)
        f = peak * shape[:, None]
        for axis in range(2):
            centre = (2.0 * _uniform(seed, gg, sensors, 1 + axis) - 1.0) * c.position_mm[axis]
            jitter = (2.0 * _uniform(seed, kk, sensors, 3 + axis) - 1.0) * c.jitter_mm
            pos[:, :, axis] = centre + jitter
        size = np.exp((2.0 * _uniform(seed, gg, sensors, 5) - 1.0) * c.size_spread)
        ratio = _uniform(seed, kk, sensors, 6) * c.shear_ratio
        angle = 2.0 * np.pi * _uniform(seed, kk, sensors, 7)
    else:
        # grasp: soft (even) and firm (odd) objects alternate; every finger closes at once
        k = np.maximum(np.floor((t - c.onset_s) / c.grasp_period_s), 0.0).astype(np.int64)
        u = t - c.onset_s - k * c.grasp_period_s
        firm = (k % 2) == 1
        rise = np.where(firm, c.firm_rise_s, c.soft_rise_s)
        top = np.where(firm, c.firm_force_n, c.soft_force_n)
        shape = raised_cosine(u / rise) - raised_cosine((u - rise - c.hold_s) / c.release_s)
        shape = np.where(t < c.onset_s, 0.0, shape)
        kk = k[:, None]
        share = np.array([1.0, 0.6, 0.5])[None, :]  # the thumb opposes the two fingers
        spread = 1.0 + 0.1 * (2.0 * _uniform(seed, kk, sensors, 5) - 1.0)
        f = (top * shape)[:, None] * share * spread
        for axis, half in enumerate((2.0, 1.0)):
            pos[:, :, axis] = (2.0 * _uniform(seed, kk, sensors, 6 + axis) - 1.0) * half
        # a soft object wraps around the fingertip: a wider contact than a firm one
        base = np.where(firm, 0.85, 1.3)[:, None]
        size = base * np.exp((2.0 * _uniform(seed, kk, sensors, 8) - 1.0) * 0.5 * c.size_spread)
        ratio = _uniform(seed, kk, sensors, 9) * 0.5 * c.shear_ratio
        angle = 2.0 * np.pi * _uniform(seed, kk, sensors, 10)
    shear[:, :, 0] = f * ratio * np.cos(angle)
    shear[:, :, 1] = f * ratio * np.sin(angle)
    return Contacts(f, pos, shear, size * np.ones((n, N_FINGERS)))


def _count_frames(mark: float, fps: float, *, strict: bool) -> int:
    """Number of frames ``k >= 0`` with ``k / fps < mark`` (strict) or ``<= mark``, exactly."""
    if not mark > -np.inf or mark < 0:
        return 0
    if mark == np.inf:
        return 2**62
    k = math.floor(mark * fps)
    while (k + 1) / fps < mark or (not strict and (k + 1) / fps == mark):
        k += 1
    while k >= 0 and (k / fps > mark or (strict and k / fps == mark)):
        k -= 1
    return k + 1


class TactipSim(Source):
    """Three emulated TacTips (thumb, index, middle): 30-pin camera frames and the true contact force.

    Ports
    -----
    force (input, optional) : float64 (3,), units "N"
        True contact force from a gripper simulator (closed loop). When connected, frame ``k``
        renders the latest force sample with ``t <= k / fps`` (0 before the first) at the contact
        position ``contact_mm``, and the scenario is not used.
    frames : uint8 (3, 240, 320), units "DN"
        Gray camera frames, axis 0 = ``FINGERS`` (thumb, index, middle), at ``fps``.
    force : float64 (3,), units "N", labels FINGERS
        The contact force each frame shows (scenario truth, or the input sample used).
    contact : float64 (3, 2), units "mm"
        Contact centre (x along the finger, y across, from the pin-array centre) of each frame.

    Config
    ------
    See the field docs (``flowtact blocks tactip_sim``). Units are in the field names.

    Notes
    -----
    *Image.* A dark membrane (25–38 DN, lit slightly unevenly, inside an elliptical field of view
    with a darker lens rim) carries 30 white pin tips in 3 staggered rows of 10 (pitch 3 mm =
    21 px, rows 3.4 mm apart, tip radius 0.7 mm ≈ 4.9 px, area ≈ 75 px², inside every sensor's
    Table 3.1 blob-area range), ≈ 140–180 DN above the skin with a slight dome shading and a
    soft 0.6 px edge, rendered at sub-pixel positions. The pins lie inside the centred 90×240
    crop (rows 75–165, columns 40–280) the paper uses. Lens vignetting multiplies everything by
    ``(1 − v) + v·cos⁴θ`` (90° field of view, ``v = vignette``). Sensor noise: independent per
    pixel, approximately Gaussian (Irwin–Hall sum of four uniforms) with SD ``noise_dn`` (3 DN, as
    in the SSIM test frames of NUMERICS §2), then rounding to uint8. With 3 DN the SSIM of a rest
    frame against a rest reference is ≈ 0.8 (noise alone in flat dark regions), like the paper's
    Table 3.2 (max SSIM 0.83–0.85 at its lightest touches).

    *Sensors differ.* Each physical sensor (fixed by ``unit_seed``, not by the run's seed, so a
    model trained on one recording works on another run) has its own array offset (±3, ±2 px),
    rotation (±1°), pin-tip jitter (±0.08 mm, radius ±5 %, brightness ±6 %), overall pin
    brightness (0.85–1.1), skin level, lighting gradient, lens centre and vignetting depth.

    *Contact.* A normal force ``F`` at contact centre ``c`` pushes every pin radially away from
    ``c`` by ``δ(F)·(r/w)·exp(½(1 − r²/w²))`` (largest, ``δ(F) = displacement_mm·(F/5 N)^0.75``,
    at distance ``r = w = 2 + 1.6·F^(1/3)`` mm, none under the centre), and pins within the
    Hertz-like contact radius ``a = 2.5·F^(1/3)`` mm are pressed towards the lens: up to 15 %
    larger and 25 % brighter (``× exp(−r²/2a²)·F/(F + 1.5 N)``). A tangential force drags the
    skin under the contact along it (``0.3 mm/N × exp(−r²/2w²)``), and the object's curvature
    scales the contact size (``size``: ``a`` and ``w`` grow with it). SSIM (7×7, the paper's)
    against a rest reference falls steadily with force: on the 90×240 crop ≈ 0.85 at rest to
    ≈ 0.60 at 5 N for a central contact (Table 3.2: 0.62–0.85), on the full frame 0.80 to 0.73.
    Contacts near the array ends move fewer pins, and shear and contact size change the image
    without changing the normal force, so SSIM alone leaves an error: a linear SSIM→force fit on
    100 s of default taps has an MAE of 0.16–0.23 N per sensor (the paper: 0.14–0.42 N), a small
    CNN on 2× downsampled crops ≈ 0.04 N (the paper's CNN: ≈ 0.10 N).

    *Scenarios.* ``taps``: from ``onset_s`` a tap every ``tap_period_s`` lasting ``tap_s``; at
    each contact position ``levels`` taps of rising peak force from ``force_min_n`` to
    ``force_max_n`` (each jittered by ``level_jitter`` of a level step), then the position moves
    (uniform within ``±position_mm``, plus ``jitter_mm`` per tap) — the paper's collection
    procedure (10 force levels per position); each sensor has its own positions and jitter.
    ``grasp``: every ``grasp_period_s`` all fingers close on an object, alternately soft (force
    rising over ``soft_rise_s`` to ``soft_force_n``) and firm (``firm_rise_s``, ``firm_force_n``),
    hold ``hold_s``, release over ``release_s``; thumb : index : middle forces 1 : 0.6 : 0.5 (±10 %
    per grasp). ``rest``: no contact. Profiles are raised cosines, pure functions of ``t = k/fps``.

    *Determinism.* Frame ``k``'s noise depends only on (run seed, ``k``, sensor) through a
    counter-based hash (splitmix64), the scenario's draws only on (run seed, tap/grasp index,
    sensor): any tick pattern gives identical frames. The run seed comes from ``self.rng``.

    *Timing.* Scenario mode: no latency; frames with ``t < now`` are emitted at each tick.
    Input mode: frame ``k`` waits until the force input's watermark (its last sample time, or its
    ``end`` beyond ``k/fps``) covers ``k/fps``. Every step sets ``end`` on its outputs to the time
    of the next frame not yet emitted (``now`` once everything is out). The force input is not a
    ``delay`` port: if a graph's feedback loop closes through it, the loop must be broken at
    another port (or frames wait one tick for the delayed force). At end of stream (``flush``)
    frames still due render with the last force.

    *Speed.* :func:`render` draws a 3-sensor stack in ≈ 0.8 ms on one core (≈ 1 200 stacks/s,
    numba kernel); the block ticked at 40 Hz ≈ 650 stacks/s. ``render(..., engine="numpy")`` is
    the slow reference twin the tests compare against.

    Example
    -------
    >>> from flowtact.testing import run_source
    >>> out = run_source(TactipSim(scenario="taps", tap_period_s=0.5, tap_s=0.4), 1.0)
    >>> out["frames"].data.shape, out["frames"].data.dtype.name
    ((40, 3, 240, 320), 'uint8')
    >>> round(float(out["force"].data.max()), 2) > 0.4
    True
    """

    config_cls = TactipSimConfig
    inputs = {
        "force": Port(
            dtype="float64",
            shape=(N_FINGERS,),
            units="N",
            optional=True,
            doc="true contact force per sensor from a gripper simulator (replaces the scenario)",
        )
    }
    outputs = {
        "frames": Port(dtype="uint8", shape=(N_FINGERS, HEIGHT, WIDTH), units="DN", doc="gray camera frames"),
        "force": Port(shape=(N_FINGERS,), units="N", doc="true contact force shown by each frame"),
        "contact": Port(shape=(N_FINGERS, 2), units="mm", doc="contact centre (x, y) of each frame"),
    }
    counter_docs = nonfinite_counter_docs("force samples on 'force'")

    def specs(self, inputs: Mapping[str, StreamSpec]) -> dict[str, StreamSpec]:
        spec = inputs.get("force")
        if spec is not None:
            if spec.events:
                raise SpecError("force", "expects a sampled force stream, got events")
            if spec.units != "N":
                raise SpecError("force", f"expects units N, got {spec.units!r} ({spec.describe()})")
            if tuple(spec.shape) != (N_FINGERS,):
                raise SpecError(
                    "force", f"expects one force per sensor, shape ({N_FINGERS},); got {spec.describe()}"
                )
        rate = self.config.fps
        return {
            "frames": StreamSpec(dtype="uint8", shape=(N_FINGERS, HEIGHT, WIDTH), units="DN", rate_hz=rate),
            "force": StreamSpec(shape=(N_FINGERS,), units="N", rate_hz=rate, labels=FINGERS),
            "contact": StreamSpec(
                shape=(N_FINGERS, 2),
                units="mm",
                rate_hz=rate,
                labels=tuple(f"{f} {a}" for f in FINGERS for a in "xy"),
            ),
        }

    def reset(self) -> None:
        c = self.config
        self.i = 0
        self.seed_frames = int(self.rng.integers(0, 2**63))
        self.seed_scenario = int(self.rng.integers(0, 2**63))
        self.driven = "force" in self.input_specs
        cm = np.asarray(c.contact_mm, np.float64)
        self.contact_fixed = np.broadcast_to(cm.reshape(-1, 2), (N_FINGERS, 2)).copy()
        self.latest = np.zeros(N_FINGERS)  # force held from the input (0 before its first sample)
        self.last_good: np.ndarray | None = None
        self.pending_t = np.empty(0)
        self.pending_f = np.empty((0, N_FINGERS))
        self.last_t = -np.inf  # the force input's last sample time
        self.end_mark = -np.inf  # and its watermark
        self.last_now = 0.0
        _units(c.unit_seed, c.vignette)  # build the sensors now, not on the first frame

    def _absorb(self, chunk: Chunk | None) -> None:
        if chunk is None:
            return
        chunk, self.last_good = screen_nonfinite(
            self, chunk, self.config.on_bad_data, "force", self.last_good
        )
        if len(chunk):
            d = np.asarray(chunk.data, np.float64).reshape(len(chunk), N_FINGERS)
            self.pending_t = np.concatenate([self.pending_t, np.asarray(chunk.t, np.float64)])
            self.pending_f = np.concatenate([self.pending_f, d])
        if len(chunk.t):  # dropped samples still tell that time moved on
            self.last_t = max(self.last_t, float(chunk.t[-1]))
        if chunk.end is not None:
            self.end_mark = max(self.end_mark, float(chunk.end))

    def _ready(self) -> int:
        """Frames whose time the force input covers: k/fps <= its last sample time, or < its end."""
        fps = self.config.fps
        return max(
            _count_frames(self.last_t, fps, strict=False), _count_frames(self.end_mark, fps, strict=True)
        )

    def _driven_forces(self, t: np.ndarray) -> np.ndarray:
        """Latest input force with time <= each frame time; consumes the pending samples."""
        f = np.empty((len(t), N_FINGERS))
        j = 0
        for k, tk in enumerate(t):
            while j < len(self.pending_t) and self.pending_t[j] <= tk:
                self.latest = self.pending_f[j]
                j += 1
            f[k] = self.latest
        self.pending_t = self.pending_t[j:]
        self.pending_f = self.pending_f[j:]
        return f

    def step(self, now: float, force: Chunk | None = None) -> dict[str, Chunk]:
        self.last_now = max(self.last_now, float(now))
        due = self.due(self.last_now, self.config.fps)
        if self.driven:
            self._absorb(force)
            due = min(due, self._ready())
        return self._emit(due)

    def flush(self) -> dict[str, Chunk]:
        if not self.driven:
            return {}
        # end of stream: the force input has nothing more, render what is due with the held force
        return self._emit(self.due(self.last_now, self.config.fps))

    def _emit(self, due: int) -> dict[str, Chunk]:
        c = self.config
        n = max(due - self.i, 0)
        idx = self.i + np.arange(n)
        t = idx / c.fps
        self.i += n
        if self.driven:
            f = self._driven_forces(t)
            pos = np.broadcast_to(self.contact_fixed, (n, N_FINGERS, 2)).copy()
            shear, size = None, None
        else:
            truth = scenario_contacts(c, self.seed_scenario, t)
            f, pos, shear, size = truth.force, truth.position, truth.shear, truth.size
        end = min(self.last_now, self.i / c.fps)
        want = self.demanded
        out: dict[str, Chunk] = {}
        if "frames" in want:
            out["frames"] = Chunk(t, render(f, pos, idx, self.seed_frames, c, shear=shear, size=size), end)
        if "force" in want:
            out["force"] = Chunk(t, f, end)
        if "contact" in want:
            out["contact"] = Chunk(t, pos, end)
        return out

    @classmethod
    def example(cls) -> Example:
        return Example(
            params={"scenario": "taps", "onset_s": 0.05, "tap_period_s": 0.3, "tap_s": 0.25, "levels": 3},
            rate_hz=40.0,
            duration_s=1.0,
        )
