"""The Remote Feelings exoskeleton (White 2023, §3.2): FSR force, kinematics, fingertip force, gripper command.

Every stream is vectorised over the three instrumented fingers in the order of
:data:`flowtact.blocks.teleop.hand.FINGERS` (thumb, index, middle). Joint angles are radians, positions
millimetres, forces newtons. Conventions (binding for the teleop graphs, /work/briefs/teleop.md):

- the FSR force and the fingertip force are **positive when the user's finger pushes towards
  closing** against the servo and negative when it pulls back open;
- the finger plane: the MCP joint at the origin, the straight finger along +x, flexion rotating
  counter-clockwise (towards +y, the palm side); the exoskeleton sits on the dorsal side (−y).

Kinematic constants. The thesis gives the equations but not the dimensions of its exoskeleton or
of the user's hand, so the defaults below are **assumptions** (plausible, self-consistent values:
every finger pose in MCP −10…80°, PIP 0…100°, DIP = ⅔·PIP is reachable by the exoskeleton chain):

================  =====================================  ==========================================
constant          default (thumb; index; middle)          source
================  =====================================  ==========================================
eq. 3.10          |F| = 0.6867·exp(0.0023·R) N            thesis, eq. 3.10 (fit to an F/T sensor)
rest readings     20                                      thesis, §3.2.3
τ1 lever          0.02 m                                  thesis, eq. 3.9 text
finger l1,l2,l3   (34, 23, –); (46, 27, 18); (50, 32, 20)  assumed: adult hand ≈ 190 mm long,
                  mm (thumb: proximal, distal)            segment proportions after Buchholz 1992
exo a1,a2,a3      (40, 45, 0); (60, 85, 20); (65, 90, 20)  assumed; a3 = 0 for the thumb (thesis)
s_a (O − MCP)     (−15, −25); (−20, −35); (−20, −35) mm   assumed: servo pivot behind, above MCP
ζ1, ζ2, ζ3        (−0.35, 1.39, 0); (−0.82, 1.59, 0);     assumed: φ1 = φ2 = 0 with the hand
                  (−0.79, 1.53, 0) rad                    open flat (only ζ2 + ζ3 matters)
================  =====================================  ==========================================

Module functions (numpy, vectorised over any leading axes, fingers on axis −2) implement the
chain both ways so that emulators and tests can produce consistent exoskeleton angles from a
finger pose: :func:`exo_forward` (eq. 3.3), :func:`finger_inverse` (eqs. 3.4–3.8),
:func:`finger_forward` and :func:`exo_inverse` (their inverses), :func:`phi_from_theta`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

import numpy as np

import flowtact.api as ft

from .hand import FINGERS, N_FINGERS

__all__ = [
    "EXO_A_MM",
    "EXO_S_A_MM",
    "EXO_ZETA_RAD",
    "FINGER_MM",
    "FSR_EXP_PER_ADC",
    "FSR_LEVER_M",
    "FSR_SCALE_N",
    "REST_READINGS",
    "ExoKinematics",
    "ExoKinematicsConfig",
    "FingertipForce",
    "FingertipForceConfig",
    "FsrForce",
    "FsrForceConfig",
    "GripperCommand",
    "GripperCommandConfig",
    "exo_forward",
    "exo_inverse",
    "finger_forward",
    "finger_inverse",
    "fingertip_gain",
    "phi_from_theta",
]


#: Eq. 3.10: |F_FSR| = FSR_SCALE_N · exp(FSR_EXP_PER_ADC · R_FSR), R the 10-bit ADC reading.
FSR_SCALE_N, FSR_EXP_PER_ADC = 0.6867, 0.0023
#: §3.2.3: the rest offset is the mean of this many readings taken with the fingers still.
REST_READINGS = 20
#: Eq. 3.9: τ1 = 0.02 m · |F_FSR| (the link from the servo pivot O to the ψ1 joint).
FSR_LEVER_M = 0.02

#: Finger segment lengths l1, l2, l3 in mm (thumb: proximal, distal, unused). Assumed.
FINGER_MM: tuple[tuple[float, ...], ...] = ((34.0, 23.0, 0.0), (46.0, 27.0, 18.0), (50.0, 32.0, 20.0))
#: Exoskeleton link lengths a1, a2, a3 in mm (a3 = r6; the thumb's a3 = 0, eq. 3.3). Assumed.
EXO_A_MM: tuple[tuple[float, ...], ...] = ((40.0, 45.0, 0.0), (60.0, 85.0, 20.0), (65.0, 90.0, 20.0))
#: Fixed exoskeleton angles ζ1, ζ2, ζ3 in rad (ψ1 = φ1 + ζ1, ψ2 = φ2 + ζ2 + ζ3). Assumed.
EXO_ZETA_RAD: tuple[tuple[float, ...], ...] = ((-0.35, 1.39, 0.0), (-0.82, 1.59, 0.0), (-0.79, 1.53, 0.0))
#: s_a: the servo pivot O relative to the finger's MCP joint, in mm (eq. 3.3). Assumed.
EXO_S_A_MM: tuple[tuple[float, ...], ...] = ((-15.0, -25.0), (-20.0, -35.0), (-20.0, -35.0))

_THUMB = 0  # row of the thumb: a3 = ψ3 = 0 (eq. 3.3) and a two-joint finger (IK)


# -- kinematics (numpy; elementwise, so chunking never changes a bit) --------------------------------


def _geometry(rows: tuple[tuple[float, ...], ...] | np.ndarray, width: int) -> np.ndarray:
    g = np.asarray(rows, np.float64)
    if g.shape != (N_FINGERS, width):
        raise ValueError(f"expected {N_FINGERS} rows of {width} numbers, got shape {g.shape}")
    return g


def _psi(phi: np.ndarray, zeta: np.ndarray) -> np.ndarray:
    """ψ1 = φ1 + ζ1, ψ2 = φ2 + ζ2 + ζ3, ψ3 = φ3 (thumb: ψ3 = 0); phi (..., 3, 3)."""
    psi = np.empty_like(phi)
    psi[..., 0] = phi[..., 0] + zeta[:, 0]
    psi[..., 1] = phi[..., 1] + (zeta[:, 1] + zeta[:, 2])
    psi[..., 2] = phi[..., 2]
    psi[..., _THUMB, 2] = 0.0
    return psi


def exo_forward(
    phi: np.ndarray,
    a_mm: tuple[tuple[float, ...], ...] | np.ndarray = EXO_A_MM,
    zeta_rad: tuple[tuple[float, ...], ...] | np.ndarray = EXO_ZETA_RAD,
    s_a_mm: tuple[tuple[float, ...], ...] | np.ndarray = EXO_S_A_MM,
) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 3.3: attachment point s_Q (..., 3, 2) mm and ψ1 + ψ2 + ψ3 (..., 3) from φ (..., 3, 3) rad.

    The thumb (row 0) uses a3 = ψ3 = 0, whatever its φ3 column holds.
    """
    a, s_a = _geometry(a_mm, 3), _geometry(s_a_mm, 2)
    psi = _psi(np.asarray(phi, np.float64), _geometry(zeta_rad, 3))
    c1 = psi[..., 0]
    c2 = c1 + psi[..., 1]
    c3 = c2 + psi[..., 2]
    a3 = a[:, 2].copy()
    a3[_THUMB] = 0.0
    s_q = np.empty((*psi.shape[:-1], 2))
    s_q[..., 0] = a[:, 0] * np.cos(c1) + a[:, 1] * np.cos(c2) + a3 * np.cos(c3) + s_a[:, 0]
    s_q[..., 1] = a[:, 0] * np.sin(c1) + a[:, 1] * np.sin(c2) + a3 * np.sin(c3) + s_a[:, 1]
    return s_q, c3


