"""Grid kernel of an NLIF population whose every unit has its own parameters (threshold, post-spike
weights, besides τ, gain, v_leak, σ), with a threshold block after a spike and either post-spike
history: only the most recent spike's kernel (``last``, a renewal process) or every past spike's
(``sum``, through a per-unit ring as in ``_spike_history``).

TouchSim's afferent model (Saal, Delhaye et al. 2017) is this neuron: after a spike at step ``m``
the current ``H[m + k] = h_unit(k·dt)`` for lags ``k = 1 … L`` (0 beyond) restarts, earlier spikes'
kernels are dropped (``last``); a spike needs ``v > threshold`` and a lag of more than ``n_block`` steps since
the last spike (the threshold is blocked; ``v`` keeps integrating). The summed-history kernel
(``_lif_kernels.lif_grid``) is untouched: a population with shared parameters and no threshold
block keeps that path bit for bit (Rager's model).

Per step and unit, the same update as ``lif_grid``: ``v ← v·a + D·b + s·ξ`` with
``D = v_leak + g·u + H`` clamped to ``±DRIVE_MAX``, then the membrane clamp (``v`` held at 0 while
the refractory count is > 0), threshold and reset to 0. ``H = Σ_j w[j, k]·basis[j, lag_k]``: the unit's
weights on the basis columns any unit uses (a few multiply-adds from a table that stays in L1, not a
per-unit ring); ``lag`` is capped at ``L + 1``, whose table entry is 0. ``sum``: ``H`` is read (and
cleared) from slot ``pos`` of the unit's ring (N, L), and a spike adds ``Σ_j w[j, k]·basis[j, 1 … L]``
into the slots after it (the products summed in ``j`` order: the values may differ by an ulp from
``lif_grid``'s table ``basis @ w``).

Noise: the normals of unit ``k`` come from stream ``k // NOISE_GROUP`` in (step, unit) order, as in
``lif_grid``, so runs are the same whatever the chunking. The loop is step-major over the whole
population (its state, ~12 doubles a unit, stays in L2 up to ~20 000 units).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from flowtact.blocks.spiking._bitops import select
from flowtact.blocks.spiking._lif_kernels import DRIVE_MAX, NOISE_GROUP, NOISE_INTERNAL, NOISE_OFF
from flowtact.blocks.spiking.normal_draws import fill_normal, fill_normal_py

__all__ = ["lif_units", "lif_units_py"]


@njit(cache=True)
def _grow(a: np.ndarray, need: int) -> np.ndarray:
    out = np.empty(max(need, 2 * a.shape[0]), a.dtype)
    out[: a.shape[0]] = a
    return out


@njit(cache=True)
def _draw(noise_mode, rng, xi_ext, i, xbuf):  # type: ignore[no-untyped-def]
    """Step ``i``'s normals for every unit into ``xbuf`` (each group from its own stream)."""
    n = xbuf.shape[0]
    if noise_mode == NOISE_INTERNAL:
        for g in range(rng.shape[0]):
            fill_normal(rng[g], xbuf[g * NOISE_GROUP : min(n, (g + 1) * NOISE_GROUP)])
    else:
        for k in range(n):
            xbuf[k] = xi_ext[i, k]


@njit(cache=True)
def _collect(fired, i, n_fired, spk_step, spk_idx, n_spk):  # type: ignore[no-untyped-def]
    """Append the ``n_fired`` spikes of step ``i`` (flags ``fired``) in unit order."""
    k = 0
    while n_fired > 0:
        if fired[k]:
            spk_step[n_spk] = i
            spk_idx[n_spk] = k
            n_spk += 1
            n_fired -= 1
        k += 1
    return n_spk


@njit(cache=True)
def _ring_add(ring, p, k, w, basis):  # type: ignore[no-untyped-def]
    """A spike of unit ``k`` in the step of slot ``p``: lag ``j`` (1 … L) into slot ``(p + j) % L``."""
    n_lags = ring.shape[1]
    for j in range(1, n_lags + 1):
        h = 0.0
        for b in range(w.shape[0]):
            h += w[b, k] * basis[b, j]
        q = p + j
        if q >= n_lags:
            q -= n_lags
        ring[k, q] += h


