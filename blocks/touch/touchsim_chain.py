"""``touchsim_chain``: TouchSim's whole per-afferent model (prefilter, rectified gains, noise,
saturation, membrane) in one block — the chain ``iir → iir → rectified_gain → nlif`` of
graphs/touchsim_afferents.yaml, fused for speed.

Why: the chain of generic blocks writes and reads a (samples × afferents) float64 array per stage
and tick, fresh each time (chunks are sealed and shared, so no stage may reuse its output); for the
whole hand (8 450 afferents a shard, 25-sample ticks) that is 1.7 MB a stage a tick: memory traffic,
and page faults the OS zero-fills. Here each tile of :data:`TILE` afferents keeps its whole state
(filters, gains, membranes) in one contiguous workspace the block owns, and every sample of the
tick passes through it while it is in cache (nothing leaves the block but the spikes); s is filtered
only where a model weighs it (TouchSim filters s for SA1 only; RA and PC have p1 = p2 = 0).

The arithmetic is the generic blocks', term for term and in the same order (:func:`chain_tiles`
against ``iir.sos_apply``, ``rectified_gain.fused_current`` and ``lif_units``' last-spike update,
on nlif's own coefficients: :meth:`Nlif.unit_arrays`), so spikes and current are bit-identical to
the chain bound with the same seeds (tests/blocks/touch/test_touchsim_chain.py).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

import flowtact.api as ft
from flowtact.blocks.signal.iir import design_sos
from flowtact.blocks.signal.rectified_gain import NOISE_GROUP
from flowtact.blocks.spiking._bitops import prefetch, select, trailing_zeros
from flowtact.blocks.spiking._lif_kernels import DRIVE_MAX
from flowtact.blocks.spiking.nlif import Nlif
from flowtact.blocks.spiking.normal_draws import fill_normal, seed_state, shard_noise_offset
from flowtact.blocks.touch.touchsim import touchsim_models

__all__ = [
    "FIELDS",
    "TILE",
    "TouchsimChain",
    "TouchsimChainConfig",
    "by_row",
    "chain_tiles",
    "draw_rows",
    "tiled",
]


def _readonly(a: np.ndarray) -> np.ndarray:
    """A read-only view: the kernel sees one array type whether an input came sealed (read-only)
    from another node or fresh from the aligner, so it compiles once (in the warm-up)."""
    v = a.view()
    v.flags.writeable = False
    return v


#: Afferents per cache tile (64: the one-pass row returns its spikes as the bits of one uint64): a tile's filter, gain and membrane state (:data:`FIELDS` doubles an
#: afferent, ~21 KB) stays in L1 while every sample of the chunk passes through it (256 afferents,
#: ~86 KB, spilled to L2 once the loops vectorised: 10-15 % slower per afferent-sample).
TILE = 64
#: Rows ahead whose lanes a tile's row prefetches (s, d and noise rows are a row of the population apart).
AHEAD = 4
#: Second-order sections of TouchSim's prefilter (a 3rd-order Butterworth: 2).
NSEC = 2
#: Post-spike basis columns a TouchSim membrane weighs (nlif's ``w`` rows; 2: p10 and p11).
NB = 2

# A tile's workspace: fields of TILE doubles at these offsets (× TILE) in one flat array. The
# offsets are compile-time constants and the loops run over the whole tile, so LLVM proves the
# fields never overlap and vectorises without runtime alias checks (4x faster than separate arrays).
_XS, _XD, _HS, _HD, _Y = 0, 1, 2, 3, 4  # filter s, filter d (then Δd's next sample), held s, d, current
_SOS = 5  # b0, b1, b2, a1, a2 per section
_ZS = _SOS + 5 * NSEC  # z0, z1 per section: prefilter of s
_ZD = _ZS + 2 * NSEC  # the same for d
_G = _ZD + 2 * NSEC  # p1 … p6
_SD = _G + 6
_SAT = _SD + 1
_C0, _C1, _C3, _C4 = _SAT + 1, _SAT + 2, _SAT + 3, _SAT + 4  # nlif's coef rows a, b, v_leak, gain
_THR = _SAT + 5
_W = _THR + 1  # NB basis weights
_V = _W + NB
_H = _V + 1  # the membranes' history term of the row (looked up before their vector pass)
_XI = _H + 1  # the row's noise (the one-pass row)
#: Doubles per afferent in a tile's workspace.
FIELDS = _XI + 1


@njit(cache=True)
def draw_rows(rng, xi, rows, nc):  # type: ignore[no-untyped-def]
    """The noise of ``rows`` samples of ``nc`` afferents into flat ``xi`` (row-major): per sample, each group of
    :data:`NOISE_GROUP` channels from its stream ``rng[g]`` (``rectified_gain``'s draw order)."""
    if rng.shape[0] == 1:  # one stream: the rows in one request (the same values, fewer calls)
        fill_normal(rng[0], xi[: rows * nc])
        return
    for r in range(rows):
        for q in range(rng.shape[0]):
            fill_normal(rng[q], xi[r * nc + q * NOISE_GROUP : r * nc + min(nc, (q + 1) * NOISE_GROUP)])


@njit(cache=True, inline="always")
def _sections(ws, xf, zf):  # type: ignore[no-untyped-def]
    """Field ``xf`` through the sections (state fields from ``zf``), in place: ``iir.sos_apply``'s
    update in its order."""
    x0 = xf * TILE
    for q in range(NSEC):
        o = (_SOS + 5 * q) * TILE
        z = (zf + 2 * q) * TILE
        for k in range(TILE):
            x = ws[x0 + k]
            out = ws[o + k] * x + ws[z + k]
            ws[z + k] = ws[o + TILE + k] * x - ws[o + 3 * TILE + k] * out + ws[z + TILE + k]
            ws[z + TILE + k] = ws[o + 2 * TILE + k] * x - ws[o + 4 * TILE + k] * out
            ws[x0 + k] = out


@njit(cache=True, inline="always")
def _current(ws, noisy, xi, xo):  # type: ignore[no-untyped-def]
    """The held row's current into field _Y (``rectified_gain.fused_current`` term for term)."""
    for k in range(TILE):
        acc = 0.0
        x = ws[_HS * TILE + k]
        acc += ws[_G * TILE + k] * max(x, 0.0) - ws[(_G + 1) * TILE + k] * min(x, 0.0)
        x = ws[_HD * TILE + k]
        acc += ws[(_G + 2) * TILE + k] * max(x, 0.0) - ws[(_G + 3) * TILE + k] * min(x, 0.0)
        x = ws[_XD * TILE + k] - ws[_HD * TILE + k]
        acc += ws[(_G + 4) * TILE + k] * max(x, 0.0) - ws[(_G + 5) * TILE + k] * min(x, 0.0)
        if noisy:
            acc = acc + ws[_SD * TILE + k] * xi[xo + k]
        p = ws[_SAT * TILE + k]
        sa = p * acc / (p + abs(acc))
        sa = select(sa != sa, 0.0, sa)
        ws[_Y * TILE + k] = select(p > 0.0, sa, acc)


@njit(cache=True, inline="always")
def _history(ws, lag, basis):  # type: ignore[no-untyped-def]
    """The membranes' history term of each lane into field _H, in its own loop: its loads are
    indexed by the lags, so LLVM cannot prove a loop that also stores anything free of aliasing and
    leaves it scalar. Here that loop is only the lookups (~0.5-0.9 ns an afferent); the update, with no indexed
    load, vectorises (1.97 → 0.85 ns per afferent for lookup and update)."""
    for k in range(TILE):
        lk = lag[k]
        h = 0.0
        for j in range(NB):
            h += ws[(_W + j) * TILE + k] * basis[j, lk]
        ws[_H * TILE + k] = h


@njit(cache=True, inline="always")
def _membranes(ws, lag, basis, n_block, fired):  # type: ignore[no-untyped-def]
    """``lif_units``' last-spike update of the tile's membranes driven by field _Y; flags in ``fired``."""
    _history(ws, lag, basis)
    cap = basis.shape[1] - 1
    n_fired = 0
    for k in range(TILE):
        lk = lag[k]
        drv = ws[_C3 * TILE + k] + ws[_C4 * TILE + k] * ws[_Y * TILE + k] + ws[_H * TILE + k]
        dd = min(max(drv, -DRIVE_MAX), DRIVE_MAX)
        vn = ws[_V * TILE + k] * ws[_C0 * TILE + k] + dd * ws[_C1 * TILE + k]
        spike = (vn > ws[_THR * TILE + k]) & (lk > n_block)
        ws[_V * TILE + k] = select(spike, 0.0, vn)
        lag[k] = select(spike, 1, min(lk + 1, cap))
        fired[k] = spike
        n_fired += spike
    return n_fired


@njit(cache=True, inline="always")
def _biquad(ws, o, z, k, x):  # type: ignore[no-untyped-def]
    """Lane ``k``'s sample ``x`` through the section with coefficients at ``o`` and state at ``z``
    (``iir.sos_apply``'s update in its order); returns its output."""
    out = ws[o + k] * x + ws[z + k]
    ws[z + k] = ws[o + TILE + k] * x - ws[o + 3 * TILE + k] * out + ws[z + TILE + k]
    ws[z + TILE + k] = ws[o + 2 * TILE + k] * x - ws[o + 4 * TILE + k] * out
    return out


@njit(cache=True, inline="always")
def _one_pass(ws, lag, n_block, cap, filt_s, noisy):  # type: ignore[no-untyped-def]
    """A full tile's common row in one pass over the lanes: the input row (fields _XS, _XD, its
    noise _XI) through the prefilters, the held row's current and its membranes (history in _H),
    then the new row held — per lane the same operations, in the same order, as :func:`_sections`,
    :func:`_current` and :func:`_membranes`, with the intermediates in registers. Returns (spikes,
    non-finite currents), the spikes as a mask, bit k for lane k (a tile is 64 lanes). The terms are
    written out here, not taken from per-lane helpers shared with those two: inlined helpers left
    LLVM unable to vectorise this loop (2.5x slower, `scripts/touchsim_chain_ab.py`)."""
    mask = np.uint64(0)
    bad = 0
    for k in range(TILE):
        xs = 0.0
        if filt_s:
            xs = ws[_XS * TILE + k]
            for q in range(NSEC):
                xs = _biquad(ws, (_SOS + 5 * q) * TILE, (_ZS + 2 * q) * TILE, k, xs)
        xd = ws[_XD * TILE + k]
        for q in range(NSEC):
            xd = _biquad(ws, (_SOS + 5 * q) * TILE, (_ZD + 2 * q) * TILE, k, xd)
        hd = ws[_HD * TILE + k]
        acc = 0.0
        x = ws[_HS * TILE + k]
        acc += ws[_G * TILE + k] * max(x, 0.0) - ws[(_G + 1) * TILE + k] * min(x, 0.0)
        acc += ws[(_G + 2) * TILE + k] * max(hd, 0.0) - ws[(_G + 3) * TILE + k] * min(hd, 0.0)
        x = xd - hd
        acc += ws[(_G + 4) * TILE + k] * max(x, 0.0) - ws[(_G + 5) * TILE + k] * min(x, 0.0)
        if noisy:
            acc = acc + ws[_SD * TILE + k] * ws[_XI * TILE + k]
        p = ws[_SAT * TILE + k]
        sa = p * acc / (p + abs(acc))
        sa = select(sa != sa, 0.0, sa)
        y = select(p > 0.0, sa, acc)
        ws[_Y * TILE + k] = y
        lk = lag[k]
        drv = ws[_C3 * TILE + k] + ws[_C4 * TILE + k] * y + ws[_H * TILE + k]
        dd = min(max(drv, -DRIVE_MAX), DRIVE_MAX)
        vn = ws[_V * TILE + k] * ws[_C0 * TILE + k] + dd * ws[_C1 * TILE + k]
        spike = (vn > ws[_THR * TILE + k]) & (lk > n_block)
        ws[_V * TILE + k] = select(spike, 0.0, vn)
        lag[k] = select(spike, 1, min(lk + 1, cap))
        mask |= np.uint64(spike) << np.uint64(k)
        bad += not (abs(y) < math.inf)
        if filt_s:
            ws[_HS * TILE + k] = xs
        ws[_HD * TILE + k] = xd
    return mask, bad


@njit(cache=True, error_model="numpy")  # x/0 is inf or NaN (never selected), not a raise: loops vectorise
def chain_tiles(  # noqa: C901 — one hot loop nest; see the module doc
    s, d, s_tile, work, lag, basis, n_block, has_held, last, noisy, xi, cur, spk_row, spk_unit
):  # type: ignore[no-untyped-def]
    """The rows of ``s``, ``d`` (C afferents) through the whole model, a tile of :data:`TILE`
    afferents at a time; ``work`` (tiles, FIELDS·TILE) holds each tile's workspace (see the offsets
    above), ``lag`` (tiles, TILE) its lags since the last spike.

    Per input row: the prefilters (s only in tiles where ``s_tile`` is set: the others' s gains are
    0), then, once the next row has come, the held row's current (``rectified_gain``'s
    ``fused_current`` term for term: Δd = d[n+1] − d[n], noise ``sd·xi`` of its output row, then
    saturation) and its membranes (``lif_units``' last-spike update: no summed history, no membrane
    noise or clamp). With ``last``, the held row's own current after them (Δd = 0). ``xi`` (flat,
    rows × C then a tile of zeros): the noise. ``cur`` (rows × C, or no rows): the current, if wanted.
    Spikes go to ``spk_row``/``spk_unit`` tile by tile (sort them by row, stably, for step-then-unit
    order). Returns (output rows, whether a row is held, spikes, current values not finite)."""
    n, nc = s.shape[0], s.shape[1]
    total = n + (1 if last and (has_held or n > 0) else 0)
    want_cur = cur.shape[0] > 0
    fired = np.zeros(TILE, np.uint8)
    xi2 = xi[: (xi.shape[0] // nc) * nc].reshape(-1, nc) if nc else xi[:0].reshape(0, 1)
    n_spk = 0
    bad = 0
    row = 0
    hh = has_held
    for tt in range(work.shape[0]):
        t0 = tt * TILE
        m = min(nc, t0 + TILE) - t0
        filt_s = s_tile[tt]
        ws = work[tt]
        lg = lag[tt]
        hh = has_held
        row = 0
        for i in range(total):
            if m == TILE and hh and i < n:  # the common row: one pass over the lanes
                if i + AHEAD < n:  # this tile's lanes AHEAD rows on: a page or more away
                    for q in range(0, TILE, 8):
                        if filt_s:
                            prefetch(s, i + AHEAD, t0 + q)
                        prefetch(d, i + AHEAD, t0 + q)
                        if noisy:
                            prefetch(xi2, row + AHEAD, t0 + q)
                if filt_s:
                    for k in range(TILE):
                        ws[_XS * TILE + k] = s[i, t0 + k]
                for k in range(TILE):
                    ws[_XD * TILE + k] = d[i, t0 + k]
                if noisy:
                    xo = row * nc + t0
                    for k in range(TILE):
                        ws[_XI * TILE + k] = xi[xo + k]
                _history(ws, lg, basis)
                cap = basis.shape[1] - 1
                if filt_s:
                    if noisy:
                        mask, b = _one_pass(ws, lg, n_block, cap, True, True)
                    else:
                        mask, b = _one_pass(ws, lg, n_block, cap, True, False)
                elif noisy:
                    mask, b = _one_pass(ws, lg, n_block, cap, False, True)
                else:
                    mask, b = _one_pass(ws, lg, n_block, cap, False, False)
                bad += b
                if want_cur:
                    for k in range(TILE):
                        cur[row, t0 + k] = ws[_Y * TILE + k]
                while mask:  # the spiking lanes, in order
                    spk_row[n_spk] = row
                    spk_unit[n_spk] = t0 + np.intp(trailing_zeros(mask))
                    n_spk += 1
                    mask &= mask - np.uint64(1)
                row += 1
                continue
            if i < n:
                if filt_s:
                    for k in range(m):
                        ws[_XS * TILE + k] = s[i, t0 + k]
                    _sections(ws, _XS, _ZS)
                for k in range(m):
                    ws[_XD * TILE + k] = d[i, t0 + k]
                _sections(ws, _XD, _ZD)
            else:
                for k in range(TILE):
                    ws[_XD * TILE + k] = ws[_HD * TILE + k]
            if hh:
                _current(ws, noisy, xi, row * nc + t0)
                n_fired = _membranes(ws, lg, basis, n_block, fired)
                for k in range(m):
                    if not math.isfinite(ws[_Y * TILE + k]):
                        bad += 1
                if want_cur:
                    for k in range(m):
                        cur[row, t0 + k] = ws[_Y * TILE + k]
                k = 0
                while n_fired > 0:
                    if fired[k]:
                        spk_row[n_spk] = row
                        spk_unit[n_spk] = t0 + k
                        n_spk += 1
                        n_fired -= 1
                    k += 1
                row += 1
            if i < n:
                if filt_s:
                    for k in range(TILE):
                        ws[_HS * TILE + k] = ws[_XS * TILE + k]
                for k in range(TILE):
                    ws[_HD * TILE + k] = ws[_XD * TILE + k]
                hh = True
            else:
                hh = False
    return row, hh, n_spk, bad


@njit(cache=True)
def by_row(spk_row, spk_unit, n_spk, rows, out_row, out_unit):  # type: ignore[no-untyped-def]
    """The first ``n_spk`` spikes (found tile by tile) into ``out_row``/``out_unit`` in step-then-unit
    order: a stable counting sort on the row (rows are few; a few times faster than ``argsort``).
    Returns ``n_spk`` (a function returning nothing or new arrays costs ~8 µs more a call)."""
    start = np.zeros(rows + 1, np.int64)
    for j in range(n_spk):
        start[spk_row[j] + 1] += 1
    for r in range(rows):
        start[r + 1] += start[r]
    for j in range(n_spk):
        r = spk_row[j]
        q = start[r]
        out_row[q] = r
        out_unit[q] = spk_unit[j]
        start[r] = q + 1
    return n_spk


def aligned_zeros(shape: int | tuple[int, ...], dtype: Any = np.float64) -> np.ndarray:
    """Zeros whose first element starts a 64-byte cache line (numpy promises 16 bytes): a tile's
    fields are 512 bytes, so every 512-bit load of them then stays within one line; a 16-byte
    offset splits each and cost 10-15 % of the kernel (it moved from process to process)."""
    dt = np.dtype(dtype)
    size = int(np.prod(shape)) * dt.itemsize
    raw = np.zeros(size + 64, np.uint8)
    off = -raw.ctypes.data % 64
    return raw[off : off + size].view(dt).reshape(shape)


def tiled(a: np.ndarray, tile: int = TILE) -> np.ndarray:
    """``a`` (…, N) as (tiles, …, tile), C-contiguous, zero past N: a tile's rows contiguous."""
    a = np.asarray(a)
    n = a.shape[-1]
    k = -(-n // tile)
    pad = np.zeros((*a.shape[:-1], k * tile), a.dtype)
    pad[..., :n] = a
    return np.ascontiguousarray(np.moveaxis(pad.reshape(*a.shape[:-1], k, tile), -2, 0))


@dataclass(frozen=True)
class TouchsimChainConfig(ft.BadDataConfig):
    """Parameters of :class:`TouchsimChain`."""

    models: tuple[str, ...] = ft.param(
        ("SA1.0",), doc="TouchSim model per afferent (column), SA1.0-3, RA.0-8, PC.0-3", min_len=1
    )
    noise_scale: float = ft.param(1.0, doc="multiplies each model's noise s.d. p8 (0: noise off)", ge=0)
    noise_offset: int = ft.param(
        0,
        doc="a shard's first afferent in the whole population (set by shards: K): its noise streams are "
        "the whole population's from there on; a multiple of 4096 (one noise stream's afferents)",
        ge=0,
    )

    def check(self) -> None:
        known = touchsim_models()
        for m in self.models:
            if m not in known:
                raise self.error("models", f"unknown TouchSim model {m!r} (known: {', '.join(known)})")
        if self.noise_offset % NOISE_GROUP:
            raise self.error("noise_offset", f"must be a multiple of {NOISE_GROUP}; got {self.noise_offset}")


class TouchsimChain(ft.Block):
    """TouchSim's per-afferent model from s and d to spikes in one block (one model per column).

    Config
    ------
    See :class:`TouchsimChainConfig`.

    Notes
    -----
    The same computation as graphs/touchsim_afferents.yaml's chain, bit for bit (the same seed:
    the same noise): ``iir`` (butter, order 3, 10·p0 Hz) on s and d, ``rectified_gain`` (p1–p6,
    Δd one sample ahead, noise p8·ξ before saturation p7; noise from one stream per 4 096 afferents
    in (sample, afferent) order), ``nlif`` with ``models:`` (TouchSim's membrane, last-spike history,
    threshold block). Spikes are stamped with their input sample's time (TouchSim's (n + 1)/fs is one
    sample later). It holds back one sample, as rectified_gain does (Δd needs the next one), and
    emits it at the end with Δd = 0. s is filtered only for afferents whose model weighs it (SA1):
    the others' s terms are 0 in the chain too. Inputs are paired by arrival (equal stamps);
    ``current`` (optional) is the input current of the membranes. A current that overflows float64
    (inputs far off) is counted (``overflow``) and integrated as it is, where the chain's nlif would
    apply its ``on_bad_data``: the one place the two may differ.

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.touch.touchsim_chain import TouchsimChain
    >>> from flowtact.testing import run_offline
    >>> t = np.arange(4000) / 5000.0
    >>> s = np.tile(0.0128 * np.clip(t / 0.05, 0, 1)[:, None], (1, 2))
    >>> d = np.tile((4.0 * (t < 0.05))[:, None], (1, 2))
    >>> out = run_offline(TouchsimChain(models=["SA1.0", "RA.3"], noise_scale=0.0), s=s, d=d, rate_hz=5000.0)
    >>> np.bincount(out["spikes"].data, minlength=2).tolist()     # spikes per afferent
    [10, 14]
    """

    config_cls = TouchsimChainConfig
    shardable = True
    per_unit_params = ("models",)
    inputs = {
        "s": ft.Port(dtype="float64", ndim=(1,), require_rate=True, doc="static term per afferent"),
        "d": ft.Port(dtype="float64", ndim=(1,), require_rate=True, doc="dynamic term per afferent"),
    }
    outputs = {
        "spikes": ft.Port(dtype="int64", events=True, doc="spike events, data = afferent index"),
        "current": ft.Port(dtype="float64", optional=True, doc="the membranes' input current"),
    }
    counter_docs = {
        "nonfinite_drop": "instants where s or d had NaN/inf, removed from both (on_bad_data: drop)",
        "nonfinite_hold": "samples (per input) with NaN/inf, held at the last finite value (on_bad_data: hold)",
        "overflow": "current values that overflowed float64 (inputs far off)",
        "unpaired_at_end": "input samples with no partner on the other input when the stream ended",
    }

    @classmethod
    def shard_units(cls, config: TouchsimChainConfig) -> int | None:
        """One unit per model."""
        return len(config.models) if len(config.models) > 1 else None

    @classmethod
    def shard_align(cls, config: TouchsimChainConfig) -> int:
        """Noisy: cut at the noise streams' boundaries (4 096 afferents each)."""
        return NOISE_GROUP if config.noise_scale > 0 else 1

    @classmethod
    def shard_params(cls, params: dict[str, Any], lo: int, hi: int, n: int) -> dict[str, Any]:
        out = super().shard_params(params, lo, hi, n)
        return shard_noise_offset(out, params, lo, NOISE_GROUP)

    def specs(self, inputs: Mapping[str, ft.StreamSpec]) -> dict[str, ft.StreamSpec]:
        s = inputs["s"]
        n = len(self.config.models)
        for p in ("s", "d"):
            spec = inputs[p]
            if spec.shape != (n,):
                raise ft.SpecError(p, f"input '{p}' has shape {spec.shape} but models lists {n} afferents")
            if not math.isclose(spec.rate_hz or 0.0, s.rate_hz or 0.0, rel_tol=1e-9):
                raise ft.SpecError(p, f"input '{p}' is {spec.rate_hz:g} Hz but s is {s.rate_hz:g} Hz")
        for m in self.config.models:
            if 10.0 * touchsim_models()[m][0] >= 0.5 * float(s.rate_hz or 0.0):
                raise ft.SpecError("s", f"model {m}'s prefilter cut-off must be below half the rate")
        return {
            "spikes": ft.StreamSpec(dtype="int64", shape=(), units="1", events=True, n_units=n),
            "current": ft.StreamSpec(dtype="float64", shape=(n,), units="1", rate_hz=s.rate_hz),
        }

    def reset(self) -> None:
        cfg = self.config
        spec = self.input_specs["s"]
        n = self._n = len(cfg.models)
        rate = float(spec.rate_hz or 0.0)
        self._dt = 1.0 / rate
        p = np.array([touchsim_models()[m] for m in cfg.models], np.float64)
        nyq = 0.5 * rate
        designs = {f: design_sos("butter", 3, "lowpass", f / nyq) for f in set((10.0 * p[:, 0]).tolist())}
        sos = np.stack(
            [designs[f] for f in (10.0 * p[:, 0]).tolist()], -1
        )  # one design per model, not per afferent
        weighs_s = (p[:, 1] != 0) | (p[:, 2] != 0)  # TouchSim: SA1 (RA and PC have p1 = p2 = 0)
        self._s_tile = np.array([weighs_s[i : i + TILE].any() for i in range(0, n, TILE)], np.bool_)
        sd = cfg.noise_scale * p[:, 8]
        self._noisy = bool(sd.any())
        self._rng = np.zeros((0, 1), np.uint64)
        if self._noisy:
            for _ in range(cfg.noise_offset // NOISE_GROUP):  # the streams of afferents before the shard
                seed_state(self.rng)
            self._rng = np.stack([seed_state(self.rng) for _ in range(-(-n // NOISE_GROUP))])
        self._neurons = Nlif(models=list(cfg.models))
        self._neurons.bind(
            {"x": ft.StreamSpec(dtype="float64", shape=(n,), rate_hz=rate)},
            seed=self.seed,
            demanded=frozenset({"spikes"}),
        )
        u = self._neurons.unit_arrays()  # its membranes, run here on the tiles' copies
        if sos.shape[0] != NSEC or u.w.shape[0] > NB or u.summed or u.noisy or u.n_clamp:
            raise ValueError(
                "touchsim_chain: TouchSim's model is 2 sections, 2 basis columns, last-spike history"
            )
        fields = np.zeros((FIELDS, n))
        fields[_SOS : _SOS + 5 * NSEC] = sos[:, [0, 1, 2, 4, 5]].reshape(5 * NSEC, n)
        fields[_G : _G + 6] = p[:, 1:7].T
        fields[_SD], fields[_SAT] = sd, p[:, 7]
        fields[[_C0, _C1, _C3, _C4]] = u.coef[[0, 1, 3, 4], :n]
        fields[_THR] = u.thr
        fields[_W : _W + u.w.shape[0]] = u.w
        fields[_V] = u.v
        self._work = aligned_zeros((len(self._s_tile), FIELDS * TILE))
        self._work[:] = tiled(fields).reshape(self._work.shape)
        self._lag = aligned_zeros((len(self._s_tile), TILE), np.int64)
        self._lag[:] = tiled(u.lag)
        self._basis = np.zeros((NB, u.basis.shape[1]))
        self._basis[: u.basis.shape[0]] = u.basis
        self._n_block = u.n_block
        self._xi = aligned_zeros(TILE)
        self._has_held = False
        self._held_t = np.empty(0)
        self._no_cur = np.empty((0, n))
        self._spk = (np.empty(0, np.int64), np.empty(0, np.int64))
        self._align = ft.Aligner(self.node, self.input_specs, ["s", "d"], tol_s=1e-6 / rate)
        self._last: dict[str, np.ndarray | None] = {"s": None, "d": None}
        self._end: float | None = None
        self._want_current = "current" in self.demanded

    def _run(self, t: np.ndarray, s: np.ndarray, d: np.ndarray, last: bool) -> dict[str, ft.Chunk]:
        """The rows of s, d (and with ``last`` the held sample) through the whole model."""
        m, n = len(t), self._n
        had = self._has_held
        total = m + (1 if last and (had or m > 0) else 0)
        rows = total - (0 if had else 1) if total else 0
        if self._xi.shape[0] < rows * n + TILE:  # the block's own scratch: reused, never handed out
            self._xi = aligned_zeros(rows * n + TILE)  # a tile past the rows: the last tile's lanes read it
        if self._noisy:
            draw_rows(self._rng, self._xi, rows, n)
        if self._spk[0].shape[0] < rows * n:
            self._spk = (np.empty(rows * n, np.int64), np.empty(rows * n, np.int64))
        cur = np.empty((rows, n)) if self._want_current else self._no_cur
        _, self._has_held, n_spk, bad = chain_tiles(
            s, d, self._s_tile, self._work, self._lag, self._basis, self._n_block, had, last, self._noisy,
            self._xi, cur, *self._spk,
        )  # fmt: skip
        self.count("overflow", bad)
        t_out = np.concatenate([self._held_t, t])[:rows] if had else t[:rows]
        if m:
            self._held_t = t[-1:].copy()
        out: dict[str, ft.Chunk] = {}
        if not rows:
            out["spikes"] = ft.Chunk.empty(dtype="int64", end=self._end)
            if self._want_current:
                out["current"] = ft.Chunk.empty(shape=(n,))
            return out
        steps, idx = np.empty(n_spk, np.int64), np.empty(n_spk, np.int64)
        by_row(*self._spk, n_spk, rows, steps, idx)  # tile by tile → step, then afferent
        self._end = t_out[-1].item() + self._dt
        out["spikes"] = ft.Chunk(t_out[steps], idx, self._end)
        if self._want_current:
            out["current"] = ft.Chunk(t_out, cur)
        return out

    def step(self, s: ft.Chunk, d: ft.Chunk) -> dict[str, ft.Chunk]:
        t, data = self._align.push({"s": s, "d": d})
        if len(t):
            t, data = ft.screen_aligned(self, self.config.on_bad_data, t, data, self._last)
        m = len(t)
        sd = [_readonly(np.ascontiguousarray(data[p].reshape(m, self._n), np.float64)) for p in ("s", "d")]
        return self._run(t, sd[0], sd[1], False)

    def flush(self) -> dict[str, ft.Chunk]:
        self.count("unpaired_at_end", sum(self._align.pending().values()))
        if not self._has_held:
            return {}
        none = _readonly(np.empty((0, self._n)))
        return self._run(np.empty(0), none, none, True)

    @classmethod
    def example(cls) -> ft.Example:
        t = np.arange(2500) / 5000.0
        ramp = np.clip((t - 0.05) / 0.05, 0.0, 1.0)[:, None]
        s = ramp * np.array([0.0128, 0.0029, 0.0019])
        d = np.gradient(ramp, axis=0)[:, :1] * 5000.0 * 0.05 * np.array([4.0, 0.14, 0.09])
        return ft.Example(
            params={"models": ["SA1.0", "RA.3", "PC.1"]},
            inputs={"s": s, "d": d},
            rate_hz=5000.0,
            units={"s": "1", "d": "1"},
        )
