"""``nlif``: a population of noisy leaky integrate-and-fire neurons with a post-spike current
(Rager et al. eq. 5–6), on numba kernels (``_lif_kernels``, ``_spike_history``)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any, Literal, NamedTuple

import numpy as np

import flowtact.api as ft
from flowtact.blocks.spiking._lif_kernels import (
    NOISE_FILL,
    NOISE_GROUP,
    NOISE_INTERNAL,
    NOISE_OFF,
    grid_coefficients,
    interp_coefficients,
    lif_grid,
    lif_interp,
    order_within_steps,
    seed_state,
    seed_streams,
)
from flowtact.blocks.spiking._lif_unit_kernels import lif_units
from flowtact.blocks.spiking._spike_history import history_table
from flowtact.blocks.spiking.nlif_models import per_unit_models
from flowtact.blocks.spiking.normal_draws import shard_noise_offset

__all__ = ["NLIF_DEFAULTS", "Nlif", "NlifConfig", "UnitArrays"]

_MODEL = (
    "tau_s",
    "v_leak",
    "gain",
    "sigma",
    "refractory_s",
    "integrator",
    "h_weights",
    "h_peaks_s",
    "h_offset_s",
    "history",
    "threshold",
    "threshold_block_s",
)
_PER_NEURON = ("tau_s", "v_leak", "gain", "sigma", "threshold")
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
class NlifConfig(ft.BadDataConfig):
    """Parameters of :class:`Nlif`; each default is the field's own (:data:`NLIF_DEFAULTS` reads
    them). With ``models``, a model parameter not given explicitly comes from the models."""

    n: int = ft.param(1, doc="number of neurons in the population (with models: 1 or len(models))", ge=1)
    models: tuple[str, ...] | None = ft.param(
        None,
        doc="one nlif preset per unit (e.g. [SA1.0, RA.3, PC.1] or touch.SA1.0): per-unit parameters "
        "from each; explicit parameters override them for every unit",
        min_len=1,
    )
    tau_s: float | tuple[float, ...] = ft.param(
        0.01, doc="membrane time constant in s, one value or one per neuron", gt=0
    )
    v_leak: float | tuple[float, ...] = ft.param(
        0.0, doc="leak (resting) potential, threshold = 1, reset = 0; one value or n"
    )
    gain: float | tuple[float, ...] = ft.param(
        1.0, doc="drive gain g: the input adds g·x to the membrane target; one value or n"
    )
    sigma: float | tuple[float, ...] = ft.param(
        0.0,
        doc="noise intensity σ of σ·dW in 1/sqrt(s): stationary sd σ·sqrt(τ/2); one value or n",
        ge=0,
    )
    refractory_s: float = ft.param(
        0.0,
        doc="absolute refractory period in s: held at reset, at most 1/refractory_s spikes/s",
        ge=0,
    )
    integrator: Literal["exp", "euler", "exp_interp"] = ft.param(
        "exp",
        doc="exp: exact for held input; euler: Euler-Maruyama; exp_interp: linear input, "
        "interpolated spike times, one sample of latency",
    )
    h_weights: tuple[float, ...] | tuple[tuple[float, ...], ...] = ft.param(
        (),
        doc="post-spike current: weights of the raised-cosine basis columns ([] or all 0: none), "
        "or one list per unit",
    )
    h_peaks_s: tuple[float, ...] = ft.param(
        (0.002, 0.05),
        doc="post-spike basis: first and last peak times in s",
        ge=0,
        le=10,
        min_len=2,
        max_len=2,
    )
    h_offset_s: float = ft.param(
        0.005, doc="post-spike basis: log-time offset b in s (small = finer early lags)", gt=0
    )
    history: Literal["sum", "last"] = ft.param(
        "sum",
        doc="post-spike current: sum (every past spike's kernel, Rager) or last (only the most "
        "recent spike's, TouchSim's renewal model)",
    )
    threshold: float | tuple[float, ...] = ft.param(
        1.0, doc="spike threshold (reset 0), one value or n", gt=0
    )
    threshold_block_s: float = ft.param(
        0.0,
        doc="threshold blocked after a spike (v keeps integrating, unlike refractory_s): intervals "
        ">= ceil(x/dt) steps",
        ge=0,
    )

    noise_offset: int = ft.param(
        0,
        doc="a shard's first unit in the whole population (set by shards: K): its noise streams are "
        "the whole population's from there on, so each unit draws the same normals sharded or not; "
        "a multiple of 4096 (one noise stream's units)",
        ge=0,
    )

    @property
    def size(self) -> int:
        """Units in the population: ``len(models)`` when models are given, else ``n``."""
        return len(self.models) if self.models else self.n

    def state_bytes(self) -> dict[str, float]:
        """Per neuron: a dozen rows of coefficients and state, a chunk of ``v`` and the post-spike
        history ring (about 2 × the last basis peak at :data:`NOMINAL_RATE_HZ`)."""
        weights = np.ravel(np.asarray(self.h_weights, dtype=np.float64))
        ring = 2.0 * max(self.h_peaks_s) * ft.NOMINAL_RATE_HZ if np.any(weights != 0) else 0.0
        return {"n": self.size * 8.0 * (80 + ring)}

    @classmethod
    def build(cls, params: Mapping[str, Any] | None = None, owner: str | None = None) -> NlifConfig:
        """As :meth:`Config.build`, with the ``models``' values written into the parameters not
        given: the config then holds what runs, and ``to_dict()`` builds the same config back
        (as a worker's plan and a recording's graph do)."""
        cfg = super().build(params, owner)
        if not cfg.models:
            return cfg
        explicit = cfg.explicit()
        given = {key: getattr(cfg, key) if key in explicit else None for key in NLIF_DEFAULTS}
        unit = per_unit_models(cfg, cfg.models, given)
        if not unit:
            return cfg
        return super().build({**(params or {}), **unit}, owner)

    def explicit(self) -> frozenset[str]:
        """The parameters given (in the graph or as keywords); a config made directly rather than
        through ``build`` counts those that differ from their defaults."""
        given = getattr(self, "given", None)
        if given is not None:
            return frozenset(given)
        return frozenset(f.name for f in fields(self) if getattr(self, f.name) != f.default)

    def resolved(self) -> dict[str, Any]:
        """Every model parameter, defaults filled in (per-neuron values as arrays; with history:
        last, ``h_weights`` is an (n, columns) array)."""
        n = self.size
        explicit = self.explicit()
        given = {key: getattr(self, key) if key in explicit else None for key in NLIF_DEFAULTS}
        unit = per_unit_models(self, self.models, given) if self.models else {}
        out: dict[str, Any] = {}
        for key, default in NLIF_DEFAULTS.items():
            value = given[key] if given[key] is not None else unit.get(key)
            out[key] = default if value is None else value
        for key in _PER_NEURON:
            arr = np.atleast_1d(np.asarray(out[key], dtype=np.float64))
            out[key] = np.broadcast_to(arr, (n,)).copy() if arr.shape[0] == 1 else arr
        w = out["h_weights"]
        if w and isinstance(w[0], (tuple, list, np.ndarray)):
            if len(w) != n or len({len(row) for row in w}) != 1:
                raise self.error("h_weights", f"one list per unit needs {n} lists of one length")
            out["h_weights"] = np.array(w, dtype=np.float64).reshape(n, -1)
        else:
            out["h_weights"] = tuple(float(x) for x in w)
        out["h_peaks_s"] = tuple(float(p) for p in out["h_peaks_s"])
        out["refractory_s"] = float(out["refractory_s"])
        out["h_offset_s"] = float(out["h_offset_s"])
        out["threshold_block_s"] = float(out["threshold_block_s"])
        return out

    def check(self) -> None:
        if self.noise_offset % NOISE_GROUP:
            raise self.error("noise_offset", f"must be a multiple of {NOISE_GROUP}; got {self.noise_offset}")
        if self.models and self.n not in (1, len(self.models)):
            raise self.error("n", f"must be 1 or len(models) = {len(self.models)}; got {self.n}")
        for key in _PER_NEURON:
            value = getattr(self, key)
            if isinstance(value, (tuple, list)) and len(value) not in (1, self.size):
                raise self.error(key, f"must have 1 or n = {self.size} values; got {len(value)}")
        p = self.resolved()
        self._check_history(p)
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
        cols = p["h_weights"].shape[1] if isinstance(p["h_weights"], np.ndarray) else len(p["h_weights"])
        if cols == 1:
            raise self.error("h_weights", "needs at least 2 basis weights (or none)")
        if cols:
            first, last = p["h_peaks_s"]
            if not 0 <= first < last:
                raise self.error(
                    "h_peaks_s", f"must be [first, last] with 0 <= first < last; got {[first, last]}"
                )
            if not p["h_offset_s"] > 0:
                raise self.error("h_offset_s", "must be > 0")

    def per_unit(self, p: dict[str, Any]) -> bool:
        """Whether the population runs on the per-unit kernel (``_lif_unit_kernels``): the last-spike
        history, per-unit post-spike weights, a threshold other than 1 or a threshold block. Otherwise
        the shared-parameter kernels run, as before these options existed."""
        return (
            p["history"] == "last"
            or isinstance(p["h_weights"], np.ndarray)
            or not (p["threshold"] == 1.0).all()
            or p["threshold_block_s"] > 0.0
        )

    def _check_history(self, p: dict[str, Any]) -> None:
        """The options of the per-unit kernel (grid integrators only)."""
        if p["history"] not in ("sum", "last"):
            raise self.error("history", f"must be 'sum' or 'last'; got {p['history']!r}")
        if self.per_unit(p) and p["integrator"] == "exp_interp":
            raise self.error(
                "integrator",
                "exp_interp has no history: last, per-unit h_weights, threshold or threshold block (use exp or euler)",
            )
        if isinstance(p["h_weights"], np.ndarray) and not np.isfinite(p["h_weights"]).all():
            raise self.error("h_weights", "must be finite")
        if not (p["threshold"] > 0).all() or not np.isfinite(p["threshold"]).all():
            raise self.error("threshold", "must be finite and > 0")
        if not p["threshold_block_s"] >= 0:
            raise self.error("threshold_block_s", "must be >= 0")


def _row_buffer(n_rows: int, n: int, first: int = 0) -> np.ndarray:
    """Zeroed (n_rows, S) float64 rows, S·8 bytes ≡ 256 (mod 4096), S ≥ n; row ``r`` starts
    ``256·(first + r)`` bytes past a 4 KiB boundary (rows of two such buffers with different
    ``first`` rows are not 4K-aliased either)."""
    stride = -(-n // 512) * 512 + 32
    raw = np.zeros(n_rows * stride * 8 + 8192, np.uint8)
    base = -raw.ctypes.data % 4096 + 256 * first % 4096
    return raw[base : base + n_rows * stride * 8].view(np.float64).reshape(n_rows, stride)


#: The arrays of a step without spikes, shared by every such chunk (read-only, as chunks' arrays are).
_NO_SPIKES = ft.Chunk.empty(dtype="int64").readonly()


def _spike_buffers(cap: int, offsets: bool) -> tuple[np.ndarray, ...]:
    """Empty spike buffers (steps, [offsets,] neurons) of ``cap`` entries, allocated by numpy (which
    asks for huge pages from 4 MiB on)."""
    if offsets:
        return np.empty(cap, np.int64), np.empty(cap), np.empty(cap, np.int64)
    return np.empty(cap, np.int64), np.empty(cap, np.int64)


NLIF_DEFAULTS: dict[str, Any] = {f.name: f.default for f in fields(NlifConfig) if f.name in _MODEL}
"""Every model parameter's default: the config fields' own (for bench and tests)."""


class UnitArrays(NamedTuple):
    """The per-unit kernel's state (``lif_units``' arguments of the same names): rows ``a, b, s,
    v_leak, gain`` of ``coef``, thresholds, basis weights (J, N) and columns (J, L + 2), membranes,
    lags since the last spike (capped at L + 1), refractory counts, threshold block and membrane
    clamp in steps, and whether the history is summed and the membrane noisy."""

    coef: np.ndarray
    thr: np.ndarray
    w: np.ndarray
    basis: np.ndarray
    v: np.ndarray
    lag: np.ndarray
    refc: np.ndarray
    n_block: int
    n_clamp: int
    summed: bool
    noisy: bool


class Nlif(ft.Block):
    """A population of N noisy leaky integrate-and-fire neurons (Rager et al. eq. 5–6): drive → spikes.

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
    * ``history: last``: only the most recent spike's post-spike current acts,
      ``I_hist[n] = h((n − m)·dt)`` after the last spike at step ``m`` (a renewal process,
      TouchSim's afferents). ``threshold_block_s`` blocks the threshold (not the membrane: v keeps
      integrating) for the steps starting less than it after the spike's step; ``threshold`` and
      ``h_weights`` may be given per unit. ``models:`` names one preset per unit (``[SA1.0, RA.3,
      PC.1]``: TouchSim's 17 models, ``flowtact.blocks.touch.touchsim``; or ``[SA1, FA1]``), filling
      the per-unit parameters from each. Any of these runs the per-unit kernel
      (``_lif_unit_kernels``, grid integrators only); without them the shared-parameter kernels run
      as before, bit for bit. docs/touchsim.md.

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
    shardable = True
    per_unit_params = ("models", "tau_s", "v_leak", "gain", "sigma", "threshold")
    inputs = {
        "x": ft.Port(
            dtype="float64",
            units="1",
            ndim=(0, 1),
            require_rate=True,
            doc="drive, shape () for all neurons or (n,) per neuron",
        )
    }
    outputs = {
        "spikes": ft.Port(
            dtype="int64",
            shape=(),
            units="1",
            events=True,
            doc="spike times (s) and neuron indices (n_units: n, or len(models)), sorted by time then "
            "index. Chunk.end is the watermark: time of the last processed sample + dt (nothing more "
            "will come before it)",
        ),
        "v": ft.Port(
            dtype="float64",
            units="1",
            doc="the membrane (threshold 1), shape (n,), at each input sample's time t_i (before that "
            "sample acts; after the reset of the previous step), as Brian2's StateMonitor records it. "
            "Computed only when v is demanded",
        ),
    }
    counter_docs = ft.nonfinite_counter_docs("drive samples on 'x'")

    # -- shards -----------------------------------------------------------------------------
    @classmethod
    def shard_units(cls, config: NlifConfig) -> int:
        return config.size

    @classmethod
    def shard_align(cls, config: NlifConfig) -> int:
        """Noisy populations split at their noise streams' boundaries (4 096 units each)."""
        return NOISE_GROUP if (config.resolved()["sigma"] > 0).any() else 1

    @classmethod
    def shard_params(cls, params: dict[str, Any], lo: int, hi: int, n: int) -> dict[str, Any]:
        out = super().shard_params(params, lo, hi, n)
        w = out.get("h_weights")
        if isinstance(w, (list, tuple)) and w and isinstance(w[0], (list, tuple)) and len(w) == n:
            out["h_weights"] = list(w[lo:hi])
        if "n" in out and out.get("models"):
            out["n"] = 1 if params["n"] == 1 else hi - lo
        return shard_noise_offset(out, params, lo, NOISE_GROUP)

    # -- specs -------------------------------------------------------------------------------
    def specs(self, inputs: Mapping[str, ft.StreamSpec]) -> dict[str, ft.StreamSpec]:
        n = self.config.size
        x = inputs["x"]
        if x.shape not in ((), (n,)):
            raise ft.SpecError(
                "x", f"{self.node}: input 'x' must have shape () or ({n},) for n = {n}; got {x.shape}"
            )
        p = self.config.resolved()
        dt = 1.0 / x.rate_hz
        if p["integrator"] == "euler" and (dt >= 2.0 * p["tau_s"]).any():
            raise ft.SpecError(
                "x",
                f"{self.node}: euler is unstable for dt >= 2·tau (dt = {dt:g} s, min tau = "
                f"{p['tau_s'].min():g} s); use integrator: exp",
            )
        return {
            "spikes": ft.StreamSpec(dtype="int64", shape=(), units="1", events=True, n_units=n),
            "v": ft.StreamSpec(dtype="float64", shape=(n,), units="1", rate_hz=x.rate_hz),
        }

    # -- state -------------------------------------------------------------------------------
    def reset(self) -> None:
        p = self.config.resolved()
        spec = self.input_specs["x"]
        n = self.config.size
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
        self._units = self.config.per_unit(p)
        if self._units:
            self._reset_units(p, dt)
        w = () if self._units else p["h_weights"]
        if w and any(x != 0.0 for x in w):
            self._h = history_table(w, p["h_peaks_s"], p["h_offset_s"], dt)
            self._ring = np.zeros((n, len(self._h) - 1))  # (N, L): see _spike_history
        else:
            self._h = np.zeros(1)
            self._ring = np.zeros((n, 0))
        self._pos = 0
        self._noise = NOISE_INTERNAL if (p["sigma"] > 0).any() else NOISE_OFF
        for _ in range(self.config.noise_offset // NOISE_GROUP):  # the streams of units before the shard
            seed_state(self.rng)
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

    def _reset_units(self, p: dict[str, Any], dt: float) -> None:
        """State of the per-unit kernel: thresholds, the basis columns any unit weights (J, L + 2; the
        last entry 0, where lags past the kernel are capped), lags since the last spike (capped: the
        first spike is never blocked), the threshold block in steps, and the summed mode's ring."""
        n = self._n
        w = p["h_weights"]
        if not isinstance(w, np.ndarray):
            w = np.broadcast_to(np.array(w, dtype=np.float64), (n, len(w)))
        self._n_block = max(0, math.ceil(p["threshold_block_s"] / dt - 1e-9) - 1)
        used = [j for j in range(w.shape[1]) if (w[:, j] != 0.0).any()]
        eye = np.eye(w.shape[1])
        cols = [history_table(eye[j], p["h_peaks_s"], p["h_offset_s"], dt) for j in used]
        # the lag cap (last entry) must exceed both the kernel and the threshold block
        width = max([len(c) + 1 for c in cols] + [self._n_block + 2])
        self._basis = np.zeros((len(used), width))
        for r, c in enumerate(cols):
            self._basis[r, 1 : len(c)] = c[1:]  # lag 0 is never read
        self._w = np.ascontiguousarray(w[:, used].T)
        self._thr = p["threshold"].copy()
        self._lag = np.full(n, width - 1, np.int64)
        summed = p["history"] == "sum" and len(used) > 0
        self._unit_ring = np.zeros((n, width - 2 if summed else 0))
        self._unit_pos = 0
        self._xi_step = np.zeros(n)

    # -- stepping ----------------------------------------------------------------------------
    def _empty(self) -> dict[str, ft.Chunk]:
        out = {}
        if "spikes" in self.demanded:
            out["spikes"] = ft.Chunk.empty(dtype="int64", end=self._end)
        if "v" in self.demanded:
            out["v"] = ft.Chunk.empty(shape=(self._n,))
        return out

    def step(self, x: ft.Chunk) -> dict[str, ft.Chunk]:
        if x.t.shape[0] == 0:
            return self._empty()
        u = x.data
        if u.dtype is not _F64 or not u.flags.c_contiguous:
            u = np.ascontiguousarray(u, dtype=np.float64)
        if not ft.all_finite(u):
            x, self._last = ft.screen_nonfinite(self, x, self.config.on_bad_data, "x", self._last)
            if len(x) == 0:
                return self._empty()
            u = np.ascontiguousarray(x.data, dtype=np.float64)
        elif self._hold:
            self._last = u[-1].copy()
        u2 = u.reshape(x.t.shape[0], self._m)
        if self._interp:
            return self._step_interp(x.t, u2)
        return self._step_grid(x.t, u2)

    def unit_arrays(self) -> UnitArrays:
        """The bound per-unit kernel's arrays (``models:`` or any per-unit parameter), shared, not
        copied: a fused kernel that runs these membranes itself (touchsim_chain) updates ``v`` and
        ``lag`` in place, so the block's state stays one. See :class:`UnitArrays`."""
        if not self._units:
            raise ValueError("nlif: unit_arrays() needs the per-unit kernel (models: or per-unit parameters)")
        return UnitArrays(
            self._coef, self._thr, self._w, self._basis, self._v, self._lag, self._refc, self._n_block,
            self._n_clamp, self._unit_ring.shape[1] > 0, self._noise != NOISE_OFF,
        )  # fmt: skip

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
        if self._units:
            steps, idx, n, self._unit_pos = lif_units(
                u, self._coef, self._thr, self._w, self._basis, self._v, self._lag, self._refc, self._n_block,
                self._n_clamp, self._unit_ring, self._unit_pos, self._noise, self._rng_state, self._no_xi,
                self._xi_step, v_out, *self._spk,
            )  # fmt: skip
            self._spk, offs = (steps, idx), None
        elif self._interp:
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

    def _step_grid(self, t: np.ndarray, u: np.ndarray) -> dict[str, ft.Chunk]:
        want_v = self._want_v
        v_out = np.empty((t.shape[0], self._n)) if want_v else self._no_v
        steps, _, idx = self.integrate(u, v_out=v_out)
        n_spk = steps.shape[0]
        self._end = t[-1].item() + self._dt
        out = {}
        if self._want_spikes:
            out["spikes"] = (
                ft.Chunk(t[steps], idx.copy(), self._end)
                if n_spk
                else ft.Chunk(_NO_SPIKES.t, _NO_SPIKES.data, self._end)
            )
        if want_v:
            out["v"] = ft.Chunk(t, v_out)
        return out

    def _step_interp(self, t: np.ndarray, u: np.ndarray) -> dict[str, ft.Chunk]:
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
            out["v"] = ft.Chunk(vt, vd)
        return out

    def _run_interp(self, u_first: np.ndarray, u: np.ndarray, want_v: bool):  # type: ignore[no-untyped-def]
        v_out = np.empty((len(u), self._n)) if want_v else self._no_v
        return self.integrate(u, u_first, v_out), v_out

    def _spike_chunk(self, steps: np.ndarray, times: np.ndarray, idx: np.ndarray) -> ft.Chunk:
        """Interpolated spikes (in step, neuron order) as a chunk sorted by time, then neuron; the
        neurons copied out of the block's buffer."""
        if len(times) > 1:
            order = order_within_steps(steps, times)
            times, idx = times[order], idx[order]
        else:
            idx = idx.copy()
        return ft.Chunk(np.asarray(times, np.float64), idx, self._end)

    def flush(self) -> dict[str, ft.Chunk]:
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
    def example(cls) -> ft.Example:
        t = np.arange(1500) / 1000.0
        drive = 0.06 + 0.05 * np.sin(2 * np.pi * 3 * t) + 0.08 * (t > 0.7)
        return ft.Example(
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