#: Slack on the triangle cosines before a pose counts as out of reach (≈ 0.02 mm beyond full extension).
REACH_TOL = 1e-3


def _two_link(x: np.ndarray, y: np.ndarray, l1: np.ndarray, l2: np.ndarray) -> tuple[np.ndarray, ...]:
    """Planar 2-link IK (eqs. 3.5–3.8), elbow flexed counter-clockwise: (q1, q2, clipped)."""
    r2 = x * x + y * y
    r = np.sqrt(r2)
    c_beta = (l1 * l1 + l2 * l2 - r2) / (2.0 * l1 * l2)
    with np.errstate(divide="ignore", invalid="ignore"):
        c_gamma = (r2 + l1 * l1 - l2 * l2) / (2.0 * l1 * r)
    c_gamma = np.where(r > 0.0, c_gamma, 1.0)
    # flag real misses, not a fully extended finger read through encoder quantisation and noise
    clipped = (np.abs(c_beta) > 1.0 + REACH_TOL) | (np.abs(c_gamma) > 1.0 + REACH_TOL)
    q2 = np.pi - np.arccos(np.clip(c_beta, -1.0, 1.0))
    q1 = np.arctan2(y, x) - np.arccos(np.clip(c_gamma, -1.0, 1.0))
    return q1, q2, clipped


def finger_inverse(
    s_q: np.ndarray,
    angle_sum: np.ndarray,
    finger_mm: tuple[tuple[float, ...], ...] | np.ndarray = FINGER_MM,
) -> tuple[np.ndarray, np.ndarray]:
    """Eqs. 3.4–3.8: finger joint angles θ (..., 3, 3) from s_Q (..., 3, 2) and θ1 + θ2 + θ3 (..., 3).

    Index and middle: DIP = s_Q − ½·l3·[cos Σθ, sin Σθ] (eq. 3.4), θ2 and θ1 from the MCP–PIP–DIP
    triangle (eqs. 3.6, 3.8, with atan2 for the quadrant), θ3 = Σθ − θ1 − θ2. Thumb (row 0, two
    joints): θ1 (MCP) and θ2 (IP) from the 2-link chain MCP → IP → s_Q with links l1 and ½·l2 (s_Q
    at the middle of the distal phalanx); θ3 = 0; ``angle_sum`` is not used for it. Targets out of
    reach are clipped to the nearest reachable pose; the second result flags them (..., 3).
    """
    lengths = _geometry(finger_mm, 3)
    s_q = np.asarray(s_q, np.float64)
    angle_sum = np.asarray(angle_sum, np.float64)
    x = s_q[..., 0] - 0.5 * lengths[:, 2] * np.cos(angle_sum)
    y = s_q[..., 1] - 0.5 * lengths[:, 2] * np.sin(angle_sum)
    x[..., _THUMB] = s_q[..., _THUMB, 0]
    y[..., _THUMB] = s_q[..., _THUMB, 1]
    l2 = lengths[:, 1].copy()
    l2[_THUMB] *= 0.5
    q1, q2, clipped = _two_link(x, y, lengths[:, 0], l2)
    theta = np.empty((*angle_sum.shape, 3))
    theta[..., 0] = q1
    theta[..., 1] = q2
    theta[..., 2] = angle_sum - q1 - q2
    theta[..., _THUMB, 2] = 0.0
    return theta, clipped


