"""Post-spike current: the raised-cosine basis of Pillow et al. (2008) and its streaming ring buffer.

The post-spike (history) current of Rager et al.'s eq. 6 is ``I_hist(t) = Σ_{t_i < t} h(t − t_i)``
with ``h(t) = Σ_j w_j b_j(t)`` built on the log-time-stretched raised-cosine basis of the
GLMspiketools function ``makeBasis_PostSpike``::

    x(t)   = log(t + b + 1e-20)
    c_j    = x(t_first) + j·Δ,   Δ = (log(t_last + b) − log(t_first + b)) / (ncols − 1)
    b_j(t) = ½ (1 + cos(clip((x(t) − c_j)·π / (2Δ), −π, π)))
    b_0(t) := 1 for t ≤ t_first  (the GLMspiketools "flat start"; ``first_flat=False`` gives the raw bump)

Column ``j`` peaks at ``t = exp(c_j) − b``; neighbouring bumps are spaced by π/2 in phase so that
four of them overlap and ``Σ_j b_j(t) = 2`` between the 2nd and the 2nd-to-last peak. The support
ends ``2Δ`` (in log time) after the last peak: ``t_max = exp(log(t_last + b) + 2Δ) − b``; ``h`` is 0
beyond. The weights refer to this raw (not orthonormalised) basis; GLMspiketools' absolute-refractory
column is not used (the neuron block has its own ``refractory_s``).

Causality convention (NUMERICS §4): on a grid of step ``dt`` the current during step ``n`` is
``I_hist[n] = Σ_{i < n, spike at i} h((n − i)·dt)`` — strictly past spikes, lags ≥ dt. Streaming
uses a per-neuron ring buffer of ``L = floor(t_max / dt)`` slots: O(1) work per neuron-step (read and
clear one slot) and O(L) per spike. A spike stamped a fraction ``θ`` of a step after the grid point
(the interpolating integrator) adds ``h`` at the fractional lags ``(j − θ)·dt``, linearly
interpolated in the table.

The ring is laid out ``(N, L)``: a neuron's slots are contiguous, so a spike adds ``h`` in two
vectorised runs (before and after the wrap); the per-step read of slot ``p`` is a strided column.
The ``(L, N)`` layout reads a contiguous row per step but scatters every spike over ``L`` rows
``8·N`` bytes apart, which cost 3–4× more at tens of spikes/s (``flowtact bench nlif``, post-spike rows).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = [
    "basis_centres",
    "basis_peaks_s",
    "basis_support_s",
    "history_reference",
    "history_stream",
    "history_stream_py",
    "history_table",
    "raised_cosine_basis",
]


def _check(n_basis: int, peaks_s: tuple[float, float], offset_s: float) -> None:
    if n_basis < 2:
        raise ValueError(f"a raised-cosine basis needs at least 2 columns; got {n_basis}")
    first, last = float(peaks_s[0]), float(peaks_s[1])
    if not (0.0 <= first < last):
        raise ValueError(f"peaks must satisfy 0 <= first < last; got {peaks_s}")
    if not offset_s > 0.0:
        raise ValueError(f"offset must be > 0; got {offset_s}")


def basis_centres(n_basis: int, peaks_s: tuple[float, float], offset_s: float) -> tuple[np.ndarray, float]:
    """Centres ``c_j`` (in log time) of the ``n_basis`` bumps and their spacing ``Δ``."""
    _check(n_basis, peaks_s, offset_s)
    lo = math.log(peaks_s[0] + offset_s + 1e-20)
    hi = math.log(peaks_s[1] + offset_s + 1e-20)
    delta = (hi - lo) / (n_basis - 1)
    return lo + delta * np.arange(n_basis), delta


def basis_peaks_s(n_basis: int, peaks_s: tuple[float, float], offset_s: float) -> np.ndarray:
    """Peak time of every raw column, ``exp(c_j) − b`` (s)."""
    c, _ = basis_centres(n_basis, peaks_s, offset_s)
    return np.exp(c) - 1e-20 - offset_s


def basis_support_s(n_basis: int, peaks_s: tuple[float, float], offset_s: float) -> float:
    """End of the basis' support, ``exp(log(t_last + b) + 2Δ) − b`` (s); every column is 0 after."""
    c, delta = basis_centres(n_basis, peaks_s, offset_s)
    return float(math.exp(c[-1] + 2.0 * delta) - 1e-20 - offset_s)


def raised_cosine_basis(
    t_s: np.ndarray,
    n_basis: int,
    peaks_s: tuple[float, float],
    offset_s: float,
    *,
    first_flat: bool = True,
) -> np.ndarray:
    """The basis evaluated at times ``t_s`` (≥ 0, any grid): shape ``(len(t_s), n_basis)``.

    A function of continuous time, so values at a given ``t`` do not depend on the grid that
    contains it. ``first_flat`` sets column 0 to 1 for ``t ≤ t_first`` (GLMspiketools).
    """
    t = np.asarray(t_s, dtype=np.float64)
    c, delta = basis_centres(n_basis, peaks_s, offset_s)
    x = np.log(t + offset_s + 1e-20)
    arg = np.clip((x[:, None] - c[None, :]) * (np.pi / (2.0 * delta)), -np.pi, np.pi)
    b = 0.5 * (1.0 + np.cos(arg))
    if first_flat:
        b[t <= peaks_s[0], 0] = 1.0
    return b


