"""Numba kernels of the noisy leaky integrate-and-fire population, with plain-numpy twins.

Model (normalised, NUMERICS §3, §5): ``dv = (−(v − v_leak) + g·u(t) + I_hist(t))/τ dt + σ dW``,
threshold 1 (``v > 1``), reset 0. All kernels process a chunk of ``T`` input samples for ``N``
neurons, mutate the carried state arrays in place and write the spikes into the caller's buffers,
growing them when short (they return the buffers and the spike count).

Grid kernel (``lif_grid``): one update per input sample, ``v ← v·a + D·b + s·ξ`` with the drive
``D = v_leak + g·u_i + I_hist[i]`` held over the step, then threshold → reset (Brian2's order).
The coefficients pick the integrator:

* ``exp``   — ``a = exp(−dt/τ)``, ``b = −expm1(−dt/τ)``, ``s = σ·sqrt(τ/2·(1 − a²))``: exact for input
  held over the step (Brian2 ``exact``) with the exact Ornstein–Uhlenbeck noise step; stable for
  any ``dt/τ``. The ``v·a + D·b`` form survives ``u = ±huge`` (``D + (v − D)·a`` gives inf − inf).
* ``euler`` — ``a = 1 − dt/τ``, ``b = dt/τ``, ``s = σ·sqrt(dt)``: Euler–Maruyama (Brian2 ``euler``).

Interpolating kernel (``lif_interp``): first-order hold of the input over ``[t_i, t_{i+1}]`` solved
exactly, ``v(dt) = v·a + D₀·b + (D₁ − D₀)·e + s·ξ`` with ``e = 1 − τ·b/dt``; a crossing inside the step
is located by linear interpolation between the step's end points, and the neuron restarts exactly
from 0 at that time (second-order spike times).

The drive is clamped to ``±DRIVE_MAX`` (1e100) so that no finite input can overflow the state: a
drive of 1e100 fires at every allowed step anyway. Non-finite inputs never reach a kernel (the
block applies its bad-data policy first).

Noise: exact standard normals from :mod:`normal_draws` (32 SIMD xoshiro256++ lanes feeding a
256-layer ziggurat with its exact tail). Each group of ``NOISE_GROUP`` (4 096) neurons draws from a
stream of its own, seeded from the block's generator, one normal per neuron and step in (step,
neuron) order, so the streams are the same whatever the chunking; a population of up to 4 096
neurons is one stream. The normals of the next ``NOISE_FILL // m`` steps of a tile of ``m`` neurons
come in one generator call. Or from an external ``(T, N)`` array (tests).

Execution order (results are bit-identical whichever is used; the tests check it against the
plain-numpy twins, which step one sample at a time):

* ``N ≤ SCALAR_N``: neuron-major — each neuron runs the whole chunk with its state in registers
  (no per-step loop overhead; a single neuron is a ~4 ns/step dependency chain), spikes are then
  counting-sorted by step;
* otherwise step-major over neuron tiles of ``tile`` neurons that stay in cache for a block of
  ``TIME_BLOCK`` steps; the tiles' spikes of each block are merged into (step, neuron) order by
  whole runs. Noisy populations are tiled by their noise groups.

In the tiled grid run, update → threshold → reset is one branch-free loop that vectorises: a spike
sets a flag byte and the step's spikes are then collected from the flags by a separate (not
inlined) function, so that the spike buffers are plain arguments there (a buffer that may be
reallocated inside the hot loop costs 3× in numba). Its conditionals are :func:`select`, not
``a if c else b``: numba lowers those to branches, and LLVM then vectorises the loop with masked
loads and stores (``vmaskmovpd``), 3× slower on AMD Zen 3 (1.8 against 0.6 ns per neuron-step at
N = 1 000, noise-free).
Both kernels share their buffers, execution order, noise and ring-slot helpers. Each kernel is a
dispatcher over a by-neuron and a by-tile run, inlined into it (a call costs numba a reference-count
pair per array argument, ~0.3 µs per kernel call). Inside the per-step loops only scalar helpers are
inlined (an array an inlined helper takes there, or a tuple of arrays a call returns, costs an
atomic reference-count pair per step: 2–3× at N = 24), so those loops are written out.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from flowtact.blocks.spiking._bitops import select, trailing_zeros
from flowtact.blocks.spiking._spike_history import ring_add
from flowtact.blocks.spiking.normal_draws import fill_normal, fill_normal_py, seed_state

__all__ = [
    "DRIVE_MAX",
    "NOISE_EXTERNAL",
    "NOISE_FILL",
    "NOISE_GROUP",
    "NOISE_INTERNAL",
    "NOISE_OFF",
    "fill_normal",
    "fill_normal_py",
    "grid_coefficients",
    "interp_coefficients",
    "lif_grid",
    "lif_grid_py",
    "lif_interp",
    "lif_interp_py",
    "noise_streams",
    "order_within_steps",
    "seed_state",
    "seed_streams",
]

DRIVE_MAX = 1e100
#: Populations up to this size run neuron-major (state in registers, no per-step loop overhead).
SCALAR_N = 8
#: Steps per time block when neurons are tiled (a tile's state stays in cache for the block).
TIME_BLOCK = 64
#: Neurons per noise stream: neuron ``k`` draws from stream ``k // NOISE_GROUP`` of the block, in
#: (step, neuron) order, so noisy populations are tiled by these groups like noise-free ones.
NOISE_GROUP = 4096
#: Normals drawn per call of the generator: the next steps' draws of a small tile come in one call.
NOISE_FILL = 4096
NOISE_OFF, NOISE_INTERNAL, NOISE_EXTERNAL = 0, 1, 2

# -- coefficients ------------------------------------------------------------------------------


def grid_coefficients(method: str, tau_s: np.ndarray, sigma: np.ndarray, dt_s: float) -> np.ndarray:
    """Rows ``a, b, s`` (3, N) of the grid update ``v ← v·a + D·b + s·ξ`` for ``exp`` or ``euler``."""
    tau = np.asarray(tau_s, dtype=np.float64)
    sigma = np.asarray(sigma, dtype=np.float64)
    if method == "euler":
        c = dt_s / tau
        return np.stack([1.0 - c, c, sigma * math.sqrt(dt_s) * np.ones_like(tau)])
    if method in ("exp", "exp_interp"):
        x = dt_s / tau
        a = np.exp(-x)
        b = -np.expm1(-x)
        s = sigma * np.sqrt(tau / 2.0 * -np.expm1(-2.0 * x))
        return np.stack([a, b, s])
    raise ValueError(f"unknown integrator {method!r}")


def interp_coefficients(tau_s: np.ndarray, sigma: np.ndarray, dt_s: float) -> np.ndarray:
    """Rows ``a, b, e, s, τ, σ`` (6, N) of the first-order-hold exact step (see module doc)."""
    tau = np.asarray(tau_s, dtype=np.float64)
    a, b, s = grid_coefficients("exp", tau, sigma, dt_s)
    e = 1.0 - tau * b / dt_s
    return np.stack([a, b, e, s, tau, np.asarray(sigma, dtype=np.float64) * np.ones_like(tau)])


# -- spike buffers -----------------------------------------------------------------------------


@njit(cache=True)
def _grow(a: np.ndarray, need: int) -> np.ndarray:
    """``a`` copied into a new buffer of at least ``need`` and at least twice its entries."""
    out = np.empty(max(2 * a.shape[0], need), a.dtype)
    out[: a.shape[0]] = a
    return out


@njit(cache=True, inline="always")
def _given_buffers(spk_step, spk_off, spk_idx, with_offsets):  # type: ignore[no-untyped-def]
    """The caller's spike buffers (steps, offsets, neurons) cut to a common length, the offsets
    empty unless ``with_offsets``: the kernels write past no end they were not told of."""
    cap = min(spk_step.shape[0], spk_idx.shape[0])
    if with_offsets:
        cap = min(cap, spk_off.shape[0])
        return spk_step[:cap], spk_off[:cap], spk_idx[:cap]
    return spk_step[:cap], spk_off[:0], spk_idx[:cap]


@njit(cache=True)
def _sort_by_step(steps: np.ndarray, idx: np.ndarray, off: np.ndarray, i0: int, n_b: int) -> None:
    """Stable counting sort by step (steps in ``i0 … i0+n_b−1``) of spike arrays, in place.

    A neuron-major run emits its spikes neuron by neuron; this restores the (step, neuron) order.
    """
    n_spk = steps.shape[0]
    if n_spk < 2:
        return
    start = np.zeros(n_b + 1, np.int64)
    for j in range(n_spk):
        start[steps[j] - i0 + 1] += 1
    for i in range(n_b):
        start[i + 1] += start[i]
    s2 = np.empty_like(steps)
    i2 = np.empty_like(idx)
    o2 = np.empty_like(off)
    has_off = off.shape[0] > 0
    for j in range(n_spk):
        q = start[steps[j] - i0]
        start[steps[j] - i0] += 1
        s2[q] = steps[j]
        i2[q] = idx[j]
        if has_off:
            o2[q] = off[j]
    steps[:] = s2
    idx[:] = i2
    if has_off:
        off[:] = o2


@njit(cache=True, inline="always")
def _sorted_spikes(spk_step, spk_off, spk_idx, n_spk, n, n_t):  # type: ignore[no-untyped-def]
    """The buffers, their first ``n_spk`` spikes (of a neuron-major run, neuron by neuron) sorted
    in place by step then neuron."""
    if n > 1:
        _sort_by_step(spk_step[:n_spk], spk_idx[:n_spk], spk_off[:n_spk], 0, n_t)
    return spk_step, spk_off, spk_idx


@njit(cache=True)
def _merge_tiles(spk_step, spk_idx, spk_off, nb0, n_spk, segs, i0):  # type: ignore[no-untyped-def]
    """Spikes ``nb0 … n_spk−1`` of a time block from step ``i0``, written tile by tile, put in
    (step, neuron) order in place: tile ``t``'s spikes of step ``i0 + j`` are entries
    ``segs[t, j] … segs[t, j + 1]``, so whole runs are copied (a counting sort of every spike cost
    ~30 ns per spike at N = 100 000)."""
    if n_spk - nb0 < 2:
        return
    idx = spk_idx[nb0:n_spk].copy()
    timed = spk_off.shape[0] > 0
    off = spk_off[nb0:n_spk].copy() if timed else spk_off[:0]
    q = nb0
    for j in range(segs.shape[1] - 1):
        for t in range(segs.shape[0]):
            for x in range(segs[t, j] - nb0, segs[t, j + 1] - nb0):
                spk_step[q] = i0 + j
                spk_idx[q] = idx[x]
                if timed:
                    spk_off[q] = off[x]
                q += 1


@njit(cache=True)
def order_within_steps(steps: np.ndarray, off: np.ndarray) -> np.ndarray:
    """Permutation putting spikes sorted by (step, neuron) into (step, offset, neuron) order.

    Steps are disjoint time intervals, so only the runs of one step need sorting (a stable sort
    by offset keeps equal offsets in neuron order).
    """
    n = steps.shape[0]
    perm = np.arange(n)
    j0 = 0
    while j0 < n:
        j1 = j0 + 1
        while j1 < n and steps[j1] == steps[j0]:
            j1 += 1
        if j1 - j0 > 1:
            perm[j0:j1] = j0 + np.argsort(off[j0:j1], kind="mergesort")
        j0 = j1
    return perm


# -- execution order and the pieces of a step both kernels share -------------------------------


@njit(cache=True, inline="always")
def _neuron_major(n, noise_mode):  # type: ignore[no-untyped-def]
    """Whether a population runs neuron by neuron (small, and not drawing a shared noise stream)."""
    return n <= SCALAR_N and (noise_mode != NOISE_INTERNAL or n == 1)


def noise_streams(n: int) -> int:
    """How many noise streams (rows of the generator state) a population of ``n`` neurons draws from."""
    return -(-n // NOISE_GROUP)


def seed_streams(rng: np.random.Generator, n: int) -> np.ndarray:
    """The generator states of a population of ``n`` neurons, drawn from ``rng`` one after another."""
    return np.stack([seed_state(rng) for _ in range(noise_streams(n))])


def _draw_py(rng: np.ndarray, xi: np.ndarray) -> None:
    """One step's normals for the whole population, each group of neurons from its own stream."""
    for g in range(rng.shape[0]):
        fill_normal_py(rng[g], xi[g * NOISE_GROUP : (g + 1) * NOISE_GROUP])


