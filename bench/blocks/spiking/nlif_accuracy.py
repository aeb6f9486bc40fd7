"""Suite ``nlif_accuracy``: run time against spike-time error of the nlif block's integrators on a
tactile-like drive, noise-free and with a frozen noise path, against an independent exact oracle.

Settings: integrator (exp, euler, exp_interp) × dt (1, 0.5, 0.25, 0.1 ms), float64 (the block
refuses float32 drives: stated, not faked). Population: 24 SA1-like neurons (the ``touch.SA1``
preset's τ = 10 ms, V_leak = −0.8, refractory 3.5 ms; gains 24 … 36 around the preset's 30 so
that the trains differ; σ = 0 inside the block and no post-spike current, so that an exact
solution exists).

* Truth: the drive is defined as linear between samples on a 10 µs grid; ``lif_reference`` solves
  that continuous-time model exactly (closed form per segment + bisection; no code shared with the
  block). Each setting sees the drive sampled at its own sample times.
* Deterministic case: a smooth touch (rest 0.046, raised-cosine ramp to the 0.19 plateau of the
  touch scenario's SA1 drive, 40 Hz texture ripple, release), 1 s.
* Noisy case: the same plus a frozen Ornstein–Uhlenbeck path per neuron (correlation 2 ms, sd
  0.009 drive units → membrane sd ≈ 0.11, as the SA1 preset's internal σ = 1.5 gives), drawn once
  on the 10 µs grid: every setting and the oracle see the same noise path. (The block's internal
  noise streams differ per dt, so a spike-by-spike comparison would be meaningless.)
* Errors: van Rossum D² per reference spike (τ = 5 ms; ≈ mean |Δt|/τ for small shifts, ½ per
  missing or extra spike), coincidence factor Γ (Kistler 1997, ±2 ms) and the spike-count error.
  Grid integrators (exp, euler) stamp a spike at its step's start; it is compared at the step's
  end, when the crossing is known (NUMERICS §3.2). exp_interp's interpolated times as they are.
* Cost: one core's time per neuron per simulated second (1 000 neurons, the deterministic drive,
  0.1 s of drive per call), the shipped default (exp, 1 ms) as the same-run baseline.
"""

from __future__ import annotations

import math

import numpy as np

from flowtact.bench.blocks.spiking.lif_reference import exact_spikes
from flowtact.bench.blocks.spiking.spike_metrics import (
    coincidence_factor,
    count_error,
    split_by_neuron,
    van_rossum_sq,
)
from flowtact.benchmark import Context, Suite

INTEGRATORS = ("exp", "euler", "exp_interp")
DTS_MS = (1.0, 0.5, 0.25, 0.1)
H = 1e-5  # the oracle's grid (s): every dt is a whole number of steps of it
DURATION = 1.0
N = 24
TAU, V_LEAK, REFRACTORY = 0.010, -0.8, 0.0035  # touch.SA1
GAINS = 30.0 * np.linspace(0.8, 1.2, N)
VR_TAU, GAMMA_WINDOW = 0.005, 0.002
NOISE_TAU, NOISE_SD = 0.002, 0.009
COST_N = 1000


def _smooth_step(t: np.ndarray, t0: float, rise: float) -> np.ndarray:
    x = np.clip((t - t0) / rise, 0.0, 1.0)
    return 0.5 - 0.5 * np.cos(np.pi * x)


def touch_drive(t: np.ndarray) -> np.ndarray:
    """A tactile-like SA1 drive: rest, ramp to the plateau, 40 Hz texture ripple, release."""
    contact = _smooth_step(t, 0.2, 0.05) - _smooth_step(t, 0.7, 0.05)
    return 0.046 + contact * (0.144 + 0.02 * np.sin(2 * np.pi * 40.0 * t))


def ou_paths(n_t: int, n: int, h: float, tau: float, sd: float, seed: int) -> np.ndarray:
    """(n_t, n) exact Ornstein–Uhlenbeck paths on a grid of step h, stationary from the start."""
    rng = np.random.default_rng(seed)
    a = math.exp(-h / tau)
    kick = sd * math.sqrt(1.0 - a * a)
    xi = rng.standard_normal((n_t, n))
    out = np.empty((n_t, n))
    out[0] = sd * xi[0]
    for k in range(1, n_t):
        out[k] = a * out[k - 1] + kick * xi[k]
    return out