def history_table(
    weights: tuple[float, ...] | np.ndarray,
    peaks_s: tuple[float, float],
    offset_s: float,
    dt_s: float,
) -> np.ndarray:
    """``h(j·dt)`` for ``j = 0 … L`` with ``L = floor(t_max / dt)`` (the ring-buffer length).

    ``h(0)`` (entry 0) is only used to interpolate fractional lags; grid methods use lags ≥ 1.
    """
    w = np.asarray(weights, dtype=np.float64)
    support = basis_support_s(len(w), peaks_s, offset_s)
    n_lags = max(1, math.floor(support / dt_s * (1.0 + 1e-12)))
    t = np.arange(n_lags + 1) * dt_s
    return raised_cosine_basis(t, len(w), peaks_s, offset_s) @ w


def history_reference(spikes: np.ndarray, h_table: np.ndarray) -> np.ndarray:
    """Test reference: ``I[n] = Σ_{i<n} s[i]·h((n−i)·dt)`` by ``np.convolve`` (one column per neuron)."""
    s = np.asarray(spikes, dtype=np.float64)
    s2 = s.reshape(len(s), -1)
    kern = np.concatenate([[0.0], h_table[1:]])
    out = np.stack([np.convolve(s2[:, k], kern)[: len(s2)] for k in range(s2.shape[1])], axis=1)
    return out.reshape(s.shape)


# -- ring buffer (the same helpers are inlined in the neuron kernels) --------------------------


@njit(cache=True, inline="always")
def _add_lags(dst: np.ndarray, h_table: np.ndarray, j0: int, frac: float) -> None:
    """``dst[i] += h((j0 + i − frac)·dt)`` for every ``i`` of ``dst`` (lags ``j0 …``, table-interpolated).

    Views and a loop index from 0: numba then drops its negative-index check and vectorises.
    """
    m = dst.shape[0]
    h1 = h_table[j0 : j0 + m]
    if frac == 0.0:
        for i in range(m):
            dst[i] += h1[i]
    else:
        w1 = 1.0 - frac
        h0 = h_table[j0 - 1 : j0 - 1 + m]
        for i in range(m):
            dst[i] += w1 * h1[i] + frac * h0[i]


@njit(cache=True, inline="always")
def ring_add(ring: np.ndarray, pos: int, k: int, h_table: np.ndarray, frac: float) -> None:
    """Add one spike of neuron ``k`` (a fraction ``frac`` of a step after slot ``pos``'s grid point).

    Slot ``(pos + j) % L`` of row ``k`` receives ``h((j − frac)·dt)`` for ``j = 1 … L``: lags
    ``1 … L−1−pos`` land after ``pos``, the rest wrap to slots ``0 … pos``.
    """
    row = ring[k]
    n_lags = row.shape[0]
    _add_lags(row[pos + 1 :], h_table, 1, frac)
    _add_lags(row[: pos + 1], h_table, n_lags - pos, frac)


@njit(cache=True)
def history_stream(
    spikes: np.ndarray, h_table: np.ndarray, ring: np.ndarray, pos: int
) -> tuple[np.ndarray, int]:
    """Streaming ``I_hist`` for a (T, N) 0/1 spike array; ``ring`` (N, L) and ``pos`` carry state.

    Returns the (T, N) current (value during each step, before that step's spikes) and the new pos.
    """
    n_t, n = spikes.shape
    n_lags = ring.shape[1]
    out = np.empty((n_t, n))
    for i in range(n_t):
        for k in range(n):
            out[i, k] = ring[k, pos]
            ring[k, pos] = 0.0
        for k in range(n):
            if spikes[i, k]:
                ring_add(ring, pos, k, h_table, 0.0)
        pos += 1
        if pos == n_lags:
            pos = 0
    return out, pos


def history_stream_py(
    spikes: np.ndarray, h_table: np.ndarray, ring: np.ndarray, pos: int
) -> tuple[np.ndarray, int]:
    """Plain-numpy twin of :func:`history_stream` (same ring layout and order of operations)."""
    n_t, n = spikes.shape
    n_lags = ring.shape[1]
    out = np.empty((n_t, n))
    slots_after = np.arange(1, n_lags + 1)
    for i in range(n_t):
        out[i] = ring[:, pos]
        ring[:, pos] = 0.0
        for k in np.flatnonzero(spikes[i]):
            ring[k, (pos + slots_after) % n_lags] += h_table[1:]
        pos = (pos + 1) % n_lags
    return out, pos
