"""Exact standard normals for the NLIF kernels: 32 xoshiro256++ lanes (SIMD) feeding a ziggurat.

Why: one scalar xoshiro256++ stream is a serial dependency chain (~2–3 ns per normal); 32 independent
lanes advance together in vector registers. Each 64-bit word feeds the 256-layer ziggurat of
Marsaglia & Tsang (2000) (NumPy's layout): bits 0–7 pick the layer, bit 8 the sign, bits 12–63 a
52-bit uniform ``u``; ``x = u·x_i`` is accepted when ``u < x_{i+1}/x_i`` (~98.8 %). Rejected words
finish the exact algorithm on a separate scalar xoshiro256++ stream (the wedge test, Marsaglia's
exponential tail beyond r = 3.654 for the base strip, or a fresh draw), so the distribution is the
exact normal, tails included — no truncated table.

The stream is one flat sequence per state: :func:`fill_normal` continues it whatever the request
sizes, so T calls of N values equal one call of T·N — the kernels' chunking invariance rests on this.
Values are made in whole rounds of :data:`QUANTUM` = ROUNDS·LANES words (word ``j`` of a round from
lane ``j % LANES``), straight into the caller's array (at most :data:`BATCH` per pass); only the last,
partial round of a request goes through a buffer in the state, whose unused rest the next request
takes first. The words, and so the values, do not depend on how a request is cut into rounds.

State (uint64, :data:`STATE_WORDS`): ``[4·LANES lane words | 4 fix-up words | cursor | QUANTUM
buffered values (float64 bits) | BATCH + BATCH/64 scratch words]``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from numba import njit

from flowtact.blocks.spiking._bitops import bits_to_f64, trailing_zeros

__all__ = [
    "BATCH",
    "LANES",
    "QUANTUM",
    "STATE_WORDS",
    "fill_normal",
    "fill_normal_py",
    "seed_state",
    "shard_noise_offset",
    "stream_words",
]

LANES = 32
#: Words per lane made per load of its state.
ROUNDS = 4
#: Values made per round of the lanes: the unit of a request (the rest of a round is buffered).
QUANTUM = ROUNDS * LANES
#: Most values made per pass (the size of the scratch; a multiple of QUANTUM).
BATCH = 512
_FIX = 4 * LANES
_CUR = _FIX + 4
_BUF = _CUR + 1
_RAW = _BUF + QUANTUM
_REJ = _RAW + BATCH
_GROUPS = BATCH // 64
STATE_WORDS = _REJ + _GROUPS

_M64 = (1 << 64) - 1
_ZIG_R = 3.6541528853610088
_ZIG_INV_R = 1.0 / _ZIG_R
_ZIG_V = 0.00492867323399
_ONE_BITS = 0x3FF0000000000000


def _numpy_layout_tables() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``x_i`` (layer scales), ``k_i/2^52`` (acceptance bounds) and ``f_i`` in NumPy's index order."""
    m1 = float(2**52)
    k = np.zeros(256)
    w = np.zeros(256)
    f = np.zeros(256)
    dn = tn = _ZIG_R
    q = _ZIG_V / math.exp(-0.5 * dn * dn)
    k[0] = math.floor((dn / q) * m1)
    k[1] = 0.0
    w[0] = q
    w[255] = dn
    f[0] = 1.0
    f[255] = math.exp(-0.5 * dn * dn)
    for i in range(254, 0, -1):
        dn = math.sqrt(-2.0 * math.log(_ZIG_V / dn + math.exp(-0.5 * dn * dn)))
        k[i + 1] = math.floor((dn / tn) * m1)
        tn = dn
        f[i] = math.exp(-0.5 * dn * dn)
        w[i] = dn
    return w, k / m1, f


ZIG_X, ZIG_ACCEPT, ZIG_F = _numpy_layout_tables()