def make_block(integrator: str, dt: float, gains: np.ndarray, per_neuron: bool):  # type: ignore[no-untyped-def]
    from flowtact.blocks.spiking.nlif import Nlif
    from flowtact.chunk import StreamSpec

    n = len(gains)
    blk = Nlif(
        n=n, tau_s=TAU, v_leak=V_LEAK, refractory_s=REFRACTORY, gain=list(gains), integrator=integrator
    )
    blk.bind({"x": StreamSpec(rate_hz=1.0 / dt, shape=(n,) if per_neuron else ())},
             demanded=frozenset({"spikes"}))  # fmt: skip
    return blk


def block_spikes(
    integrator: str, dt: float, u: np.ndarray, gains: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The block's spikes (compared times, neuron indices) for drive samples ``u`` every ``dt``."""
    from flowtact.chunk import Chunk

    blk = make_block(integrator, dt, gains, u.ndim == 2)
    t = np.arange(len(u)) * dt
    step = max(1, round(0.1 / dt))
    outs = [blk(x=Chunk(t[i : i + step], u[i : i + step]))["spikes"] for i in range(0, len(u), step)]
    outs.append(blk.flush().get("spikes"))
    outs = [c for c in outs if c is not None]
    times = np.concatenate([c.t for c in outs])
    idx = np.concatenate([c.data for c in outs]).astype(np.int64)
    if integrator != "exp_interp":
        times = times + dt  # the crossing is known at the step's end (NUMERICS §3.2)
    keep = times < DURATION
    return times[keep], idx[keep]


def errors(ref: tuple[np.ndarray, np.ndarray], got: tuple[np.ndarray, np.ndarray]) -> dict[str, float]:
    """van Rossum D² per reference spike, mean Γ over neurons and the count error of ``got``."""
    r, g = split_by_neuron(*ref, N), split_by_neuron(*got, N)
    n_ref = sum(len(x) for x in r)
    per_neuron = [van_rossum_sq(a, b, VR_TAU) for a, b in zip(r, g, strict=True)]
    d2 = sum(per_neuron) / n_ref
    gam = [coincidence_factor(a, b, GAMMA_WINDOW, DURATION) for a, b in zip(r, g, strict=True)]
    return {
        "vr_d2_per_spike": d2,
        "gamma": float(np.nanmean(gam)),
        "count_error": count_error([len(x) for x in r], [len(x) for x in g]),
        "n_spikes": len(got[0]),
        "n_ref": n_ref,
        "vr_d2_per_neuron": per_neuron,
    }


def measure_cost(ctx: Context, integrator: str, dt_ms: float) -> float:
    """µs of one core per neuron per simulated second (figure ``cost …``); returns the median."""
    from flowtact.chunk import Chunk

    dt = dt_ms * 1e-3
    n_t = round(1.0 / dt)
    t = np.arange(n_t) * dt
    u = touch_drive(t)
    step = round(0.1 / dt)
    chunks = [Chunk(t[i : i + step], u[i : i + step]) for i in range(0, n_t, step)]
    blk = make_block(integrator, dt, np.linspace(0.8, 1.2, COST_N) * 30.0, False)

    def setup():  # type: ignore[no-untyped-def]
        blk.reset()
        return blk

    def run(b) -> None:  # type: ignore[no-untyped-def]
        for c in chunks:
            b(x=c)

    default = integrator == "exp" and dt_ms == 1.0
    fig = ctx.duration(
        f"cost {integrator}, dt {dt_ms:g} ms",
        run,
        scale=1e6 / COST_N,
        unit="µs per neuron per simulated s",
        setup=setup,
        is_baseline=default,
        baseline=None if default else "cost exp, dt 1 ms",
        repeats=ctx.repeats if dt_ms >= 0.25 else 3,
        params={"integrator": integrator, "dt_ms": dt_ms, "n": COST_N},
    )
    return fig.median


def float32_note(ctx: Context) -> None:
    from flowtact.blocks.spiking.nlif import Nlif
    from flowtact.chunk import StreamSpec
    from flowtact.errors import SpecError

    try:
        Nlif(n=2).bind({"x": StreamSpec(rate_hz=1000.0, dtype="float32")})
        ctx.note("float32: the block accepted a float32 drive; this suite still measured float64 only.")
    except SpecError as e:  # the refusal is the finding
        ctx.note(
            "float32 is **not supported**: the nlif block is float64 only (state and drive), and binding a "
            f"float32 drive is refused ({type(e).__name__}: {e}). The float32 column of the grid is "
            "therefore absent rather than faked; NUMERICS §3.5 explains why float32 state is unsafe at small dt/τ."
        )


def paired(exp: dict, euler: dict) -> tuple[float, float]:
    """Mean and standard error over neurons of exp's minus Euler's van Rossum D² (same neurons)."""
    d = np.asarray(exp["vr_d2_per_neuron"]) - np.asarray(euler["vr_d2_per_neuron"])
    return float(d.mean()), float(d.std(ddof=1) / math.sqrt(len(d)))


def verdict(ctx: Context, case: str, rows: list[dict]) -> None:
    """The issue's check: exp more accurate than Euler at equal cost for dt ≥ 0.5 ms. Equal cost: the
    same dt (one step each; the premise is checked on the fastest repeats, within 15 %). More
    accurate: exp's van Rossum D² lower than Euler's on the same neurons by more than two standard
    errors of the paired difference, at every dt ≥ 0.5 ms."""
    by = {(r["integrator"], r["dt_ms"]): r for r in rows}
    parts, ok = [], True
    for dt_ms in (d for d in DTS_MS if d >= 0.5):
        ex, eu = by[("exp", dt_ms)], by[("euler", dt_ms)]
        mean, se = paired(ex, eu)
        cost_ratio = (
            ctx.figures[f"cost exp, dt {dt_ms:g} ms"].min / ctx.figures[f"cost euler, dt {dt_ms:g} ms"].min
        )
        better = mean + 2 * se < 0
        ok &= better and cost_ratio <= 1.15
        parts.append(
            f"dt {dt_ms:g} ms: D²/spike exp {ex['vr_d2_per_spike']:.3g} vs Euler {eu['vr_d2_per_spike']:.3g} "
            f"(paired difference per neuron {mean:+.3g} ± {se:.2g} SE: "
            f"{'exp better' if better else 'not significant' if mean + 2 * se >= 0 > mean - 2 * se else 'Euler better'}), "
            f"count error exp {100 * ex['count_error']:.2g} % vs Euler {100 * eu['count_error']:.2g} %, "
            f"speed-up exp vs Euler {1 / cost_ratio:.2f} (> 1: exp faster)"
        )
    ctx.check(f"exp more accurate than euler at equal cost for dt >= 0.5 ms ({case})", ok, "; ".join(parts))
    if not ok:
        ctx.note(f"**{case.capitalize()} drive: the exact exponential integrator is NOT shown more accurate than "
                 f"Euler at equal cost for dt ≥ 0.5 ms** (van Rossum D², paired over the {N} neurons): "
                 f"{'; '.join(parts)}.")  # fmt: skip


def run_case(ctx: Context, case: str, u_fine: np.ndarray, costs: dict) -> list[dict]:
    ref = exact_spikes(u_fine, H, TAU, V_LEAK, GAINS, REFRACTORY)
    ctx.data[f"{case} reference spikes"] = len(ref[0])
    trade = ctx.tradeoff(
        f"nlif_accuracy_{case}",
        f"NLIF {case} touch drive, 24 SA1-like neurons: error against cost (exact oracle)",
        "one core's time per neuron per simulated second (µs)",
        f"van Rossum D² per reference spike (τ = {VR_TAU * 1e3:g} ms)",
    )
    rows = []
    for integ in INTEGRATORS:
        for dt_ms in DTS_MS:
            ctx.step(f"{case}: {integ} dt={dt_ms:g} ms")
            every = round(dt_ms * 1e-3 / H)
            e = errors(ref, block_spikes(integ, dt_ms * 1e-3, u_fine[::every], GAINS))
            cost = costs[(integ, dt_ms)]
            rows.append({"integrator": integ, "dt_ms": dt_ms, "cost": cost, **e})
            default = integ == "exp" and dt_ms == 1.0
            trade.add(cost, max(e["vr_d2_per_spike"], 1e-12), f"{dt_ms:g} ms", default=default, series=integ)
    ctx.table(
        f"{case.capitalize()} case: error against the exact oracle ({rows[0]['n_ref']} reference spikes, "
        f"{N} neurons, {DURATION:g} s)",
        ["integrator", "dt (ms)", "µs per neuron-s", "van Rossum D²/spike", f"Γ (±{GAMMA_WINDOW * 1e3:g} ms)",
         "count error (%)", "spikes"],
        [[r["integrator"], r["dt_ms"], r["cost"], r["vr_d2_per_spike"], r["gamma"], 100 * r["count_error"],
          r["n_spikes"]] for r in rows],
    )  # fmt: skip
    ctx.data[f"{case} rows"] = rows
    return rows


def check_oracle(ctx: Context, u_fine: np.ndarray) -> None:
    """The oracle against itself on a grid twice as coarse, and the block's exp_interp at 10 µs
    (independent code, fine dt) against it: both must be far below every setting's error."""
    ref = exact_spikes(u_fine, H, TAU, V_LEAK, GAINS, REFRACTORY)
    coarse = exact_spikes(u_fine[::2], 2 * H, TAU, V_LEAK, GAINS, REFRACTORY)
    fine_blk = block_spikes("exp_interp", H, u_fine, GAINS)
    d_self, d_blk = errors(ref, coarse)["vr_d2_per_spike"], errors(ref, fine_blk)["vr_d2_per_spike"]
    ctx.data["oracle self-consistency D2"] = d_self
    ctx.data["exp_interp at 10 us vs oracle D2"] = d_blk
    ctx.note(
        f"Oracle cross-checks (deterministic drive): the oracle on a 20 µs grid differs from itself on the 10 µs "
        f"grid by D² = {d_self:.2g} per spike (drive discretisation); the block's exp_interp at dt = 10 µs "
        f"differs from the oracle by D² = {d_blk:.2g} per spike. Both are far below the errors plotted."
    )


def run(ctx: Context) -> None:
    float32_note(ctx)
    costs = {}
    for integ in INTEGRATORS:  # the default first: it is every cost's baseline
        for dt_ms in DTS_MS:
            costs[(integ, dt_ms)] = measure_cost(ctx, integ, dt_ms)
    t = np.arange(round(DURATION / H) + 1) * H
    smooth = touch_drive(t)
    check_oracle(ctx, smooth)
    det = run_case(ctx, "deterministic", smooth, costs)
    noisy_u = smooth[:, None] + ou_paths(len(t), N, H, NOISE_TAU, NOISE_SD, seed=12)
    noisy = run_case(ctx, "noisy", noisy_u, costs)
    verdict(ctx, "deterministic", det)
    verdict(ctx, "noisy", noisy)
    grid = {(r["integrator"], r["dt_ms"]): r["vr_d2_per_spike"] for r in det}
    ctx.note(
        "Reading the plots: the grid integrators (exp, euler) lose the phase of a tonic burst. Each spike "
        "and each refractory release is quantised to the step, and the error carries over to every later "
        "spike of the 0.5 s plateau (~85 spikes per neuron): at dt = 0.1 ms the last spikes are still "
        "several ms off. Their D² therefore stays near its ceiling at every dt tried here (deterministic "
        f"exp: {grid[('exp', 1.0)]:.3g} at 1 ms, {grid[('exp', 0.1)]:.3g} at 0.1 ms; euler: "
        f"{grid[('euler', 1.0)]:.3g}, {grid[('euler', 0.1)]:.3g}). exp_interp (interpolated crossings, "
        "exact refractory restart) keeps spike times to second order. Spike counts converge for all three."
    )
    ctx.note(
        "Costs are measured once per setting on the deterministic drive shared by all neurons; the noisy "
        "case's per-neuron drive adds memory traffic that is not a property of the integrator. The block's "
        "internal noise (σ > 0) was not used here: its stream differs per dt, so no spike-by-spike error "
        "exists; the `nlif` suite reports its membrane sd and rate against dt. No post-spike current (the "
        "SA1 preset's h) here: the oracle has none."
    )


SUITE = Suite(
    name="nlif_accuracy",
    title="NLIF integrators: spike-time error against cost on a touch, noise-free and noisy",
    measures="For exp, euler and exp_interp at dt = 1, 0.5, 0.25 and 0.1 ms: van Rossum distance, coincidence "
    "factor Γ and spike-count error of 24 SA1-like neurons against an independent exact oracle, on a smooth "
    "tactile drive and on the same drive with a frozen Ornstein–Uhlenbeck noise path; cost as one core's "
    "time per neuron per simulated second (1 000 neurons). Checks whether the exact exponential integrator "
    "beats Euler at equal cost for dt ≥ 0.5 ms.",
    baseline="the shipped default, exp at dt = 1 ms (cost ratios > 1: cheaper than the default); errors "
    "against the exact oracle (`lif_reference`), never against the block",
    run=run,
    minutes_quick=0.2,
    minutes_full=1.0,
)
