"""An independent oracle for the NLIF accuracy study: exact threshold-crossing times of the
noise-free LIF (threshold 1, reset 0, absolute refractory period) for a drive that is linear
between samples — closed-form membrane on each segment, crossing located by bisection.

It shares no code with the block's kernels: between samples t_k and t_k + h the drive is
u(t) = u_k + s·(t − t_k), and τ v' = −(v − v_leak) + g·u(t) has the solution
v(t) = v_p(t) + (v_k − v_p(t_k))·e^{−(t − t_k)/τ},  v_p(t) = v_leak + g·(u(t) − s·τ).
v is convex or concave on a segment, so a crossing is either seen at the segment's end or at
the interior extremum; it is then bracketed and bisected to machine precision.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["exact_spikes"]


@njit(cache=True)
def _v_at(t: float, v0: float, a: float, s: float, tau: float, vl: float, g: float) -> float:
    """Membrane at offset t into a segment that starts at v0 with drive a + s·t."""
    vp0 = vl + g * (a - s * tau)
    return vp0 + g * s * t + (v0 - vp0) * math.exp(-t / tau)


@njit(cache=True)
def _first_crossing(v0: float, a: float, s: float, h: float, tau: float, vl: float, g: float) -> float:
    """Offset in [0, h] where v first reaches 1 (v0 ≤ 1), or −1 when it stays below."""
    hi = -1.0
    if _v_at(h, v0, a, s, tau, vl, g) > 1.0:
        hi = h
    else:
        c = v0 - (vl + g * (a - s * tau))
        # interior maximum of a concave v (c < 0, falling target s < 0): v' = g·s − c/τ·e^{−t/τ} = 0
        if c < 0.0 and s < 0.0:
            r = g * s * tau / c
            if 0.0 < r < 1.0:
                tm = -tau * math.log(r)
                if tm < h and _v_at(tm, v0, a, s, tau, vl, g) > 1.0:
                    hi = tm
    if hi < 0.0:
        return -1.0
    lo = 0.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid <= lo or mid >= hi:
            break
        if _v_at(mid, v0, a, s, tau, vl, g) > 1.0:
            hi = mid
        else:
            lo = mid
    return hi


@njit(cache=True)
def _neuron(u: np.ndarray, h: float, tau: float, vl: float, g: float, ref: float, out: np.ndarray) -> int:
    """Spike times of one neuron (written to ``out``), starting at v = 0 at t = 0; returns their count."""
    v = 0.0
    free = 0.0  # held at 0 until this time (refractory)
    n = 0
    for k in range(len(u) - 1):
        t0, t1 = k * h, (k + 1) * h
        if free >= t1:
            continue
        s = (u[k + 1] - u[k]) / h
        start = t0
        if free > t0:
            start, v = free, 0.0
        while True:
            a = u[k] + s * (start - t0)
            off = _first_crossing(v, a, s, t1 - start, tau, vl, g)
            if off < 0.0:
                v = _v_at(t1 - start, v, a, s, tau, vl, g)
                break
            ts = start + off
            if n < len(out):
                out[n] = ts
            n += 1
            free, v = ts + ref, 0.0
            if free >= t1:
                break
            start = free
    return n


def exact_spikes(
    u: np.ndarray, h: float, tau: float, v_leak: float, gain: np.ndarray, refractory: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Spike (times, neuron indices), sorted by time, of len(gain) neurons driven by ``u``: samples
    every ``h`` seconds from t = 0, linear between them, shape (T,) (shared) or (T, n) (per neuron)."""
    gain = np.atleast_1d(np.asarray(gain, np.float64))
    u = np.asarray(u, np.float64)
    times, idx = [], []
    cap = max(16, int(len(u) * h / max(refractory, h)) + 16)
    for i, g in enumerate(gain):
        col = np.ascontiguousarray(u if u.ndim == 1 else u[:, i])
        out = np.empty(cap)
        n = _neuron(col, h, tau, v_leak, float(g), refractory, out)
        if n > cap:
            raise RuntimeError(f"exact_spikes: {n} spikes exceed the buffer of {cap}")
        times.append(out[:n])
        idx.append(np.full(n, i, np.int64))
    t, k = np.concatenate(times), np.concatenate(idx)
    order = np.lexsort((k, t))
    return t[order], k[order]