def shard_noise_offset(out: dict[str, Any], params: Mapping[str, Any], lo: int, group: int) -> dict[str, Any]:
    """A shard's parameters ``out`` given its ``noise_offset`` (the units before unit ``lo``), so it
    draws what those units draw in the unsharded population: set when the offset falls on a noise
    stream's boundary (``group`` units each), always so with noise, which shards are aligned to;
    without noise it changes nothing."""
    offset = int(params.get("noise_offset", 0)) + lo
    if offset % group == 0:
        out["noise_offset"] = offset
    return out


def seed_state(rng: np.random.Generator) -> np.ndarray:
    """A fresh generator state drawn from ``rng``: 32 + 1 xoshiro256++ states, none all zero."""
    s = np.zeros(STATE_WORDS, np.uint64)
    words = rng.integers(0, 2**64, size=4 * LANES + 4, dtype=np.uint64, endpoint=False)
    lanes = words[: 4 * LANES].reshape(4, LANES)
    lanes[0, ~lanes.any(axis=0)] = np.uint64(0x9E3779B97F4A7C15)
    fix = words[4 * LANES :]
    if not fix.any():
        fix[0] = np.uint64(0x9E3779B97F4A7C15)
    s[: 4 * LANES] = lanes.ravel()
    s[_FIX:_CUR] = fix
    s[_CUR] = QUANTUM  # the buffer is empty
    return s


def stream_words(state: np.ndarray) -> np.ndarray:
    """The words of a state that decide the rest of its stream: the lanes, the fix-up stream, the
    cursor and the buffered values not yet handed out (consumed ones and scratch are left out)."""
    cur = int(state[_CUR])
    return np.concatenate([state[:_BUF], state[_BUF + cur : _BUF + QUANTUM]])


@njit(cache=True, inline="always")
def _rotl(x, k):  # type: ignore[no-untyped-def]
    return (x << np.uint64(k)) | (x >> np.uint64(64 - k))


@njit(cache=True, inline="always")
def _xoshiro(a0, a1, a2, a3):  # type: ignore[no-untyped-def]
    """One xoshiro256++ step: (output, new state words)."""
    r = _rotl(a0 + a3, 23) + a0
    t = a1 << np.uint64(17)
    a2 ^= a0
    a3 ^= a1
    a1 ^= a2
    a0 ^= a3
    a2 ^= t
    return r, a0, a1, a2, _rotl(a3, 45)


@njit(cache=True, inline="always")
def _next_double(a0, a1, a2, a3):  # type: ignore[no-untyped-def]
    """A uniform double in [0, 1) from the scalar xoshiro256++ state: (value, new state words)."""
    r, a0, a1, a2, a3 = _xoshiro(a0, a1, a2, a3)
    return float(r >> np.uint64(11)) * (1.0 / 9007199254740992.0), a0, a1, a2, a3


@njit(cache=True, error_model="numpy")
def _lane_words(lanes: np.ndarray, raw: np.ndarray) -> None:
    """``raw`` (a multiple of ROUNDS·LANES long) from the LANES xoshiro256++ states (4 rows of
    ``lanes``): word ``j`` from lane ``j % LANES``, each lane's words in its own order. The lane loop is
    independent per lane, so it vectorises; each load and store of a lane's state serves ROUNDS words
    (one word per load costs 2.5×: the state goes through memory every round)."""
    s0, s1, s2, s3 = (
        lanes[0:LANES],
        lanes[LANES : 2 * LANES],
        lanes[2 * LANES : 3 * LANES],
        lanes[3 * LANES :],
    )
    for o in range(0, raw.shape[0], ROUNDS * LANES):
        r = raw[o : o + ROUNDS * LANES]
        for lane in range(LANES):
            a0, a1, a2, a3 = s0[lane], s1[lane], s2[lane], s3[lane]
            x, a0, a1, a2, a3 = _xoshiro(a0, a1, a2, a3)
            r[lane] = x
            x, a0, a1, a2, a3 = _xoshiro(a0, a1, a2, a3)
            r[LANES + lane] = x
            x, a0, a1, a2, a3 = _xoshiro(a0, a1, a2, a3)
            r[2 * LANES + lane] = x
            x, a0, a1, a2, a3 = _xoshiro(a0, a1, a2, a3)
            r[3 * LANES + lane] = x
            s0[lane], s1[lane], s2[lane], s3[lane] = a0, a1, a2, a3


