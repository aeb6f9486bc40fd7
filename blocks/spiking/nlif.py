"""``nlif``: a population of noisy leaky integrate-and-fire neurons with a post-spike current
(Rager et al. eq. 5–6), on numba kernels (``_lif_kernels``, ``_spike_history``)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from flowtact.block import BadDataConfig, Block, Example, Port, nonfinite_counter_docs, screen_nonfinite
from flowtact.blocks.spiking._lif_kernels import (
    NOISE_FILL,
    NOISE_INTERNAL,
    NOISE_OFF,
    grid_coefficients,
    interp_coefficients,
    lif_grid,
    lif_interp,
    order_within_steps,
    seed_streams,
)
from flowtact.blocks.spiking._spike_history import history_table
from flowtact.chunk import Chunk, StreamSpec
from flowtact.errors import SpecError
from flowtact.finite import all_finite
from flowtact.inputs.limits import NOMINAL_RATE_HZ
from flowtact.params import param

__all__ = ["NLIF_DEFAULTS", "Nlif", "NlifConfig"]

#: Values used for the parameters a config leaves at None.
NLIF_DEFAULTS: dict[str, Any] = {
    "tau_s": 0.01,
    "v_leak": 0.0,
    "gain": 1.0,
    "sigma": 0.0,
    "refractory_s": 0.0,
    "integrator": "exp",
    "h_weights": (),
    "h_peaks_s": (0.002, 0.05),
    "h_offset_s": 0.005,
}
_PER_NEURON = ("tau_s", "v_leak", "gain", "sigma")
_F64 = np.dtype(np.float64)
#: Neurons per cache tile in the kernels (noise-free runs; see lif_kernels).
TILE = 4096
#: Spikes per neuron-step the spike buffers are sized for before the first call (62 per neuron and
#: second at 1 kHz; later calls use the rate seen last, × 1.25). The kernels grow short buffers
#: themselves, but doubling by doubling in numba's allocations, which get no huge pages: a large
#: first chunk spent more time faulting pages in than integrating.
SPIKE_RATE_GUESS = 1 / 16
#: Most spike-buffer entries reserved ahead of a call (64 MiB a buffer); beyond it the kernels grow.
SPIKE_RESERVE_MAX = 1 << 23
#: Spike-buffer entries at reset: a call of fewer neuron-steps needs no reservation (nor rate).
SPIKE_BUFFER_MIN = 4096


@dataclass(frozen=True)
class NlifConfig(BadDataConfig):
    """Parameters of :class:`Nlif`; ``None`` means the value in :data:`NLIF_DEFAULTS`."""

    n: int = param(1, doc="number of neurons in the population", ge=1)
    tau_s: float | tuple[float, ...] | None = param(
        None, doc="membrane time constant in s, one value or one per neuron (default 0.01)", gt=0
    )
    v_leak: float | tuple[float, ...] | None = param(
        None, doc="leak (resting) potential, threshold = 1, reset = 0; one value or n (default 0)"
    )
    gain: float | tuple[float, ...] | None = param(
        None, doc="drive gain g: the input adds g·x to the membrane target; one value or n (default 1)"
    )
    sigma: float | tuple[float, ...] | None = param(
        None,
        doc="noise intensity σ of σ·dW in 1/sqrt(s): stationary sd σ·sqrt(τ/2); one value or n (default 0)",
        ge=0,
    )
    refractory_s: float | None = param(
        None,
        doc="absolute refractory period in s: held at reset, at most 1/refractory_s spikes/s (default 0)",
        ge=0,
    )
    integrator: Literal["exp", "euler", "exp_interp"] | None = param(
        None,
        doc="exp: exact for held input; euler: Euler-Maruyama; exp_interp: linear input, "
        "interpolated spike times, one sample of latency (default exp)",
    )
    h_weights: tuple[float, ...] | None = param(
        None, doc="post-spike current: weights of the raised-cosine basis columns ([] or all 0: none)"
    )
    h_peaks_s: tuple[float, ...] | None = param(
        None,
        doc="post-spike basis: first and last peak times in s (default [0.002, 0.05])",
        ge=0,
        le=10,
        min_len=2,
        max_len=2,
    )
    h_offset_s: float | None = param(
        None, doc="post-spike basis: log-time offset b in s (small = finer early lags; default 0.005)", gt=0
    )

    def state_bytes(self) -> dict[str, float]:
        """Per neuron: a dozen rows of coefficients and state, a chunk of ``v`` and the post-spike
        history ring (about 2 × the last basis peak at :data:`NOMINAL_RATE_HZ`)."""
        weights = NLIF_DEFAULTS["h_weights"] if self.h_weights is None else self.h_weights
        peaks = NLIF_DEFAULTS["h_peaks_s"] if self.h_peaks_s is None else self.h_peaks_s
        ring = 2.0 * max(peaks) * NOMINAL_RATE_HZ if any(w != 0 for w in weights) else 0.0
        return {"n": self.n * 8.0 * (80 + ring)}

    def resolved(self) -> dict[str, Any]:
        """Every model parameter, defaults filled in (per-neuron values as arrays)."""
        out: dict[str, Any] = {}
        for key, default in NLIF_DEFAULTS.items():
            value = getattr(self, key)
            out[key] = default if value is None else value
        for key in _PER_NEURON:
            arr = np.atleast_1d(np.asarray(out[key], dtype=np.float64))
            out[key] = np.broadcast_to(arr, (self.n,)).copy() if arr.shape[0] == 1 else arr
        out["h_weights"] = tuple(float(w) for w in out["h_weights"])
        out["h_peaks_s"] = tuple(float(p) for p in out["h_peaks_s"])
        out["refractory_s"] = float(out["refractory_s"])
        out["h_offset_s"] = float(out["h_offset_s"])
        return out

    def check(self) -> None:
        for key in _PER_NEURON:
            value = getattr(self, key)
            if isinstance(value, (tuple, list)) and len(value) not in (1, self.n):
                raise self.error(key, f"must have 1 or n = {self.n} values; got {len(value)}")
        p = self.resolved()
        if not (p["tau_s"] > 0).all():
            raise self.error("tau_s", "must be > 0")
        if not (p["sigma"] >= 0).all():
            raise self.error("sigma", "must be >= 0")
        if not p["refractory_s"] >= 0:
            raise self.error("refractory_s", "must be >= 0")
        if p["integrator"] not in ("exp", "euler", "exp_interp"):
            raise self.error(
                "integrator", f"must be one of 'exp', 'euler', 'exp_interp'; got {p['integrator']!r}"
            )
        for key in ("v_leak", "gain"):
            if not np.isfinite(p[key]).all():
                raise self.error(key, "must be finite")
        if len(p["h_weights"]) == 1:
            raise self.error("h_weights", "needs at least 2 basis weights (or none)")
        if p["h_weights"]:
            first, last = p["h_peaks_s"]
            if not 0 <= first < last:
                raise self.error(
                    "h_peaks_s", f"must be [first, last] with 0 <= first < last; got {[first, last]}"
                )
            if not p["h_offset_s"] > 0:
                raise self.error("h_offset_s", "must be > 0")


def _row_buffer(n_rows: int, n: int, first: int = 0) -> np.ndarray:
    """Zeroed (n_rows, S) float64 rows, S·8 bytes ≡ 256 (mod 4096), S ≥ n; row ``r`` starts
    ``256·(first + r)`` bytes past a 4 KiB boundary (rows of two such buffers with different
    ``first`` rows are not 4K-aliased either)."""
    stride = -(-n // 512) * 512 + 32
    raw = np.zeros(n_rows * stride * 8 + 8192, np.uint8)
    base = -raw.ctypes.data % 4096 + 256 * first % 4096
    return raw[base : base + n_rows * stride * 8].view(np.float64).reshape(n_rows, stride)


#: The arrays of a step without spikes, shared by every such chunk (read-only, as chunks' arrays are).
_NO_SPIKES = Chunk.empty(dtype="int64").readonly()


def _spike_buffers(cap: int, offsets: bool) -> tuple[np.ndarray, ...]:
    """Empty spike buffers (steps, [offsets,] neurons) of ``cap`` entries, allocated by numpy (which
    asks for huge pages from 4 MiB on)."""
    if offsets:
        return np.empty(cap, np.int64), np.empty(cap), np.empty(cap, np.int64)
    return np.empty(cap, np.int64), np.empty(cap, np.int64)


class Nlif(Block):
    """A population of N noisy leaky integrate-and-fire neurons (Rager et al. eq. 5–6): drive → spikes.

    Ports
    -----
    x : float64, shape () (the same drive for all neurons) or (n,), units "1", sampled at rate_hz
        The stimulus I_stim, e.g. the Table I weighted sum of forces and derivatives.
    spikes : events, int64 neuron index, n_units = n
        Spike times (s), sorted by time then index. ``Chunk.end`` is the watermark: time of the
        last processed sample + dt (nothing more will come before it).
    v : float64, shape (n,), units "1" (threshold 1), at the input rate
        The membrane at each input sample's time ``t_i`` (before that sample acts; after the
        reset of the previous step), as Brian2's StateMonitor records it. Computed only when
        ``v`` is demanded.

    Config
    ------
    See the field docs (``flowtact blocks nlif``). ``tau_s``, ``v_leak``, ``gain`` and ``sigma``
    take one value or one per neuron. A domain's preset fills in a population
    (``preset: touch.SA1``); explicit parameters override it.

    Notes
    -----
    Normalised model, threshold 1, reset 0, ``dt = 1 / rate_hz`` of the input::

        dv = (−(v − v_leak) + gain·x(t) + I_hist(t)) / τ · dt + σ·dW
        I_hist(t) = Σ_{t_i < t} h(t − t_i),   h = Σ_j w_j b_j   (raised cosines, spike_history)

    Every step runs update → threshold (``v > 1``) → reset (Brian2's order); a spike is stamped
    with the step-start time ``t_i`` (the input sample's timestamp) by ``exp`` and ``euler``, and
    at the interpolated crossing time by ``exp_interp``. Time comes only from the input
    timestamps; a dropped (non-finite, ``on_bad_data: drop``) sample is a step the neuron skips.

    * ``exp`` (default): exact exponential step for input held over the sample (= Brian2
      ``exact``) with the exact Ornstein–Uhlenbeck noise step — stationary sd σ·sqrt(τ/2) at any
      dt; stable for any dt/τ. ``euler``: Euler–Maruyama (= Brian2 ``euler``); rejected when
      dt ≥ 2τ (it would fire spuriously at 1/dt). Both are bit-for-bit chunking-invariant and
      have zero latency.
    * ``exp_interp``: first-order hold of the input (one sample look-ahead → **one sample of
      latency** for spikes; the input value is carried across chunks), exact solution over the
      step, crossing time by linear interpolation and exact restart from 0 at that time: spike
      times are second order in dt (0.06 ms mean error at dt = 1 ms on NUMERICS' oracle B, where
      grid methods err by 1–2 ms). At most one spike per neuron per step. ``flush`` integrates
      the last sample's step with the input held. With σ > 0 the noise of a partial step reuses
      that step's normal scaled to the partial length (no Brownian bridge), so the second-order
      claim is for σ = 0.
    * Refractoriness: ``exp``/``euler`` hold v at 0 during the steps whose start is less than
      ``refractory_s`` after the spike's step (Brian2's convention): inter-spike intervals
      ≥ ceil(refractory_s/dt)·dt. ``exp_interp`` holds v at 0 for exactly ``refractory_s``
      after the crossing. Either way the rate never exceeds 1/refractory_s, whatever the drive.
      Discrete neurons otherwise fire at 1/dt on huge drives (NUMERICS §3.5), so the paper's
      "≤ 300 spikes/s" is the refractory period's job, not dt's.
    * Post-spike current: ``I_hist[n] = Σ_{i<n} h((n − i)·dt)`` (strictly past spikes) from a
      per-neuron ring buffer, held over each step; ``exp_interp`` evaluates h at the fractional
      lag of its interpolated spike. No ``h_weights`` (or all zero) costs nothing.
    * Robustness: the drive is clamped to ±1e100 so that huge finite inputs cannot overflow the
      state (the neuron then fires at its maximum rate and recovers); non-finite inputs are
      handled by ``on_bad_data`` before the kernel, so v is finite forever. State is float64.
    * Noise: one standard normal per neuron and step from a xoshiro256++/ziggurat stream seeded
      from the block's random generator at reset (one stream per 4 096 neurons, so that large
      populations run in cache-sized tiles) — identical whatever the chunking.
    * Presets: ``touch.SA1`` / ``touch.FA1`` (``flowtact.blocks.touch.presets``) are the Rager
      afferents; that module justifies each value (the paper does not print τ, V_leak, σ or h).

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.spiking.nlif import Nlif
    >>> from flowtact.testing import run_offline
    >>> t = np.arange(1000) / 1000.0
    >>> out = run_offline(Nlif(n=3, gain=[0.9, 1.0, 1.1]), x=1.5 + np.sin(2 * np.pi * 5 * t))
    >>> out["spikes"].data[:6]  # neuron indices, time-ordered
    array([2, 1, 0, 2, 1, 0])
    """

    config_cls = NlifConfig
    inputs = {
        "x": Port(
            dtype="float64",
            units="1",
            ndim=(0, 1),
            require_rate=True,
            doc="drive, shape () for all neurons or (n,) per neuron",
        )
    }
    outputs = {
        "spikes": Port(dtype="int64", shape=(), units="1", events=True, doc="spike times and neuron indices"),
        "v": Port(dtype="float64", units="1", doc="membrane at each input sample time, shape (n,)"),
    }
    counter_docs = nonfinite_counter_docs("drive samples on 'x'")

    # -- specs -------------------------------------------------------------------------------
    def specs(self, inputs: Mapping[str, StreamSpec]) -> dict[str, StreamSpec]:
        n = self.config.n
        x = inputs["x"]
        if x.shape not in ((), (n,)):
            raise SpecError(
                "x", f"{self.node}: input 'x' must have shape () or ({n},) for n = {n}; got {x.shape}"
            )
        p = self.config.resolved()
        dt = 1.0 / x.rate_hz
        if p["integrator"] == "euler" and (dt >= 2.0 * p["tau_s"]).any():
            raise SpecError(
                "x",
                f"{self.node}: euler is unstable for dt >= 2·tau (dt = {dt:g} s, min tau = "
                f"{p['tau_s'].min():g} s); use integrator: exp",
            )
        return {
            "spikes": StreamSpec(dtype="int64", shape=(), units="1", events=True, n_units=n),
            "v": StreamSpec(dtype="float64", shape=(n,), units="1", rate_hz=x.rate_hz),
        }

    # -- state -------------------------------------------------------------------------------
    def reset(self) -> None:
        p = self.config.resolved()
        spec = self.input_specs["x"]
        n = self.config.n
        self._n = n
        self._m = 1 if spec.shape == () else n
        self._dt = dt = 1.0 / float(spec.rate_hz)  # type: ignore[arg-type]
        self._method = p["integrator"]
        self._ref_s = p["refractory_s"]
        # grid: steps held at reset after the spike's step = ceil(ref/dt) − 1 (tolerant of rounding)
        self._n_clamp = max(0, math.ceil(self._ref_s / dt - 1e-9) - 1)
        vl, g = p["v_leak"], p["gain"]
        if self._method == "exp_interp":
            coef = np.vstack([interp_coefficients(p["tau_s"], p["sigma"], dt), vl, g])
            n_work = 3
        else:
            coef = np.vstack([grid_coefficients(self._method, p["tau_s"], p["sigma"], dt), vl, g])
            n_work = 2
        # every per-neuron row (coefficients, v, refractory state, scratch) in one buffer whose
        # row stride is 256 bytes past a multiple of 4 KiB: no two rows a hot loop touches are
        # 4K-aliased (that alone costs ~30 % at N = 1000)
        rows = _row_buffer(len(coef) + 3 + n_work, n)
        self._coef = rows[: len(coef)]
        self._coef[:, :n] = coef
        self._v = rows[len(coef), :n]
        self._rl = rows[len(coef) + 1, :n]
        self._refc = rows[len(coef) + 2].view(np.int64)[:n]
        self._work = rows[len(coef) + 3 :]
        self._xbuf = _row_buffer(1, max(NOISE_FILL, n), len(coef) + 3 + n_work)[0]
        w = p["h_weights"]
        if w and any(x != 0.0 for x in w):
            self._h = history_table(w, p["h_peaks_s"], p["h_offset_s"], dt)
            self._ring = np.zeros((n, len(self._h) - 1))  # (N, L): see _spike_history
        else:
            self._h = np.zeros(1)
            self._ring = np.zeros((n, 0))
        self._pos = 0
        self._noise = NOISE_INTERNAL if (p["sigma"] > 0).any() else NOISE_OFF
        self._rng_state = seed_streams(self.rng, n)
        self._no_xi = np.zeros((0, n))
        self._no_v = np.zeros((0, n))
        self._last: np.ndarray | None = None
        self._u_prev: np.ndarray | None = None
        self._t_prev = 0.0
        self._end: float | None = None
        # spike buffers the kernels fill and grow, kept across calls: a fresh 40 MB buffer per call
        # (N = 100 000, 1 s chunks) cost ~0.3 ns per neuron-step in page faults alone
        self._spk = _spike_buffers(SPIKE_BUFFER_MIN, self._method == "exp_interp")
        self._spike_rate = SPIKE_RATE_GUESS
        self._hold = self.config.on_bad_data == "hold"
        self._interp = self._method == "exp_interp"
        self._want_v = "v" in self.demanded
        self._want_spikes = "spikes" in self.demanded

    # -- stepping ----------------------------------------------------------------------------
    def _empty(self) -> dict[str, Chunk]:
        out = {}
        if "spikes" in self.demanded:
            out["spikes"] = Chunk.empty(dtype="int64", end=self._end)
        if "v" in self.demanded:
            out["v"] = Chunk.empty(shape=(self._n,))
        return out

    def step(self, x: Chunk) -> dict[str, Chunk]:
        if x.t.shape[0] == 0:
            return self._empty()
        u = x.data
        if u.dtype is not _F64 or not u.flags.c_contiguous:
            u = np.ascontiguousarray(u, dtype=np.float64)
        if not all_finite(u):
            x, self._last = screen_nonfinite(self, x, self.config.on_bad_data, "x", self._last)
            if len(x) == 0:
                return self._empty()
            u = np.ascontiguousarray(x.data, dtype=np.float64)
        elif self._hold:
            self._last = u[-1].copy()
        u2 = u.reshape(x.t.shape[0], self._m)
        if self._interp:
            return self._step_interp(x.t, u2)
        return self._step_grid(x.t, u2)

    def integrate(
        self, u: np.ndarray, u_first: np.ndarray | None = None, v_out: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        """One kernel call on the bound state, without the block's input checks and chunk handling.

        ``u``: (T, 1 or n) C-contiguous float64 drive samples; ``u_first``: the sample that opens
        the first step (``exp_interp`` only); ``v_out``: (T, n) to receive the membrane, if wanted.
        Returns the spikes as (step indices, offsets inside their steps in s — ``exp_interp`` only,
        else None — neuron indices), sorted by step then neuron: views of the block's spike buffers,
        valid until the next call (copy what must outlive it). The block's steps and the bare-kernel
        baseline of the nlif suite (`flowtact bench nlif`) use it.
        """
        v_out = self._no_v if v_out is None else v_out
        steps_in = u.shape[0] * self._n
        if steps_in > self._spk[0].shape[0]:  # a spike per neuron-step would not fit: reserve
            need = min(SPIKE_RESERVE_MAX, math.ceil(steps_in * self._spike_rate * 1.25))
            if need > self._spk[0].shape[0]:
                self._spk = _spike_buffers(need, self._interp)
        if self._interp:
            steps, offs, idx, n, self._pos = lif_interp(
                u_first, u, self._dt, self._coef, self._v, self._rl, self._ref_s, self._ring, self._pos,
                self._h, self._noise, self._rng_state, self._no_xi, self._work, self._xbuf, v_out, TILE, *self._spk,
            )  # fmt: skip
            self._spk = (steps, offs, idx)
        else:
            steps, idx, n, self._pos = lif_grid(
                u, self._coef, self._v, self._refc, self._n_clamp, self._ring, self._pos, self._h,
                self._noise, self._rng_state, self._no_xi, self._work, self._xbuf, v_out, TILE, *self._spk,
            )  # fmt: skip
            self._spk, offs = (steps, idx), None
        if steps_in > SPIKE_BUFFER_MIN:
            self._spike_rate = n / steps_in
        return steps[:n], None if offs is None else offs[:n], idx[:n]

    def _step_grid(self, t: np.ndarray, u: np.ndarray) -> dict[str, Chunk]:
        want_v = self._want_v
        v_out = np.empty((t.shape[0], self._n)) if want_v else self._no_v
        steps, _, idx = self.integrate(u, v_out=v_out)
        n_spk = steps.shape[0]
        self._end = t[-1].item() + self._dt
        out = {}
        if self._want_spikes:
            out["spikes"] = (
                Chunk(t[steps], idx.copy(), self._end)
                if n_spk
                else Chunk(_NO_SPIKES.t, _NO_SPIKES.data, self._end)
            )
        if want_v:
            out["v"] = Chunk(t, v_out)
        return out

    def _step_interp(self, t: np.ndarray, u: np.ndarray) -> dict[str, Chunk]:
        want_v = "v" in self.demanded
        first_v = None
        if self._u_prev is None:
            # the very first sample only opens step 0: v(t0) is the initial state
            first_v = self._v.copy()
            self._u_prev, self._t_prev = u[0].copy(), float(t[0])
            u, t_end = u[1:], t[1:]
        else:
            t_end = t
        starts = np.concatenate(([self._t_prev], t_end[:-1])) if len(t_end) else np.empty(0)
        spikes, v_out = self._run_interp(self._u_prev, u, want_v)
        if len(t_end):
            self._end = float(starts[-1]) + self._dt
            self._u_prev, self._t_prev = u[-1].copy(), float(t_end[-1])
        out = {}
        if "spikes" in self.demanded:
            s, off, k = spikes
            out["spikes"] = self._spike_chunk(s, starts[s] + off, k)
        if want_v:
            vt = t if first_v is not None else t_end
            vd = v_out if first_v is None else np.concatenate([first_v[None, :], v_out])
            out["v"] = Chunk(vt, vd)
        return out

    def _run_interp(self, u_first: np.ndarray, u: np.ndarray, want_v: bool):  # type: ignore[no-untyped-def]
        v_out = np.empty((len(u), self._n)) if want_v else self._no_v
        return self.integrate(u, u_first, v_out), v_out

    def _spike_chunk(self, steps: np.ndarray, times: np.ndarray, idx: np.ndarray) -> Chunk:
        """Interpolated spikes (in step, neuron order) as a chunk sorted by time, then neuron; the
        neurons copied out of the block's buffer."""
        if len(times) > 1:
            order = order_within_steps(steps, times)
            times, idx = times[order], idx[order]
        else:
            idx = idx.copy()
        return Chunk(np.asarray(times, np.float64), idx, self._end)

    def flush(self) -> dict[str, Chunk]:
        if self._method != "exp_interp" or self._u_prev is None:
            return {}
        # the last sample's step, integrated with the input held at its value
        spikes, _ = self._run_interp(self._u_prev, self._u_prev[None, :].copy(), False)
        s, off, k = spikes
        self._end = self._t_prev + self._dt
        times = self._t_prev + off
        self._u_prev = None
        return {"spikes": self._spike_chunk(s, times, k)} if "spikes" in self.demanded else {}

    @classmethod
    def example(cls) -> Example:
        t = np.arange(1500) / 1000.0
        drive = 0.06 + 0.05 * np.sin(2 * np.pi * 3 * t) + 0.08 * (t > 0.7)
        return Example(
            params={
                "n": 8,
                "tau_s": 0.01,
                "v_leak": -0.8,
                "gain": 30.0,
                "sigma": 1.5,
                "refractory_s": 0.0035,
                "h_weights": [0.0, 0.0, -0.5, -0.5],
            },
            inputs={"x": drive},
            rate_hz=1000.0,
        )