@njit(cache=True, inline="always")
def _one_neuron_noise(noise_mode, rng, xi_ext, n_t):  # type: ignore[no-untyped-def]
    """(normals, mode) for a neuron-major run: a single neuron's internal draws are made in one
    fast batch (the same stream) and then read like external normals."""
    if noise_mode == NOISE_INTERNAL:
        xi_flat = np.empty(n_t)
        fill_normal(rng[0], xi_flat)
        return xi_flat.reshape((n_t, 1)), NOISE_EXTERNAL
    return xi_ext, noise_mode


@njit(cache=True, inline="always")
def _tiling(n, n_t, tile, noise_mode):  # type: ignore[no-untyped-def]
    """(neurons per tile, steps per time block); internal noise tiles by its streams' groups."""
    if noise_mode == NOISE_INTERNAL:
        tile = NOISE_GROUP
    if tile < 1 or tile >= n:
        return n, max(n_t, 1)
    return tile, TIME_BLOCK


@njit(cache=True, inline="always")
def _tile_segments(n, tile, t_block):  # type: ignore[no-untyped-def]
    """Spike-count marks of every tile at every step of a time block (see :func:`_merge_tiles`);
    no rows when the run is one tile."""
    if tile >= n:
        return np.empty((1, 0), np.int64)
    return np.empty((-(-n // tile), t_block + 1), np.int64)


@njit(cache=True, inline="always")
def _steps_per_fill(m):  # type: ignore[no-untyped-def]
    """Steps whose normals one generator call makes for a tile of ``m`` neurons."""
    return max(1, NOISE_FILL // m)


@njit(cache=True, inline="always")
def _ring_slot(pos, step, n_lags):  # type: ignore[no-untyped-def]
    """The post-spike ring slot of ``step`` steps after slot ``pos`` (0 without a ring)."""
    return (pos + step) % n_lags if n_lags > 0 else 0


@njit(cache=True, inline="always")
def _next_slot(p, n_lags):  # type: ignore[no-untyped-def]
    """The ring slot after ``p`` (unchanged without a ring)."""
    if n_lags > 0:
        p += 1
        if p == n_lags:
            p = 0
    return p


# The helpers below that take arrays are called, not inlined, from the tiled step loops: an
# array argument of an inlined helper costs an atomic reference-count pair per step there.


@njit(cache=True)
def _add_history(ring, p, h_table, spk_idx, spk_off, j0, j1, dt):  # type: ignore[no-untyped-def]
    """The post-spike current of spikes ``j0 … j1−1``, fired in the step of ring slot ``p``, into
    the ring; their offsets (if recorded) place them inside the step of length ``dt``."""
    timed = spk_off.shape[0] > 0
    for j in range(j0, j1):
        ring_add(ring, p, spk_idx[j], h_table, spk_off[j] / dt if timed else 0.0)


@njit(cache=True)
def _draw_noise(noise_mode, rng, xi_ext, i, n_steps, k0, m, xbuf):  # type: ignore[no-untyped-def]
    """The standard normals of steps ``i … i+n_steps−1`` for the tile of ``m`` neurons from
    ``k0``, step by step into ``xbuf``: from the tile's stream (``rng[k0 // NOISE_GROUP]``; tiles
    of internal noise are its groups) or the external array."""
    if noise_mode == NOISE_INTERNAL:
        fill_normal(rng[k0 // NOISE_GROUP], xbuf[: n_steps * m])
    else:
        for j in range(n_steps):
            xe = xi_ext[i + j, k0 : k0 + m]
            xj = xbuf[j * m : j * m + m]
            for k in range(m):
                xj[k] = xe[k]


# -- grid kernel (exp / euler) -----------------------------------------------------------------


@njit(cache=True)
def _collect_fired(fired_words, n_fired, k0, i, spk_step, spk_idx, n_spk):  # type: ignore[no-untyped-def]
    """Append the ``n_fired`` spikes of step ``i`` to the buffers, in neuron order: the set bytes of a
    tile's fired flags (one byte per neuron, read 8 at a time), the first neuron being ``k0``.

    A separate function so that the spike buffers are fixed arrays inside its loop; the update loop
    itself stays branch-free, so it vectorises (a branch per neuron there cost ~1.5 ns per step).
    Packing 64 flags into one bit mask first, for fewer loop exits, was slower below ~10 % spikes
    per step (0.32 against 0.24 ns per neuron-step at 5 %).
    """
    w = 0
    while n_fired > 0:
        x = fired_words[w]
        while x and n_fired > 0:  # bytes past the tile's end are stale: stop at the last spike
            spk_step[n_spk] = i
            spk_idx[n_spk] = k0 + 8 * w + np.intp(trailing_zeros(x) >> np.uint64(3))
            n_spk += 1
            n_fired -= 1
            x &= x - np.uint64(1)
        w += 1
    return n_spk


@njit(cache=True)
def _grid_neuron(
    u, k, coef, v, refc, n_clamp, ring, pos, h_table, noisy, xi, v_out, spk_step, spk_idx, n_spk
):  # type: ignore[no-untyped-def]
    """All steps of neuron ``k`` with its state in registers (neuron-major path for small N);
    ``noisy``: add the normals ``xi[:, k]``."""
    n_t, n_in = u.shape
    n_lags = ring.shape[1]
    want_v = v_out.shape[0] > 0
    col = 0 if n_in == 1 else k
    a, b, s, vl, g = coef[0, k], coef[1, k], coef[2, k], coef[3, k], coef[4, k]
    vk, rk = v[k], refc[k]
    p = pos
    for i in range(n_t):
        drv = vl + g * u[i, col]
        if n_lags > 0:
            drv += ring[k, p]
            ring[k, p] = 0.0
        if want_v:
            v_out[i, k] = vk
        d = min(max(drv, -DRIVE_MAX), DRIVE_MAX)
        vn = vk * a + d * b + s * xi[i, k] if noisy else vk * a + d * b
        vk = vn if rk == 0 else 0.0
        if vk > 1.0:
            vk = 0.0
            rk = n_clamp
            spk_step[n_spk] = i
            spk_idx[n_spk] = k
            n_spk += 1
            if n_lags > 0:
                ring_add(ring, p, k, h_table, 0.0)
        elif rk > 0:
            rk -= 1
        p = _next_slot(p, n_lags)
    v[k], refc[k] = vk, rk
    return n_spk, p


@njit(cache=True, inline="always")
def _grid_by_neuron(u, coef, v, refc, n_clamp, ring, pos, h_table, noise_mode, rng, xi_ext, v_out, bufs):  # type: ignore[no-untyped-def]
    """The neuron-major grid run: each neuron runs the whole chunk with its state in registers."""
    n_t, n = u.shape[0], v.shape[0]
    xi, noise_mode = _one_neuron_noise(noise_mode, rng, xi_ext, n_t)
    spk_step, spk_off, spk_idx = bufs
    n_spk, pos_end = 0, pos
    for k in range(n):
        if n_spk + n_t > spk_step.shape[0]:
            spk_step = _grow(spk_step, n_spk + n_t)
            spk_idx = _grow(spk_idx, n_spk + n_t)
        n_spk, pos_end = _grid_neuron(
            u, k, coef, v, refc, n_clamp, ring, pos, h_table, noise_mode != NOISE_OFF, xi, v_out,
            spk_step, spk_idx, n_spk,
        )  # fmt: skip
    return _sorted_spikes(spk_step, spk_off, spk_idx, n_spk, n, n_t), n_spk, pos_end


@njit(cache=True, inline="always")
def _grid_fire(vn, r, n_clamp, refractory):  # type: ignore[no-untyped-def]
    """One neuron's threshold → reset → refractory count after its update ``vn`` (``refractory``:
    held at 0 while its count ``r`` > 0): (v, new count, spike). Scalars only, and selects, not
    branches (a branch here turns the vectorised loop's loads and stores into masked ones)."""
    if refractory:
        vn = select(r == 0, vn, 0.0)
    spike = vn > 1.0
    if refractory:
        r = select(spike, n_clamp, select(r > 0, r - 1, r))
    return select(spike, 0.0, vn), r, spike


@njit(cache=True, inline="always")
def _grid_tile_steps(  # noqa: C901 — one hot loop in six variants; see the docstring
    u, ib, ie, k0, k1, coef, v, refc, n_clamp, ring, p, h_table, noise_mode, rng, xi_ext, work, xbuf, v_out,
    spk_step, spk_off, spk_idx, n_spk, seg,
):  # fmt: skip  # type: ignore[no-untyped-def]
    """Steps ``ib … ie−1`` of the neurons ``k0 … k1−1`` (ring slot ``p`` at step ``ib``); returns
    the spike buffers (grown if needed), the spike count and the ring slot after the last step.
    ``seg`` (empty when untiled) receives the spike count at the start of each step and at the end.

    One loop with the step written out: numba would add an atomic reference-count pair per step for
    every array handed to an inlined helper here, and a called one costs ~20 ns per step. The
    update loop comes in variants, each vectorised and branch-free: with the drive computed in it
    (one shared input, no post-spike current) or read from a row the step fills first; with or
    without noise; with or without refractory counts (0.66 against 0.47 ns per neuron-step).
    """
    n_in = u.shape[1]
    n_lags = ring.shape[1]
    want_v = v_out.shape[0] > 0
    refractory = n_clamp > 0
    fused = n_in == 1 and n_lags == 0 and not refractory
    noisy = noise_mode != NOISE_OFF
    m = k1 - k0
    # views of this tile: every inner loop runs over 0 … m−1
    vt, rt = v[k0:k1], refc[k0:k1]
    a, b, s = coef[0, k0:k1], coef[1, k0:k1], coef[2, k0:k1]
    vl, g = coef[3, k0:k1], coef[4, k0:k1]
    drv = work[0, k0:k1]
    fired_words = work[1].view(np.uint64)  # the tile's flags from byte 0 (see _collect_fired)
    fired = fired_words.view(np.uint8)
    per_fill = _steps_per_fill(m)
    xr = xbuf[:m]
    tiled = seg.shape[0] > 0
    for i in range(ib, ie):
        if tiled:
            seg[i - ib] = n_spk
        ui = u[i, 0]
        if fused:
            pass
        elif n_in == 1:
            for k in range(m):
                drv[k] = vl[k] + g[k] * ui
        else:
            for k in range(m):
                drv[k] = vl[k] + g[k] * u[i, k0 + k]
        if n_lags > 0:
            rr = ring[k0:k1, p]
            for k in range(m):
                drv[k] += rr[k]
                rr[k] = 0.0
        if want_v:
            vo = v_out[i, k0:k1]
            for k in range(m):
                vo[k] = vt[k]
        if n_spk + m > spk_step.shape[0]:  # one call per buffer (see the module notes)
            spk_step = _grow(spk_step, n_spk + m)
            spk_idx = _grow(spk_idx, n_spk + m)
        if noisy:
            j = (i - ib) % per_fill
            if j == 0:
                _draw_noise(noise_mode, rng, xi_ext, i, min(per_fill, ie - i), k0, m, xbuf)
            xr = xbuf[j * m : j * m + m]
        # update → threshold → reset → refractory count, with no branch (a spike is a flag byte)
        n_fired = 0
        if fused and noisy:
            for k in range(m):
                d = min(max(vl[k] + g[k] * ui, -DRIVE_MAX), DRIVE_MAX)
                vt[k], _, spike = _grid_fire(vt[k] * a[k] + d * b[k] + s[k] * xr[k], 0, 0, False)
                fired[k] = spike
                n_fired += spike
        elif fused:
            for k in range(m):
                d = min(max(vl[k] + g[k] * ui, -DRIVE_MAX), DRIVE_MAX)
                vt[k], _, spike = _grid_fire(vt[k] * a[k] + d * b[k], 0, 0, False)
                fired[k] = spike
                n_fired += spike
        elif refractory and noisy:
            for k in range(m):
                d = min(max(drv[k], -DRIVE_MAX), DRIVE_MAX)
                vt[k], rt[k], spike = _grid_fire(vt[k] * a[k] + d * b[k] + s[k] * xr[k], rt[k], n_clamp, True)
                fired[k] = spike
                n_fired += spike
        elif refractory:
            for k in range(m):
                d = min(max(drv[k], -DRIVE_MAX), DRIVE_MAX)
                vt[k], rt[k], spike = _grid_fire(vt[k] * a[k] + d * b[k], rt[k], n_clamp, True)
                fired[k] = spike
                n_fired += spike
        elif noisy:
            for k in range(m):
                d = min(max(drv[k], -DRIVE_MAX), DRIVE_MAX)
                vt[k], _, spike = _grid_fire(vt[k] * a[k] + d * b[k] + s[k] * xr[k], 0, 0, False)
                fired[k] = spike
                n_fired += spike
        else:
            for k in range(m):
                d = min(max(drv[k], -DRIVE_MAX), DRIVE_MAX)
                vt[k], _, spike = _grid_fire(vt[k] * a[k] + d * b[k], 0, 0, False)
                fired[k] = spike
                n_fired += spike
        n0 = n_spk
        if n_fired > 0:
            n_spk = _collect_fired(fired_words, n_fired, k0, i, spk_step, spk_idx, n_spk)
        if n_lags > 0 and n_spk > n0:
            _add_history(ring, p, h_table, spk_idx, spk_off, n0, n_spk, 1.0)
        p = _next_slot(p, n_lags)
    if tiled:
        seg[ie - ib] = n_spk
    return spk_step, spk_off, spk_idx, n_spk, p


@njit(cache=True, inline="always")
def _grid_by_tile(
    u, coef, v, refc, n_clamp, ring, pos, h_table, noise_mode, rng, xi_ext, work, xbuf, v_out, tile, bufs
):  # type: ignore[no-untyped-def]
    """The step-major grid run over neuron tiles that stay in cache for a block of steps."""
    n_t, n = u.shape[0], v.shape[0]
    spk_step, spk_off, spk_idx = bufs
    n_spk, pos_end = 0, pos
    tile, t_block = _tiling(n, n_t, tile, noise_mode)
    segs = _tile_segments(n, tile, t_block)
    for ib in range(0, n_t, t_block):
        ie = min(ib + t_block, n_t)
        nb0 = n_spk
        for t, k0 in enumerate(range(0, n, tile)):
            spk_step, spk_off, spk_idx, n_spk, pos_end = _grid_tile_steps(
                u, ib, ie, k0, min(k0 + tile, n), coef, v, refc, n_clamp, ring, _ring_slot(pos, ib, ring.shape[1]),
                h_table, noise_mode, rng, xi_ext, work, xbuf, v_out, spk_step, spk_off, spk_idx, n_spk, segs[t],
            )  # fmt: skip
        if tile < n:
            _merge_tiles(spk_step, spk_idx, spk_off, nb0, n_spk, segs[:, : ie - ib + 1], ib)
    return (spk_step, spk_off, spk_idx), n_spk, pos_end


@njit(cache=True)
def lif_grid(
    u: np.ndarray,  # (T, M) drive samples, M = 1 (shared) or N
    coef: np.ndarray,  # (5, N): a, b, s, v_leak, gain
    v: np.ndarray,  # (N,) membrane, in/out
    refc: np.ndarray,  # (N,) int64 refractory steps left, in/out
    n_clamp: int,  # steps held at reset after a spike
    ring: np.ndarray,  # (N, L) post-spike ring buffer (L = 0: no history current)
    pos: int,  # ring slot of the first step
    h_table: np.ndarray,  # (L + 1,) h(j·dt)
    noise_mode: int,  # 0 off, 1 internal generator, 2 external normals
    rng: np.ndarray,  # (noise_streams(N), STATE_WORDS) uint64 generator states, in/out
    xi_ext: np.ndarray,  # (T, N) external normals (noise_mode 2) else (0, N)
    work: np.ndarray,  # (2, N) scratch
    xbuf: np.ndarray,  # scratch for normals, max(NOISE_FILL, N) float64
    v_out: np.ndarray,  # (T, N) membrane at each step's start, or (0, N)
    tile: int,  # neurons per tile (0: no tiling)
    spk_step: np.ndarray,  # int64 buffer for the spikes' steps (any length; grown when too short)
    spk_idx: np.ndarray,  # int64 buffer for the spikes' neurons, as long as spk_step
) -> tuple[np.ndarray, np.ndarray, int, int]:
    """All ``T`` steps of a grid integrator; returns (step buffer, neuron buffer, spike count, ring
    pos): the first ``count`` entries of the buffers are the spikes.

    Spikes come sorted by step, then neuron. Neurons are processed in tiles that stay in cache
    for the whole chunk; the internal noise generator is sequential, so it forces one tile.
    """
    bufs = _given_buffers(spk_step, np.empty(0), spk_idx, False)
    if _neuron_major(v.shape[0], noise_mode):
        spikes, n_spk, pos_end = _grid_by_neuron(
            u, coef, v, refc, n_clamp, ring, pos, h_table, noise_mode, rng, xi_ext, v_out, bufs
        )
    else:
        spikes, n_spk, pos_end = _grid_by_tile(
            u, coef, v, refc, n_clamp, ring, pos, h_table, noise_mode, rng, xi_ext, work, xbuf, v_out, tile, bufs
        )  # fmt: skip
    return spikes[0], spikes[2], n_spk, pos_end


def _ring_add_py(ring: np.ndarray, pos: int, k: int, h_table: np.ndarray, frac: float) -> None:
    """Numpy twin of :func:`ring_add` (the same sums, element by element)."""
    n_lags = ring.shape[1]
    lags = (pos + np.arange(1, n_lags + 1)) % n_lags
    if frac == 0.0:
        ring[k, lags] += h_table[1:]
    else:
        ring[k, lags] += (1.0 - frac) * h_table[1:] + frac * h_table[:-1]


def lif_grid_py(u, coef, v, refc, n_clamp, ring, pos, h_table, noise_mode, rng, xi_ext, v_out):  # type: ignore[no-untyped-def]
    """Plain-numpy twin of :func:`lif_grid`: the same arguments but the scratch and tuning ones
    (``work``, ``tile``, the spike buffers); returns (steps, neurons, ring pos), the spikes the
    kernel's buffers hold; one step at a time."""
    n_t = u.shape[0]
    n_lags = ring.shape[1]
    a, b, s, vl, g = coef
    steps, idx = [], []
    for i in range(n_t):
        drv = vl + g * u[i]
        if n_lags > 0:
            drv = drv + ring[:, pos]
            ring[:, pos] = 0.0
        if v_out.shape[0]:
            v_out[i] = v
        d = np.clip(drv, -DRIVE_MAX, DRIVE_MAX)
        vn = v * a + d * b
        if noise_mode:
            xi = np.empty(v.shape[0])
            if noise_mode == 1:
                _draw_py(rng, xi)
            else:
                xi = xi_ext[i]
            vn = vn + s * xi
        v[:] = np.where(refc == 0, vn, 0.0)
        fired = np.flatnonzero(v > 1.0)
        refc[:] = np.where(refc > 0, refc - 1, 0)
        v[fired] = 0.0
        refc[fired] = n_clamp
        steps += [i] * len(fired)
        idx += fired.tolist()
        if n_lags > 0:
            for k in fired:
                _ring_add_py(ring, pos, k, h_table, 0.0)
            pos = (pos + 1) % n_lags
    return np.array(steps, np.int64), np.array(idx, np.int64), pos


# -- interpolating kernel (exp + first-order hold + crossing interpolation) ---------------------


@njit(cache=True, inline="always")
def _segment(
    v0: float, s0: float, dt: float, d0: float, d1: float, tau: float, sig: float, xi: float
) -> float:
    """Exact FOH solution from ``v0`` at ``s0`` to the step end ``dt`` (noise scaled to the length)."""
    h = dt - s0
    x = h / tau
    ah = math.exp(-x)
    bh = -math.expm1(-x)
    slope = (d1 - d0) / dt
    out = v0 * ah + (d0 + slope * s0) * bh + slope * (h - tau * bh)
    if sig > 0.0:
        out += sig * math.sqrt(tau / 2.0 * -math.expm1(-2.0 * x)) * xi
    return out


@njit(cache=True, inline="always")
def _interp_cross(v0, v1, r, dt, ref_s, d0, d1, tau, sig, xi):  # type: ignore[no-untyped-def]
    """One neuron's step from ``v0`` (``v1``: the free solution at the step end): refractoriness,
    crossing interpolation and exact restart.

    Returns (v at the step end, refractory time left, fired, crossing offset inside the step).
    """
    s0 = 0.0
    if r > 0.0:
        if r >= dt:
            return 0.0, r - dt, False, 0.0
        s0, r, v0 = r, 0.0, 0.0
        v1 = _segment(0.0, s0, dt, d0, d1, tau, sig, xi)
    if v0 > 1.0:
        ts = s0
    elif v1 > 1.0:
        ts = min(s0 + (1.0 - v0) / (v1 - v0) * (dt - s0), dt)
    else:
        return v1, r, False, 0.0
    sr = ts + ref_s
    if sr < dt:
        return _segment(0.0, sr, dt, d0, d1, tau, sig, xi), r, True, ts
    return 0.0, sr - dt, True, ts


@njit(cache=True)
def _interp_threshold(v, vn, rl, dt, ref_s, d0, d1, tau, sig, xr, k0, i, spk_step, spk_off, spk_idx, n_spk):  # type: ignore[no-untyped-def]
    """:func:`_interp_cross` on one tile (views; ``k0`` its first neuron) at step ``i``, recording
    the spikes; returns the new spike count."""
    for k in range(v.shape[0]):
        v[k], rl[k], fired, ts = _interp_cross(
            v[k], vn[k], rl[k], dt, ref_s, d0[k], d1[k], tau[k], sig[k], xr[k]
        )
        if fired:
            spk_step[n_spk] = i
            spk_off[n_spk] = ts
            spk_idx[n_spk] = k0 + k
            n_spk += 1
    return n_spk


@njit(cache=True)
def _interp_neuron(u_first, u, k, dt, coef, v, rl, ref_s, ring, pos, h_table, noisy, xi, v_out,
                   spk_step, spk_off, spk_idx, n_spk):  # fmt: skip  # type: ignore[no-untyped-def]
    """All steps of neuron ``k`` with its state in registers (neuron-major path for small N);
    ``noisy``: add the normals ``xi[:, k]``."""
    n_t, n_in = u.shape
    n_lags = ring.shape[1]
    want_v = v_out.shape[0] > 0
    col = 0 if n_in == 1 else k
    a, b, e, s, tau, sig, vl, g = (
        coef[0, k], coef[1, k], coef[2, k], coef[3, k], coef[4, k], coef[5, k], coef[6, k], coef[7, k]
    )  # fmt: skip
    vk, r = v[k], rl[k]
    p = pos
    d1 = vl + g * u_first[col]
    for i in range(n_t):
        d0 = d1 if n_lags == 0 else vl + g * (u_first[col] if i == 0 else u[i - 1, col])
        d1 = vl + g * u[i, col]
        if n_lags > 0:
            ih = ring[k, p]
            d0 += ih
            d1 += ih
            ring[k, p] = 0.0
        d0 = min(max(d0, -DRIVE_MAX), DRIVE_MAX)
        d1c = min(max(d1, -DRIVE_MAX), DRIVE_MAX)
        xr = xi[i, k] if noisy else 0.0
        v1 = vk * a + d0 * b + (d1c - d0) * e
        if noisy:
            v1 = v1 + s * xr
        vk, r, fired, ts = _interp_cross(vk, v1, r, dt, ref_s, d0, d1c, tau, sig, xr)
        if fired:
            spk_step[n_spk] = i
            spk_off[n_spk] = ts
            spk_idx[n_spk] = k
            n_spk += 1
            if n_lags > 0:
                ring_add(ring, p, k, h_table, ts / dt)
        if want_v:
            v_out[i, k] = vk
        p = _next_slot(p, n_lags)
    v[k], rl[k] = vk, r
    return n_spk, p


@njit(cache=True, inline="always")
def _interp_by_neuron(
    u_first, u, dt, coef, v, rl, ref_s, ring, pos, h_table, noise_mode, rng, xi_ext, v_out, bufs
):  # type: ignore[no-untyped-def]
    """The neuron-major interpolating run: each neuron runs the whole chunk in registers."""
    n_t, n = u.shape[0], v.shape[0]
    xi, noise_mode = _one_neuron_noise(noise_mode, rng, xi_ext, n_t)
    spk_step, spk_off, spk_idx = bufs
    n_spk, pos_end = 0, pos
    for k in range(n):
        if n_spk + n_t > spk_step.shape[0]:
            spk_step = _grow(spk_step, n_spk + n_t)
            spk_idx = _grow(spk_idx, n_spk + n_t)
            spk_off = _grow(spk_off, n_spk + n_t)
        n_spk, pos_end = _interp_neuron(
            u_first, u, k, dt, coef, v, rl, ref_s, ring, pos, h_table, noise_mode != NOISE_OFF, xi, v_out,
            spk_step, spk_off, spk_idx, n_spk,
        )  # fmt: skip
    return _sorted_spikes(spk_step, spk_off, spk_idx, n_spk, n, n_t), n_spk, pos_end


@njit(cache=True, inline="always")
def _interp_tile_steps(  # noqa: C901 — one hot loop; see the docstring
    u_first, u, ib, ie, k0, k1, dt, coef, v, rl, ref_s, ring, p, h_table, noise_mode, rng, xi_ext, work, xbuf,
    v_out, spk_step, spk_off, spk_idx, n_spk, seg,
):  # fmt: skip  # type: ignore[no-untyped-def]
    """Steps ``ib … ie−1`` of the neurons ``k0 … k1−1`` (ring slot ``p`` at step ``ib``); returns
    the spike buffers (grown if needed), the spike count and the ring slot after the last step.

    One loop with the step written out, as in :func:`_grid_tile_steps`: its branches cannot move to
    helpers without a per-step cost.
    """
    n_in = u.shape[1]
    n_lags = ring.shape[1]
    want_v = v_out.shape[0] > 0
    m = k1 - k0
    vt, rlt = v[k0:k1], rl[k0:k1]
    a, b, e, s = coef[0, k0:k1], coef[1, k0:k1], coef[2, k0:k1], coef[3, k0:k1]
    tau, sig, vl, g = coef[4, k0:k1], coef[5, k0:k1], coef[6, k0:k1], coef[7, k0:k1]
    d0, d1, vn = work[0, k0:k1], work[1, k0:k1], work[2, k0:k1]
    per_fill = _steps_per_fill(m)
    xr = xbuf[:m]
    if noise_mode == NOISE_OFF:  # zeros: the crossing code takes a normal per neuron
        for k in range(m):
            xr[k] = 0.0
    tiled = seg.shape[0] > 0
    for i in range(ib, ie):
        if tiled:
            seg[i - ib] = n_spk
        if n_in == 1:
            ua = u_first[0] if i == 0 else u[i - 1, 0]
            ub = u[i, 0]
            for k in range(m):
                d0[k] = vl[k] + g[k] * ua
                d1[k] = vl[k] + g[k] * ub
        else:
            ura = u_first[k0:k1] if i == 0 else u[i - 1, k0:k1]
            for k in range(m):
                d0[k] = vl[k] + g[k] * ura[k]
                d1[k] = vl[k] + g[k] * u[i, k0 + k]
        if n_lags > 0:
            rr = ring[k0:k1, p]
            for k in range(m):
                d0[k] += rr[k]
                d1[k] += rr[k]
                rr[k] = 0.0
        for k in range(m):
            d0[k] = min(max(d0[k], -DRIVE_MAX), DRIVE_MAX)
            d1[k] = min(max(d1[k], -DRIVE_MAX), DRIVE_MAX)
        if noise_mode == NOISE_OFF:
            for k in range(m):
                vn[k] = vt[k] * a[k] + d0[k] * b[k] + (d1[k] - d0[k]) * e[k]
        else:
            j = (i - ib) % per_fill
            if j == 0:
                _draw_noise(noise_mode, rng, xi_ext, i, min(per_fill, ie - i), k0, m, xbuf)
            xr = xbuf[j * m : j * m + m]
            for k in range(m):
                vn[k] = vt[k] * a[k] + d0[k] * b[k] + (d1[k] - d0[k]) * e[k] + s[k] * xr[k]
        if n_spk + m > spk_step.shape[0]:
            spk_step = _grow(spk_step, n_spk + m)
            spk_idx = _grow(spk_idx, n_spk + m)
            spk_off = _grow(spk_off, n_spk + m)
        special = False  # any crossing or refractory neuron in the tile at this step?
        for k in range(m):
            special |= (vn[k] > 1.0) | (vt[k] > 1.0) | (rlt[k] > 0.0)
        if special:
            n0 = n_spk
            n_spk = _interp_threshold(
                vt, vn, rlt, dt, ref_s, d0, d1, tau, sig, xr, k0, i, spk_step, spk_off, spk_idx, n_spk
            )
            if n_lags > 0 and n_spk > n0:
                _add_history(ring, p, h_table, spk_idx, spk_off, n0, n_spk, dt)
        else:
            for k in range(m):
                vt[k] = vn[k]
        if want_v:
            vo = v_out[i, k0:k1]
            for k in range(m):
                vo[k] = vt[k]
        p = _next_slot(p, n_lags)
    if tiled:
        seg[ie - ib] = n_spk
    return spk_step, spk_off, spk_idx, n_spk, p


@njit(cache=True, inline="always")
def _interp_by_tile(
    u_first, u, dt, coef, v, rl, ref_s, ring, pos, h_table, noise_mode, rng, xi_ext, work, xbuf, v_out, tile, bufs
):  # fmt: skip  # type: ignore[no-untyped-def]
    """The step-major interpolating run over neuron tiles that stay in cache for a block of steps."""
    n_t, n = u.shape[0], v.shape[0]
    spk_step, spk_off, spk_idx = bufs
    n_spk, pos_end = 0, pos
    tile, t_block = _tiling(n, n_t, tile, noise_mode)
    segs = _tile_segments(n, tile, t_block)
    for ib in range(0, n_t, t_block):
        ie = min(ib + t_block, n_t)
        nb0 = n_spk
        for t, k0 in enumerate(range(0, n, tile)):
            spk_step, spk_off, spk_idx, n_spk, pos_end = _interp_tile_steps(
                u_first, u, ib, ie, k0, min(k0 + tile, n), dt, coef, v, rl, ref_s, ring,
                _ring_slot(pos, ib, ring.shape[1]), h_table, noise_mode, rng, xi_ext, work, xbuf, v_out,
                spk_step, spk_off, spk_idx, n_spk, segs[t],
            )  # fmt: skip
        if tile < n:
            _merge_tiles(spk_step, spk_idx, spk_off, nb0, n_spk, segs[:, : ie - ib + 1], ib)
    return (spk_step, spk_off, spk_idx), n_spk, pos_end


@njit(cache=True)
def lif_interp(
    u_first: np.ndarray,  # (M,) input at the start of step 0
    u: np.ndarray,  # (T, M) input at the end of each step
    dt: float,
    coef: np.ndarray,  # (8, N): a, b, e, s, tau, sigma, v_leak, gain
    v: np.ndarray,  # (N,) in/out
    rl: np.ndarray,  # (N,) float refractory time left (s), in/out
    ref_s: float,
    ring: np.ndarray,
    pos: int,
    h_table: np.ndarray,
    noise_mode: int,
    rng: np.ndarray,
    xi_ext: np.ndarray,
    work: np.ndarray,  # (3, N) scratch
    xbuf: np.ndarray,  # scratch for normals, max(NOISE_FILL, N) float64
    v_out: np.ndarray,  # (T, N) membrane at each step's END, or (0, N)
    tile: int,
    spk_step: np.ndarray,  # int64 buffer for the spikes' steps (any length; grown when too short)
    spk_off: np.ndarray,  # float64 buffer for their offsets, as long as spk_step
    spk_idx: np.ndarray,  # int64 buffer for their neurons, as long as spk_step
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, int]:
    """All ``T`` steps of the interpolating integrator.

    Returns (step buffer, buffer of the crossings' offsets inside their steps in s, neuron buffer,
    spike count, ring pos): the first ``count`` entries are the spikes, sorted by step then neuron
    (not by crossing time inside a step).
    """
    bufs = _given_buffers(spk_step, spk_off, spk_idx, True)
    if _neuron_major(v.shape[0], noise_mode):
        spikes, n_spk, pos_end = _interp_by_neuron(
            u_first, u, dt, coef, v, rl, ref_s, ring, pos, h_table, noise_mode, rng, xi_ext, v_out, bufs
        )
    else:
        spikes, n_spk, pos_end = _interp_by_tile(
            u_first, u, dt, coef, v, rl, ref_s, ring, pos, h_table, noise_mode, rng, xi_ext, work, xbuf, v_out, tile,
            bufs,
        )  # fmt: skip
    return spikes[0], spikes[1], spikes[2], n_spk, pos_end


def lif_interp_py(u_first, u, dt, coef, v, rl, ref_s, ring, pos, h_table, noise_mode, rng, xi_ext, v_out):  # type: ignore[no-untyped-def]
    """Plain-numpy twin of :func:`lif_interp`: the same arguments but the scratch and tuning ones
    (``work``, ``tile``, the spike buffers); returns (steps, offsets, neurons, ring pos), the spikes
    the kernel's buffers hold; one step at a time. Each neuron's
    crossing and restart is the kernel's own scalar code (``_interp_cross``) run as Python."""
    n_t = u.shape[0]
    n = v.shape[0]
    n_lags = ring.shape[1]
    a, b, e, s, tau, sig, vl, g = coef
    cross = _interp_cross.py_func
    steps, offs, idx = [], [], []
    for i in range(n_t):
        ua = u_first if i == 0 else u[i - 1]
        d0 = vl + g * ua
        d1 = vl + g * u[i]
        if n_lags > 0:
            d0 = d0 + ring[:, pos]
            d1 = d1 + ring[:, pos]
            ring[:, pos] = 0.0
        d0 = np.clip(d0, -DRIVE_MAX, DRIVE_MAX) * np.ones(n)
        d1 = np.clip(d1, -DRIVE_MAX, DRIVE_MAX) * np.ones(n)
        xr = np.zeros(n)
        if noise_mode == 1:
            _draw_py(rng, xr)
        elif noise_mode == 2:
            xr = xi_ext[i].copy()
        vn = v * a + d0 * b + (d1 - d0) * e
        if noise_mode:
            vn = vn + s * xr
        for k in range(n):
            v[k], rl[k], fired, ts = cross(v[k], vn[k], rl[k], dt, ref_s, d0[k], d1[k], tau[k], sig[k], xr[k])
            if fired:
                steps.append(i)
                offs.append(ts)
                idx.append(k)
                if n_lags > 0:
                    _ring_add_py(ring, pos, k, h_table, ts / dt)
        if v_out.shape[0]:
            v_out[i] = v
        if n_lags > 0:
            pos = (pos + 1) % n_lags
    return np.array(steps, np.int64), np.array(offs, np.float64), np.array(idx, np.int64), pos