@njit(cache=True, inline="always")
def _finish(r, f0, f1, f2, f3):  # type: ignore[no-untyped-def]
    """The exact ziggurat for word ``r`` after its failed fast test: the base strip's exponential
    tail, the wedge test, or a fresh draw, on the fix-up stream ``f0 … f3`` (scalars, inlined:
    an array argument cost a reference-count pair per rejected word). Returns (value, new state)."""
    idx = np.intp(r & np.uint64(0xFF))
    u = bits_to_f64((r >> np.uint64(12)) | np.uint64(_ONE_BITS)) - 1.0
    neg = (r >> np.uint64(8)) & np.uint64(1) != 0
    while True:
        x = u * ZIG_X[idx]
        if idx == 0:  # beyond r: Marsaglia's tail algorithm
            while True:
                d1, f0, f1, f2, f3 = _next_double(f0, f1, f2, f3)
                d2, f0, f1, f2, f3 = _next_double(f0, f1, f2, f3)
                xx = -_ZIG_INV_R * math.log1p(-d1)
                yy = -math.log1p(-d2)
                if yy + yy > xx * xx:
                    x = _ZIG_R + xx
                    break
            break
        d1, f0, f1, f2, f3 = _next_double(f0, f1, f2, f3)
        if (ZIG_F[idx - 1] - ZIG_F[idx]) * d1 + ZIG_F[idx] < math.exp(-0.5 * x * x):
            break
        # rejected: a whole new draw on the fix-up stream
        r, f0, f1, f2, f3 = _xoshiro(f0, f1, f2, f3)
        idx = np.intp(r & np.uint64(0xFF))
        u = bits_to_f64((r >> np.uint64(12)) | np.uint64(_ONE_BITS)) - 1.0
        neg = (r >> np.uint64(8)) & np.uint64(1) != 0
        if u < ZIG_ACCEPT[idx]:
            x = u * ZIG_X[idx]
            break
    return (-x if neg else x), f0, f1, f2, f3


@njit(cache=True, error_model="numpy", inline="always")
def _fast_group(raw: np.ndarray, dst: np.ndarray, o: int) -> np.uint64:
    """Words ``o … o+63``: the fast ziggurat value into ``dst`` (branch-free, the sign a factor ±1),
    and a mask of the rejected ones (bit ``q`` for word ``o+q``). The loop vectorises (two gathers)."""
    rejected = np.uint64(0)
    for q in range(64):
        r = raw[o + q]
        idx = np.intp(r & np.uint64(0xFF))
        u = bits_to_f64((r >> np.uint64(12)) | np.uint64(_ONE_BITS)) - 1.0
        sign = bits_to_f64((((r >> np.uint64(8)) & np.uint64(1)) << np.uint64(63)) | np.uint64(_ONE_BITS))
        dst[o + q] = u * ZIG_X[idx] * sign
        rejected |= np.uint64(u >= ZIG_ACCEPT[idx]) << np.uint64(q)
    return rejected


@njit(cache=True)
def _batch(state: np.ndarray, dst: np.ndarray) -> None:
    """The next ``len(dst)`` normals of the stream (a multiple of QUANTUM, at most BATCH): the fast
    pass over all words, 64 at a time, then the rare rejected words (~1.2 %) finished in order,
    found bit by bit in the masks (a scan of flags with a branch per word cost 0.4 ns per draw)."""
    n = dst.shape[0]
    groups = n // 64
    raw = state[_RAW : _RAW + n]
    _lane_words(state[:_FIX], raw)
    masks = state[_REJ : _REJ + groups]
    for g in range(groups):
        masks[g] = _fast_group(raw, dst, 64 * g)
    f0, f1, f2, f3 = state[_FIX], state[_FIX + 1], state[_FIX + 2], state[_FIX + 3]
    for g in range(groups):
        rejected = masks[g]
        while rejected:
            j = 64 * g + np.intp(trailing_zeros(rejected))
            rejected &= rejected - np.uint64(1)
            dst[j], f0, f1, f2, f3 = _finish(raw[j], f0, f1, f2, f3)
    state[_FIX], state[_FIX + 1], state[_FIX + 2], state[_FIX + 3] = f0, f1, f2, f3