def finger_forward(
    theta: np.ndarray, finger_mm: tuple[tuple[float, ...], ...] | np.ndarray = FINGER_MM
) -> np.ndarray:
    """The attachment point s_Q (..., 3, 2) of a finger pose θ (..., 3, 3) (middle of the distal phalanx)."""
    lengths = _geometry(finger_mm, 3)
    theta = np.asarray(theta, np.float64)
    c1 = theta[..., 0]
    c2 = c1 + theta[..., 1]
    c3 = c2 + theta[..., 2]
    l2 = lengths[:, 1].copy()
    l3 = lengths[:, 2].copy()
    l2[_THUMB] *= 0.5
    l3[_THUMB] = 0.0
    s_q = np.empty((*theta.shape[:-1], 2))
    s_q[..., 0] = lengths[:, 0] * np.cos(c1) + l2 * np.cos(c2) + 0.5 * l3 * np.cos(c3)
    s_q[..., 1] = lengths[:, 0] * np.sin(c1) + l2 * np.sin(c2) + 0.5 * l3 * np.sin(c3)
    return s_q


def exo_inverse(
    s_q: np.ndarray,
    angle_sum: np.ndarray,
    a_mm: tuple[tuple[float, ...], ...] | np.ndarray = EXO_A_MM,
    zeta_rad: tuple[tuple[float, ...], ...] | np.ndarray = EXO_ZETA_RAD,
    s_a_mm: tuple[tuple[float, ...], ...] | np.ndarray = EXO_S_A_MM,
) -> np.ndarray:
    """Exoskeleton angles φ (..., 3, 3) that put the attachment at s_Q, at right angles to the phalanx.

    The inverse of :func:`exo_forward` for emulators and tests: ψ1 + ψ2 + ψ3 = Σθ + π/2 (the
    thesis' right-angle connection), the ψ3 joint lies a3 behind s_Q along that direction, and
    the 2-link chain O → ψ2 joint → ψ3 joint is solved with its elbow on the dorsal side. The
    thumb (a3 = ψ3 = 0) only matches the position; its φ3 is 0.
    """
    a, s_a, zeta = _geometry(a_mm, 3), _geometry(s_a_mm, 2), _geometry(zeta_rad, 3)
    s_q = np.asarray(s_q, np.float64)
    total = np.asarray(angle_sum, np.float64) + 0.5 * np.pi
    a3 = a[:, 2].copy()
    a3[_THUMB] = 0.0
    x = s_q[..., 0] - a3 * np.cos(total) - s_a[:, 0]
    y = s_q[..., 1] - a3 * np.sin(total) - s_a[:, 1]
    psi1, psi2, _ = _two_link(x, y, a[:, 0], a[:, 1])
    phi = np.empty((*total.shape, 3))
    phi[..., 0] = psi1 - zeta[:, 0]
    phi[..., 1] = psi2 - (zeta[:, 1] + zeta[:, 2])
    phi[..., 2] = total - psi1 - psi2
    phi[..., _THUMB, 2] = 0.0
    return phi


def phi_from_theta(
    theta: np.ndarray,
    finger_mm: tuple[tuple[float, ...], ...] | np.ndarray = FINGER_MM,
    a_mm: tuple[tuple[float, ...], ...] | np.ndarray = EXO_A_MM,
    zeta_rad: tuple[tuple[float, ...], ...] | np.ndarray = EXO_ZETA_RAD,
    s_a_mm: tuple[tuple[float, ...], ...] | np.ndarray = EXO_S_A_MM,
) -> np.ndarray:
    """Exoskeleton angles φ (..., 3, 3) worn on a finger pose θ (..., 3, 3): what an emulator reports.

    ``ExoKinematics`` with the same constants recovers θ from these φ (to rounding).
    """
    theta = np.asarray(theta, np.float64)
    return exo_inverse(finger_forward(theta, finger_mm), theta.sum(axis=-1), a_mm, zeta_rad, s_a_mm)


