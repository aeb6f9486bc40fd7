"""The AuNP sensor emulator's samples in one compiled pass: force profile, gauges, drift and noise.

One kernel call per step instead of some thirty numpy calls: at one sample per 1 kHz tick a
source wakes from sleep for every step, and on a shared 2-core machine each distinct numpy call
then runs with cold caches at 3-8x its warm cost (``python scripts/step_costs.py --wake``). Every
value is computed with the same operations, in the same order, as the profile's elementwise numpy
formulas (tests/blocks/touch/test_aunp_sensor.py holds them as the oracle; where numba's sin/cos
and numpy's are both libm's, as here, bit for bit), and depends only on its sample index: the
samples do not depend on the chunking.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from flowtact.blocks.signal.shapes import raised_cosine

from .aunp_config import AunpSensorConfig

__all__ = ["SCENARIOS", "sensor_samples", "trial_constants"]

TOUCH, SLIP, REST = 0, 1, 2
SCENARIOS = {"touch": TOUCH, "slip": SLIP, "rest": REST}
"""Scenario codes of :func:`sensor_samples`."""

# p[...]: the trial's constants, prepared once per run by trial_constants
_BASE, _ONSET, _PERIOD, _KMAX, _DFZ = 0, 1, 2, 3, 4  # baseline N, onset s, period s, last trial, ΔFz N
_S0, _S1, _S2, _S3 = 5, 6, 7, 8  # time scales of the four raised cosines, s
_A, _B, _C = 9, 10, 11  # touch: u_off, shear_ratio·ΔFz, q_off; slip: u1, u2, u3
_COS, _SIN = 12, 13  # touch: cos and sin of the shear angle
_LIFT, _PHI0, _TURN, _MUS, _MUK = 14, 15, 16, 17, 18  # slip: u_lift, angle and turn (rad), μs, μk
_TOP = 19  # slip: baseline + ΔFz
_DRIFT, _W, _PHASE, _AMBIENT, _TCOEFF, _NOISE = 20, 21, 22, 23, 24, 25  # temperature and noise
_XS, _YS, _ZS = 26, 27, 28  # gauge sensitivities per N
N_CONSTANTS = 29


@njit(cache=True, inline="always")
def _raised_cosine(x: float) -> float:
    """``0.5 - 0.5 cos(π clip(x, 0, 1))``, as blocks.signal.shapes.raised_cosine."""
    return 0.5 - 0.5 * math.cos(math.pi * min(max(x, 0.0), 1.0))


@njit(cache=True)
def sensor_samples(
    i0: int, n: int, rate_hz: float, scenario: int, p: np.ndarray, noise: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Samples ``i0 .. i0 + n - 1``: (t, force (n, 3), r (n, 4), ref (n,), temp_c (n,)).

    ``noise`` holds (n, 5) standard normals for the four gauges and the reference, or no rows
    (r and ref are then noise-free: the caller does not emit them).
    """
    t = np.empty(n)
    f = np.empty((n, 3))
    r = np.empty((n, 4))
    ref = np.empty(n)
    temp = np.empty(n)
    noisy = noise.shape[0] == n
    for j in range(n):
        tj = (i0 + j) / rate_hz  # (i + arange(n)) / rate
        t[j] = tj
        fx = fy = 0.0
        fz = p[_BASE]
        if scenario != REST:
            k = np.floor((tj - p[_ONSET]) / p[_PERIOD])
            k = min(max(k, 0.0), p[_KMAX])
            u = tj - p[_ONSET] - k * p[_PERIOD]
            if scenario == TOUCH:
                v = u - p[_A]
                rc0 = _raised_cosine(u / p[_S0])
                rc1 = _raised_cosine(v / p[_S1])
                fz = p[_BASE] + p[_DFZ] * (rc0 - rc1)
                if u < p[_A]:
                    m = p[_B] * _raised_cosine(u / p[_S2])
                else:
                    m = p[_B] * (p[_C] * (1.0 - _raised_cosine(v / p[_S3])))
                fx = m * p[_COS]
                fy = m * p[_SIN]
            else:
                rc0 = _raised_cosine(u / p[_S0])
                rc1 = _raised_cosine((u - p[_LIFT]) / p[_S1])
                rc3 = _raised_cosine((u - p[_B]) / p[_S3])
                fz = p[_BASE] + p[_DFZ] * (rc0 - rc1)
                if u < p[_B]:
                    m = p[_MUS] * p[_TOP] * _raised_cosine((u - p[_A]) / p[_S2])
                elif u < p[_C]:
                    m = p[_TOP] * (p[_MUS] - (p[_MUS] - p[_MUK]) * rc3)
                else:
                    m = p[_MUK] * p[_TOP] * (1.0 - rc1)
                phi = p[_PHI0] + p[_TURN] * rc3
                fx = m * math.cos(phi)
                fy = m * math.sin(phi)
        f[j, 0], f[j, 1], f[j, 2] = fx, fy, fz
        dtemp = 0.0 if p[_DRIFT] == 0.0 else p[_DRIFT] * math.sin(p[_W] * tj + p[_PHASE])
        temp[j] = p[_AMBIENT] + dtemp
        drift = p[_TCOEFF] * dtemp
        # r1..r4 = common − sx, common + sy, common + sx, common − sy (a − b is a + (−b), bit for bit)
        common = fz * (p[_ZS] / 4.0)
        g0 = common + fx * -(p[_XS] / 2.0) + drift
        g1 = common + fy * (p[_YS] / 2.0) + drift
        g2 = common + fx * (p[_XS] / 2.0) + drift
        g3 = common + fy * -(p[_YS] / 2.0) + drift
        if noisy:
            sd = p[_NOISE]
            r[j, 0] = g0 + noise[j, 0] * sd
            r[j, 1] = g1 + noise[j, 1] * sd
            r[j, 2] = g2 + noise[j, 2] * sd
            r[j, 3] = g3 + noise[j, 3] * sd
            ref[j] = drift + noise[j, 4] * sd
        else:
            r[j, 0], r[j, 1], r[j, 2], r[j, 3] = g0, g1, g2, g3
            ref[j] = drift
    return t, f, r, ref, temp