@njit(cache=True)
def fill_normal(state: np.ndarray, out: np.ndarray) -> None:
    """Fill ``out`` (1-D float64) with the next standard normals of the stream in ``state``."""
    n = out.shape[0]
    buf = state[_BUF : _BUF + QUANTUM].view(np.float64)
    cur = np.intp(state[_CUR])
    k = min(QUANTUM - cur, n)
    for j in range(k):
        out[j] = buf[cur + j]
    cur += k
    while n - k >= QUANTUM:
        m = min(BATCH, (n - k) // QUANTUM * QUANTUM)
        _batch(state, out[k : k + m])
        k += m
    if k < n:
        _batch(state, buf)
        cur = n - k
        for j in range(cur):
            out[k + j] = buf[j]
    state[_CUR] = np.uint64(cur)


# -- plain Python/numpy twin (same bits; slow, for tests) ---------------------------------------


def _xoshiro_py(s: list[int]) -> int:
    s0, s1, s2, s3 = s
    x = (s0 + s3) & _M64
    result = (((x << 23) | (x >> 41)) + s0) & _M64
    t = (s1 << 17) & _M64
    s2 ^= s0
    s3 ^= s1
    s1 ^= s2
    s0 ^= s3
    s2 ^= t
    s3 = ((s3 << 45) | (s3 >> 19)) & _M64
    s[:] = [s0, s1, s2, s3]
    return result


def _word_py(r: int) -> tuple[int, float, bool]:
    u = float(np.array([(r >> 12) | _ONE_BITS], np.uint64).view(np.float64)[0]) - 1.0
    return r & 0xFF, u, bool((r >> 8) & 1)


def _finish_py(fix: list[int], idx: int, u: float, neg: bool) -> float:
    def next_double() -> float:
        return float(_xoshiro_py(fix) >> 11) * (1.0 / 9007199254740992.0)

    while True:
        x = u * float(ZIG_X[idx])
        if idx == 0:
            while True:
                xx = -_ZIG_INV_R * math.log1p(-next_double())
                yy = -math.log1p(-next_double())
                if yy + yy > xx * xx:
                    return -(_ZIG_R + xx) if neg else _ZIG_R + xx
        if (ZIG_F[idx - 1] - ZIG_F[idx]) * next_double() + ZIG_F[idx] < math.exp(-0.5 * x * x):
            return -x if neg else x
        idx, u, neg = _word_py(_xoshiro_py(fix))
        if u < ZIG_ACCEPT[idx]:
            return -u * float(ZIG_X[idx]) if neg else u * float(ZIG_X[idx])


def fill_normal_py(state: np.ndarray, out: np.ndarray) -> None:
    """Pure-Python twin of :func:`fill_normal`: lane by lane, word by word (same bits)."""
    lanes = [[int(state[w * LANES + lane]) for w in range(4)] for lane in range(LANES)]
    fix = [int(x) for x in state[_FIX:_CUR]]
    buf = state[_BUF : _BUF + QUANTUM].view(np.float64)
    cur = int(state[_CUR])
    for i in range(out.shape[0]):
        if cur == QUANTUM:
            for j in range(QUANTUM):
                idx, u, neg = _word_py(_xoshiro_py(lanes[j % LANES]))
                if u < ZIG_ACCEPT[idx]:
                    buf[j] = -u * float(ZIG_X[idx]) if neg else u * float(ZIG_X[idx])
                else:
                    buf[j] = _finish_py(fix, idx, u, neg)
            cur = 0
        out[i] = buf[cur]
        cur += 1
    for lane in range(LANES):
        for w in range(4):
            state[w * LANES + lane] = np.uint64(lanes[lane][w])
    state[_FIX:_CUR] = np.array(fix, np.uint64)
    state[_CUR] = np.uint64(cur)