@njit(cache=True)
def lif_units(  # noqa: C901 — one hot loop, its variants hoisted by LLVM; see the module doc
    u, coef, thr, w, basis, v, lag, refc, n_block, n_clamp, ring, pos, noise_mode, rng, xi_ext, xbuf, v_out,
    spk_step, spk_idx,
):  # fmt: skip  # type: ignore[no-untyped-def]
    """All steps of a (T, 1 or N) drive ``u`` for N units; mutates ``v``, ``lag``, ``refc`` and the
    generator states. ``coef``: rows a, b, s, v_leak, gain (≥ N columns); ``thr`` (N); ``w`` (J, N)
    and ``basis`` (J, L + 2), last entry 0; ``lag`` capped at L + 1; ``xbuf`` (N) scratch.
    ``ring`` (N, L) with slot ``pos``: the summed history (no columns: the last-spike one).
    Returns (step buffer, unit buffer, spike count, ring slot), grown if short, sorted by step then unit."""
    n_t, n_in = u.shape
    n = v.shape[0]
    n_basis = w.shape[0]
    cap = basis.shape[1] - 1
    want_v = v_out.shape[0] > 0
    noisy = noise_mode != NOISE_OFF
    clamp = n_clamp > 0
    n_lags = ring.shape[1]
    summed = n_lags > 0
    fired = np.zeros(n, np.uint8)
    n_spk = 0
    for i in range(n_t):
        if noisy:
            _draw(noise_mode, rng, xi_ext, i, xbuf)
        if want_v:
            for k in range(n):
                v_out[i, k] = v[k]
        n_fired = 0
        for k in range(n):
            lk = lag[k]
            h = 0.0
            if summed:
                h = ring[k, pos]
                ring[k, pos] = 0.0
            else:
                for j in range(n_basis):
                    h += w[j, k] * basis[j, lk]
            drv = coef[3, k] + coef[4, k] * u[i, 0 if n_in == 1 else k] + h
            d = min(max(drv, -DRIVE_MAX), DRIVE_MAX)
            vn = v[k] * coef[0, k] + d * coef[1, k]
            if noisy:
                vn += coef[2, k] * xbuf[k]
            r = refc[k]
            if clamp:
                vn = select(r > 0, 0.0, vn)
            spike = (vn > thr[k]) and (lk > n_block)
            v[k] = select(spike, 0.0, vn)
            lag[k] = select(spike, 1, min(lk + 1, cap))
            if clamp:
                refc[k] = select(spike, n_clamp, select(r > 0, r - 1, r))
            fired[k] = spike
            n_fired += spike
        if n_fired:
            if n_spk + n_fired > spk_step.shape[0]:
                spk_step = _grow(spk_step, n_spk + n_fired)
                spk_idx = _grow(spk_idx, n_spk + n_fired)
            n_spk = _collect(fired, i, n_fired, spk_step, spk_idx, n_spk)
            if summed:
                for j in range(n_spk - n_fired, n_spk):
                    _ring_add(ring, pos, spk_idx[j], w, basis)
        if summed:
            pos += 1
            if pos == n_lags:
                pos = 0
    return spk_step, spk_idx, n_spk, pos


def lif_units_py(
    u, coef, thr, w, basis, v, lag, refc, n_block, n_clamp, ring, pos, noise_mode, rng, xi_ext, v_out
):  # type: ignore[no-untyped-def]
    """Plain-numpy twin of :func:`lif_units`, one step at a time (tests): returns (steps, units, pos)."""
    n_t = u.shape[0]
    n = v.shape[0]
    cap = basis.shape[1] - 1
    xi = np.zeros(n)
    steps, units = [], []
    for i in range(n_t):
        if noise_mode == NOISE_INTERNAL:
            for g in range(rng.shape[0]):
                fill_normal_py(rng[g], xi[g * NOISE_GROUP : (g + 1) * NOISE_GROUP])
        elif noise_mode != NOISE_OFF:
            xi = xi_ext[i]
        if v_out.shape[0]:
            v_out[i] = v
        n_lags = ring.shape[1]
        if n_lags:
            h = ring[:, pos].copy()
            ring[:, pos] = 0.0
        else:
            h = (w * basis[:, lag]).sum(axis=0)
        d = np.clip(coef[3, :n] + coef[4, :n] * u[i] + h, -DRIVE_MAX, DRIVE_MAX)
        vn = v * coef[0, :n] + d * coef[1, :n]
        if noise_mode != NOISE_OFF:
            vn = vn + coef[2, :n] * xi
        if n_clamp > 0:
            vn = np.where(refc > 0, 0.0, vn)
        spike = (vn > thr) & (lag > n_block)
        v[:] = np.where(spike, 0.0, vn)
        lag[:] = np.where(spike, 1, np.minimum(lag + 1, cap))
        if n_clamp > 0:
            refc[:] = np.where(spike, n_clamp, np.where(refc > 0, refc - 1, refc))
        for k in np.flatnonzero(spike):
            steps.append(i)
            units.append(k)
            if n_lags:
                hk = np.zeros(n_lags)
                for b in range(w.shape[0]):
                    hk = hk + w[b, k] * basis[b, 1 : n_lags + 1]
                ring[k, (pos + np.arange(1, n_lags + 1)) % n_lags] += hk
        if n_lags:
            pos = (pos + 1) % n_lags
    return np.array(steps, np.int64), np.array(units, np.int64), pos