def trial_constants(c: AunpSensorConfig, temp_phase: float) -> np.ndarray:
    """The constants ``p`` of :func:`sensor_samples` for a sensor's config and drift phase, each
    computed as the profile's formula writes it (products of parameters first)."""
    p = np.zeros(N_CONSTANTS)
    d_fz = c.stiffness_n_per_mm * c.indentation_um * 1e-3
    p[[_BASE, _ONSET, _PERIOD, _DFZ]] = c.baseline_n, c.onset_s, c.period_s, d_fz
    p[_KMAX] = (c.repeat - 1) if c.repeat else np.inf
    if c.scenario == "touch":
        u_off = c.ramp_s + c.hold_s
        p[[_S0, _S1, _S2, _S3]] = c.ramp_s, c.unload_s, c.shear_rise_s, c.shear_release_s
        p[[_A, _B]] = u_off, c.shear_ratio * d_fz
        p[_C] = float(raised_cosine(np.array(u_off / c.shear_rise_s)))  # the shear reached at lift-off
        theta = np.array([math.radians(c.shear_angle_deg)])
        p[[_COS, _SIN]] = np.cos(theta)[0], np.sin(theta)[0]
    elif c.scenario == "slip":
        u1 = c.ramp_s
        u2 = u1 + c.drag_s
        u3 = u2 + c.slip_s
        p[[_S0, _S1, _S2, _S3]] = c.ramp_s, c.unload_s, c.drag_s, c.slip_s
        p[[_A, _B, _C, _LIFT]] = u1, u2, u3, u3 + c.hold_s
        p[[_PHI0, _TURN]] = math.radians(c.shear_angle_deg), math.radians(c.slip_turn_deg)
        p[[_MUS, _MUK, _TOP]] = c.friction_mu, c.friction_mu * c.kinetic_ratio, c.baseline_n + d_fz
    p[[_DRIFT, _W, _PHASE]] = c.temp_drift_c, 2.0 * np.pi / c.temp_period_s, temp_phase
    p[[_AMBIENT, _TCOEFF, _NOISE]] = c.ambient_c, c.temp_coeff_per_c, c.noise_sd
    p[[_XS, _YS, _ZS]] = c.sensitivity_per_n
    return p