def fingertip_gain(
    psi_sum: np.ndarray,
    a_mm: tuple[tuple[float, ...], ...] | np.ndarray = EXO_A_MM,
    lever_m: float = FSR_LEVER_M,
    form: Literal["equation", "text"] = "equation",
) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 3.9 per unit FSR force: (gain (..., 3), unit vector w (..., 3, 2)) with F_f = F·w, |F_f| = |F|·gain.

    ``equation`` (as printed): w = [−1, 0] − (lever/a1)·[cos α, sin α]; ``text`` (as the prose
    derives it): w = [−1, 0] − (lever/a3)·[−sin α, −cos α], a1 for the thumb (a3 = 0). α = π − Σψ.
    """
    a = _geometry(a_mm, 3)
    arm = a[:, 0].copy() if form == "equation" else a[:, 2].copy()
    if form == "text":
        arm[_THUMB] = a[_THUMB, 0]
    c = lever_m / (arm * 1e-3)
    alpha = np.pi - np.asarray(psi_sum, np.float64)
    ux, uy = (np.cos(alpha), np.sin(alpha)) if form == "equation" else (-np.sin(alpha), -np.cos(alpha))
    w = np.empty((*alpha.shape, 2))
    w[..., 0] = -1.0 - c * ux
    w[..., 1] = -c * uy
    return np.sqrt(w[..., 0] * w[..., 0] + w[..., 1] * w[..., 1]), w


# -- shared config pieces -------------------------------------------------------------------------------


def _rows_error(cfg: ft.Config, name: str, width: int) -> None:
    rows = getattr(cfg, name)
    for i, row in enumerate(rows):
        if len(row) != width:
            raise cfg.error(
                name, f"must have {width} numbers per finger; row {i} ({FINGERS[i]}) has {len(row)}"
            )


# -- fsr_force ----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FsrForceConfig(ft.BadDataConfig):
    """Parameters of :class:`FsrForce`."""

    scale_n: float = ft.param(
        FSR_SCALE_N, doc="eq. 3.10 prefactor: |F| = scale_n·exp(exponent_per_adc·R)", gt=0
    )
    exponent_per_adc: float = ft.param(FSR_EXP_PER_ADC, doc="eq. 3.10 exponent per ADC count", gt=0)
    rest_readings: int = ft.param(
        REST_READINGS, doc="readings at rest averaged into the offset (0: no offset, absolute |F|)", ge=0
    )
    adc_max: float = ft.param(
        1023.0, doc="largest valid ADC reading; readings outside [0, adc_max] are bad data", gt=0
    )
    invert: bool = ft.param(
        False, doc="true if pushing the finger closed LOWERS the reading (FSR mounted the other way)"
    )


class FsrForce(ft.Block):
    """FSR reading → signed force: eq. 3.10, minus the rest offset of the first 20 readings (§3.2.3).

    Config
    ------
    See :class:`FsrForceConfig`; the defaults are the thesis' fit (eq. 3.10) and its 20 rest readings.

    Notes
    -----
    The offset is taken in newtons: the mean of eq. 3.10 over the first ``rest_readings`` valid
    readings, per finger (the FSRs are clamped under a preload, so the rest force is not 0). Those
    readings are **held back** until the offset is known and then emitted tared (≈ 0 N): no sample
    is lost, at a one-off start-up latency of ``rest_readings`` samples (0.2 s at 100 Hz; the
    output watermark stays at the first held sample meanwhile). A stream shorter than that is
    tared with the mean of what arrived, at flush (counted ``rest_short``). The sign convention:
    in the thesis' build pressing closed raises the reading (and "negative FSR force" means the
    finger pulls back); ``invert: true`` for a sensor mounted the other way (the original RF
    design). Readings outside [0, adc_max] (a garbled serial line) count ``out_of_range`` and are
    treated as non-finite: ``on_bad_data`` decides (``hold`` before any good reading repeats 0,
    i.e. 0.69 N). The offset is summed sample by sample: chunking never changes a bit. Otherwise
    stateless; latency 0. The watermark (``end``) of ``x`` is passed on.

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.teleop.exo import FsrForce
    >>> from flowtact.testing import run_offline
    >>> r = np.vstack([np.full((2, 3), 300.0), [[300.0, 400.0, 200.0]]])
    >>> out = run_offline(FsrForce(rest_readings=2), x=r, units={"x": "ADC"})
    >>> np.round(out["y"].data[-1], 4).tolist()   # 0.6867·(e^0.92 − e^0.69), 0, 0.6867·(e^0.46 − e^0.69)
    [0.0, 0.354, -0.2813]
    """

    config_cls = FsrForceConfig
    inputs = {
        "x": ft.Port(
            dtype="float64",
            shape=(3,),
            units="ADC",
            require_rate=True,
            doc="raw FSR readings 0..1023 (thumb, index, middle)",
        )
    }
    outputs = {
        "y": ft.Port(
            dtype="float64",
            shape=(3,),
            units="N",
            labels=FINGERS,
            doc="signed force F = ±(0.6867·e^(0.0023·R) − offset) per finger; positive when the finger "
            "pushes towards closing against the servo",
        )
    }
    counter_docs = {
        "out_of_range": "samples with a reading outside [0, adc_max] (a garbled serial line): treated as "
        "NaN, so on_bad_data applies (and counts them too)",
        "rest_short": "the stream ended before rest_readings readings arrived: the rest offset is the mean "
        "of fewer readings",
        "nonfinite_drop": "samples with a NaN/inf or out-of-range reading, removed (on_bad_data: drop): "
        "bad data came from the device",
        "nonfinite_hold": "samples with a NaN/inf or out-of-range reading, held at the last good reading "
        "(0 before any; on_bad_data: hold): bad data came from the device",
    }

    def reset(self) -> None:
        cfg = self.config
        self._sign = -1.0 if cfg.invert else 1.0
        self._last: np.ndarray | None = None
        self._offset: np.ndarray | None = None if cfg.rest_readings else np.zeros(N_FINGERS)
        self._acc = np.zeros(N_FINGERS)
        self._seen = 0
        self._held: list[tuple[np.ndarray, np.ndarray]] = []

    def _force(self, r: np.ndarray) -> np.ndarray:
        return self.config.scale_n * np.exp(self.config.exponent_per_adc * r)

    def step(self, x: ft.Chunk) -> dict[str, ft.Chunk]:
        end = x.end
        if len(x):
            d = x.data
            out = (d < 0.0) | (d > self.config.adc_max)
            if out.any():
                self.count("out_of_range", int(out.reshape(len(x), -1).any(axis=1).sum()))
                x = ft.Chunk(x.t, np.where(out, np.nan, d), x.end)
            x, self._last = ft.screen_nonfinite(self, x, self.config.on_bad_data, "x", self._last)
        f = self._force(x.data)
        if self._offset is not None:
            return {"y": ft.Chunk(x.t, self._sign * (f - self._offset), end)}
        k = self.config.rest_readings
        take = min(k - self._seen, len(x))
        for i in range(take):  # sequential sum: the same additions whatever the chunking
            self._acc = self._acc + f[i]
        self._seen += take
        if len(x):
            self._held.append((x.t, f))
        if self._seen < k:
            first = self._held[0][0][0] if self._held else end
            wm = None if end is None else (min(end, first) if first is not None else end)
            return {"y": ft.Chunk.empty(shape=(N_FINGERS,), end=wm)}
        return {"y": self._release(end)}

    def _release(self, end: float | None) -> ft.Chunk:
        self._offset = self._acc / self._seen
        t = np.concatenate([h[0] for h in self._held])
        f = np.concatenate([h[1] for h in self._held])
        self._held = []
        return ft.Chunk(t, self._sign * (f - self._offset), end)

    def flush(self) -> dict[str, ft.Chunk]:
        if self._offset is None and self._seen:
            self.count("rest_short", 1)
            return {"y": self._release(None)}
        return {}

    @classmethod
    def example(cls) -> ft.Example:
        rng = np.random.default_rng(7)
        n = 150
        t = np.arange(n) / 100.0
        push = np.clip(np.sin(2 * np.pi * 0.8 * (t - 0.3)), -0.4, 1.0) * (t > 0.3)
        r = 300.0 + np.outer(push, [250.0, 300.0, 200.0]) + rng.normal(0, 3.0, (n, N_FINGERS))
        return ft.Example(inputs={"x": np.round(r)}, rate_hz=100.0, units={"x": "ADC"})


# -- exo_kinematics -----------------------------------------------------------------------------------


@dataclass(frozen=True)
class ExoKinematicsConfig(ft.BadDataConfig):
    """Parameters of :class:`ExoKinematics` (geometry rows: thumb, index, middle)."""

    finger_mm: tuple[tuple[float, ...], ...] = ft.param(
        FINGER_MM,
        doc="finger segment lengths l1, l2, l3 in mm per finger (thumb: proximal, distal, unused)",
        min_len=3,
        max_len=3,
        ge=0,
    )
    exo_a_mm: tuple[tuple[float, ...], ...] = ft.param(
        EXO_A_MM,
        doc="exoskeleton link lengths a1, a2, a3 in mm per finger (thumb's a3 unused)",
        min_len=3,
        max_len=3,
        ge=0,
    )
    exo_zeta_rad: tuple[tuple[float, ...], ...] = ft.param(
        EXO_ZETA_RAD, doc="fixed exoskeleton angles ζ1, ζ2, ζ3 in rad per finger", min_len=3, max_len=3
    )
    exo_s_a_mm: tuple[tuple[float, ...], ...] = ft.param(
        EXO_S_A_MM,
        doc="servo pivot O relative to the MCP joint (x, y) in mm per finger",
        min_len=3,
        max_len=3,
    )

    def check(self) -> None:
        _rows_error(self, "finger_mm", 3)
        _rows_error(self, "exo_a_mm", 3)
        _rows_error(self, "exo_zeta_rad", 3)
        _rows_error(self, "exo_s_a_mm", 2)
        for i, row in enumerate(self.finger_mm):
            used = row[:2] if i == _THUMB else row
            if min(used) <= 0:
                raise self.error("finger_mm", f"{FINGERS[i]}: segment lengths must be > 0; got {list(row)}")
        for i, row in enumerate(self.exo_a_mm):
            if min(row[:2]) <= 0:
                raise self.error("exo_a_mm", f"{FINGERS[i]}: a1 and a2 must be > 0; got {list(row)}")


class ExoKinematics(ft.Block):
    """Exoskeleton angles φ → fingertip position s_Q (FK, eq. 3.3) and finger joint angles θ (IK, eqs. 3.4–3.8).

    Config
    ------
    See :class:`ExoKinematicsConfig`; the module docstring tabulates the default geometry (assumed:
    the thesis gives no dimensions) and where each constant comes from.

    Notes
    -----
    FK: ψ1 = φ1 + ζ1, ψ2 = φ2 + ζ2 + ζ3, ψ3 = φ3; s_Q = Σ a_k·[cos, sin](ψ1 + … + ψk) + s_a;
    thumb a3 = ψ3 = 0. IK: θ1 + θ2 + θ3 = ψ1 + ψ2 + ψ3 − π/2 (the right-angle attachment),
    DIP = s_Q − ½·l3·[cos, sin](Σθ), θ2 = π − arccos((l1² + l2² − r²)/(2·l1·l2)),
    θ1 = atan2(y_DIP, x_DIP) − arccos((r² + l1² − l2²)/(2·l1·r)) (the thesis' arctan(y/x), with the
    quadrant kept), θ3 = Σθ − θ1 − θ2. The thumb has two joints: θ1 (MCP), θ2 (IP) from the chain
    MCP → IP → s_Q with links l1 and ½·l2; θ3 = 0. A pose the finger model cannot reach (noise,
    a wrong geometry) is clipped to the nearest reachable one and counted (``ik_out_of_reach``),
    so θ stays finite and Σθ stays exact. Only demanded outputs are computed (θ needs the FK).
    Stateless, elementwise numpy: chunking never changes a bit; latency 0; ``end`` passed on.
    :func:`phi_from_theta` produces φ from a finger pose (for emulators); this block inverts it.

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.teleop.exo import ExoKinematics, phi_from_theta
    >>> from flowtact.testing import run_offline
    >>> theta = np.array([[[0.3, 0.4, 0.0], [0.5, 0.6, 0.4], [0.2, 0.3, 0.2]]])
    >>> out = run_offline(ExoKinematics(), phi=phi_from_theta(theta), units={"phi": "rad"})
    >>> bool(np.allclose(out["theta"].data, theta, atol=1e-9))
    True
    """

    config_cls = ExoKinematicsConfig
    inputs = {
        "phi": ft.Port(
            dtype="float64",
            shape=(3, 3),
            units="rad",
            require_rate=True,
            doc="[φ1 (servo), φ2, φ3] per finger (the thumb's φ3 unused)",
        )
    }
    outputs = {
        "s_q": ft.Port(
            dtype="float64",
            shape=(3, 2),
            units="mm",
            doc="attachment point s_Q on the distal phalanx per finger, MCP at the origin (FK)",
        ),
        "theta": ft.Port(
            dtype="float64",
            shape=(3, 3),
            units="rad",
            doc="[MCP, PIP, DIP] per finger; the thumb [MCP, IP, 0] (IK)",
        ),
    }
    counter_docs = {
        "ik_out_of_reach": "samples with a finger pose the finger model cannot reach, clipped to the "
        "nearest reachable one (θ approximate): noise, or a wrong geometry if frequent",
        **ft.nonfinite_counter_docs("angle samples on 'phi'"),
    }

    def reset(self) -> None:
        self._last: np.ndarray | None = None

    def step(self, phi: ft.Chunk) -> dict[str, ft.Chunk]:
        cfg = self.config
        phi, self._last = ft.screen_nonfinite(self, phi, cfg.on_bad_data, "phi", self._last)
        s_q, psi_sum = exo_forward(phi.data, cfg.exo_a_mm, cfg.exo_zeta_rad, cfg.exo_s_a_mm)
        out = {}
        if "s_q" in self.demanded:
            out["s_q"] = ft.Chunk(phi.t, s_q, phi.end)
        if "theta" in self.demanded:
            theta, clipped = finger_inverse(s_q, psi_sum - 0.5 * np.pi, cfg.finger_mm)
            self.count("ik_out_of_reach", int(clipped.any(axis=-1).sum()))
            out["theta"] = ft.Chunk(phi.t, theta, phi.end)
        return out

    @classmethod
    def example(cls) -> ft.Example:
        n = 120
        t = np.arange(n) / 100.0
        grasp = 0.5 - 0.5 * np.cos(2 * np.pi * 0.8 * t)  # open → closed → open
        theta = np.empty((n, N_FINGERS, 3))
        theta[:, 0] = np.outer(grasp, [0.8, 1.0, 0.0])
        theta[:, 1] = np.outer(grasp, [1.0, 1.3, 0.87]) - [0.1, 0.0, 0.0]
        theta[:, 2] = np.outer(grasp, [1.0, 1.3, 0.87])
        return ft.Example(inputs={"phi": phi_from_theta(theta)}, rate_hz=100.0, units={"phi": "rad"})


# -- fingertip_force -----------------------------------------------------------------------------------


@dataclass(frozen=True)
class FingertipForceConfig(ft.BadDataConfig):
    """Parameters of :class:`FingertipForce`."""

    exo_a_mm: tuple[tuple[float, ...], ...] = ft.param(
        EXO_A_MM, doc="exoskeleton link lengths a1, a2, a3 in mm per finger", min_len=3, max_len=3, ge=0
    )
    exo_zeta_rad: tuple[tuple[float, ...], ...] = ft.param(
        EXO_ZETA_RAD, doc="fixed exoskeleton angles ζ1, ζ2, ζ3 in rad per finger", min_len=3, max_len=3
    )
    lever_m: float = ft.param(
        FSR_LEVER_M, doc="τ1 = lever_m·|F_FSR|: the link from O to the ψ1 joint, in m", gt=0
    )
    form: Literal["equation", "text"] = ft.param(
        "equation",
        doc="equation: eq. 3.9 as printed (a1, [cos α, sin α]); text: as the prose derives it (a3, [−sin α, −cos α])",
    )
    tol_s: float = ft.param(
        1e-6, doc="largest timestamp difference between paired fsr and phi samples, s", gt=0
    )

    def check(self) -> None:
        _rows_error(self, "exo_a_mm", 3)
        _rows_error(self, "exo_zeta_rad", 3)
        for i, row in enumerate(self.exo_a_mm):
            if row[0] <= 0 or (self.form == "text" and i != _THUMB and row[2] <= 0):
                raise self.error("exo_a_mm", f"{FINGERS[i]}: the torque arm must be > 0; got {list(row)}")


class FingertipForce(ft.Block):
    """Fingertip force F_f from the FSR force and the exoskeleton pose: eq. 3.9, signed like the FSR force.

    Config
    ------
    See :class:`FingertipForceConfig`.

    Notes
    -----
    Eq. 3.9: F_f = [−|F|, 0] − τ1/(a1·|[−sin α, −cos α]|)·[cos α, sin α], τ1 = 0.02·|F|,
    α = π − ψ1 − ψ2 − ψ3 (thumb ψ3 = 0). F_f is linear in |F|: F_f = |F|·w(α). The scalar output
    is F·|w(α)| — the magnitude, carrying the sign of the FSR force (the contract: positive when
    the finger pushes closed, negative when it pulls back, which releases the servo). The printed
    equation and the prose disagree (a1 vs a3; [cos α, sin α] vs [−sin α, −cos α], the latter being
    perpendicular to the last link); ``form`` picks one, the printed equation by default (it is also
    the only one defined for the thumb, whose a3 = 0). With the default geometry the gain |w| stays
    within 0.7–1.35 over the working range (MCP −10…80°, PIP 0…100°). Inputs come from one device packet: paired by arrival order with
    :class:`flowtact.streams.align.Aligner` (timestamps must agree to ``tol_s``); ``drop`` removes the
    instant from both. The output watermark is the lower of the inputs' watermarks.

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.teleop.exo import FingertipForce, phi_from_theta
    >>> from flowtact.testing import run_offline
    >>> phi = phi_from_theta(np.zeros((1, 3, 3)))      # open hand: fingers Σψ = π/2, so α = π/2
    >>> out = run_offline(FingertipForce(), fsr=np.array([[1.0, 1.0, -1.0]]), phi=phi,
    ...                   units={"fsr": "N", "phi": "rad"})
    >>> np.round(out["f"].data, 4).tolist()             # fingers: F·sqrt(1 + (0.02 m / a1)²)
    [[0.8605, 1.0541, -1.0463]]
    """

    config_cls = FingertipForceConfig
    inputs = {
        "fsr": ft.Port(
            dtype="float64",
            shape=(3,),
            units="N",
            require_rate=True,
            doc="signed FSR force per finger (fsr_force, low-passed)",
        ),
        "phi": ft.Port(
            dtype="float64",
            shape=(3, 3),
            units="rad",
            require_rate=True,
            same_rate="fsr",
            doc="exoskeleton angles φ1..φ3 of the same device packets",
        ),
    }
    outputs = {
        "f": ft.Port(
            dtype="float64",
            shape=(3,),
            units="N",
            rate="fsr",
            labels=FINGERS,
            doc="signed fingertip force per finger: F·|w(α)|",
        ),
        "f_vec": ft.Port(
            dtype="float64",
            shape=(3, 2),
            units="N",
            rate="fsr",
            doc="the fingertip force vector F·w(α) per finger (eq. 3.9 exactly when F ≥ 0)",
        ),
    }
    counter_docs = {
        "nonfinite_drop": "instants where 'fsr' or 'phi' had NaN/inf, removed from both (on_bad_data: "
        "drop): upstream sent bad data",
        "nonfinite_hold": "samples (per input, 'fsr' and 'phi') with NaN/inf, held at the last finite "
        "value (on_bad_data: hold): upstream sent bad data",
        "unpaired_at_end": "samples of 'fsr' or 'phi' with no partner on the other input when the stream "
        "ended: not used (the inputs delivered different numbers of samples)",
    }

    def reset(self) -> None:
        self._align = ft.Aligner(self.node, self.input_specs, ["fsr", "phi"], tol_s=self.config.tol_s)
        self._last: dict[str, np.ndarray | None] = {"fsr": None, "phi": None}
        self._wm: dict[str, float | None] = {"fsr": None, "phi": None}

    def _watermark(self, chunks: Mapping[str, ft.Chunk]) -> float | None:
        for p in self._wm:
            c = chunks.get(p)
            if c is None:
                continue
            marks = [m for m in (self._wm[p], c.end, float(c.t[-1]) if len(c) else None) if m is not None]
            self._wm[p] = max(marks) if marks else None
        if any(v is None for v in self._wm.values()):
            return None
        return min(v for v in self._wm.values() if v is not None)

    def step(self, **inputs: ft.Chunk) -> dict[str, ft.Chunk]:
        cfg = self.config
        end = self._watermark(inputs)
        t, data = self._align.push(inputs)
        if len(t):
            t, data = ft.screen_aligned(self, cfg.on_bad_data, t, data, self._last)
        phi = data["phi"] if len(t) else np.empty((0, N_FINGERS, 3))
        fsr = data["fsr"] if len(t) else np.empty((0, N_FINGERS))
        _, psi_sum = exo_forward(phi, cfg.exo_a_mm, cfg.exo_zeta_rad, np.zeros((N_FINGERS, 2)))
        gain, w = fingertip_gain(psi_sum, cfg.exo_a_mm, cfg.lever_m, cfg.form)
        out = {}
        if "f" in self.demanded:
            out["f"] = ft.Chunk(t, fsr * gain, end)
        if "f_vec" in self.demanded:
            out["f_vec"] = ft.Chunk(t, fsr[..., None] * w, end)
        return out

    def flush(self) -> dict[str, ft.Chunk]:
        self.count("unpaired_at_end", sum(self._align.pending().values()))
        return {}

    @classmethod
    def example(cls) -> ft.Example:
        rng = np.random.default_rng(8)
        n = 120
        t = np.arange(n) / 100.0
        grasp = 0.5 - 0.5 * np.cos(2 * np.pi * 0.8 * t)
        theta = np.stack([np.outer(grasp, [0.8, 1.0, 0.0])] + [np.outer(grasp, [1.0, 1.3, 0.87])] * 2, axis=1)
        fsr = np.outer(np.sin(2 * np.pi * 0.8 * t), [1.0, 1.5, 1.2]) + rng.normal(0, 0.05, (n, N_FINGERS))
        return ft.Example(
            inputs={"fsr": fsr, "phi": phi_from_theta(theta)}, rate_hz=100.0, units={"fsr": "N", "phi": "rad"}
        )


# -- gripper_command -----------------------------------------------------------------------------------


@dataclass(frozen=True)
class GripperCommandConfig(ft.BadDataConfig):
    """Parameters of :class:`GripperCommand` (one value per finger: thumb, index, middle)."""

    open_rad: tuple[float, ...] = ft.param(
        (0.4, 0.7, 0.7),
        doc="sum of finger angles θ1+θ2+θ3 with the hand open (relaxed), rad",
        min_len=3,
        max_len=3,
    )
    closed_rad: tuple[float, ...] = ft.param(
        (1.8, 3.2, 3.2), doc="sum of finger angles with the hand fully closed, rad", min_len=3, max_len=3
    )

    def check(self) -> None:
        for i, (a, b) in enumerate(zip(self.open_rad, self.closed_rad, strict=True)):
            if a == b:
                raise self.error("closed_rad", f"{FINGERS[i]}: must differ from open_rad ({a:g}); got {b:g}")


class GripperCommand(ft.Block):
    """Finger pose → gripper command in [0, 1] per finger: the sum of finger angles scaled between open and closed.

    Config
    ------
    See :class:`GripperCommandConfig`: the two calibration poses of §3.2.3, as sums of angles.

    Notes
    -----
    y = clip((Σθ − open) / (closed − open), 0, 1) per finger, the thesis' calibration (§3.2.3:
    the user opens then closes the hand; the sums of finger angles in those poses scale later
    sums into [0, 1]). ``closed < open`` is allowed (a reversed scale). Defaults: open flat
    (Σθ = 0) and a firm grasp (thumb 1.8 rad, fingers 3.2 rad ≈ 183°), to be replaced by a user's
    calibration. Σθ is exact even when the IK had to clip the pose (it comes from the exoskeleton).
    Stateless; latency 0; ``end`` passed on.

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.teleop.exo import GripperCommand
    >>> from flowtact.testing import run_offline
    >>> theta = np.array([[[0.55, 0.55, 0.0], [0.6, 0.7, 0.65], [1.0, 1.5, 1.5]]])
    >>> run_offline(GripperCommand(), x=theta, units={"x": "rad"})["y"].data.round(6).tolist()
    [[0.5, 0.5, 1.0]]
    """

    config_cls = GripperCommandConfig
    inputs = {
        "x": ft.Port(
            dtype="float64",
            shape=(3, 3),
            units="rad",
            require_rate=True,
            doc="finger joint angles θ per finger (exo_kinematics.theta)",
        )
    }
    outputs = {
        "y": ft.Port(
            dtype="float64",
            shape=(3,),
            units="1",
            labels=FINGERS,
            doc="gripper command per finger, 0 fully open … 1 fully closed",
        )
    }
    counter_docs = ft.nonfinite_counter_docs("pose samples on 'x'")

    def reset(self) -> None:
        self._open = np.asarray(self.config.open_rad, np.float64)
        self._span = np.asarray(self.config.closed_rad, np.float64) - self._open
        self._last: np.ndarray | None = None

    def step(self, x: ft.Chunk) -> dict[str, ft.Chunk]:
        x, self._last = ft.screen_nonfinite(self, x, self.config.on_bad_data, "x", self._last)
        d = x.data
        total = d[..., 0] + d[..., 1] + d[..., 2]
        return {"y": ft.Chunk(x.t, np.clip((total - self._open) / self._span, 0.0, 1.0), x.end)}

    @classmethod
    def example(cls) -> ft.Example:
        n = 120
        t = np.arange(n) / 100.0
        grasp = 0.6 - 0.7 * np.cos(2 * np.pi * 0.8 * t)  # overshoots both calibration poses
        theta = np.stack([np.outer(grasp, [0.8, 1.0, 0.0])] + [np.outer(grasp, [1.0, 1.3, 0.87])] * 2, axis=1)
        return ft.Example(inputs={"x": theta}, rate_hz=100.0, units={"x": "rad"})
