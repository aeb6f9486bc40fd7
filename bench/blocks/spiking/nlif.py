"""Suite ``nlif``: speed and accuracy of the nlif block (NUMERICS §6 items 3–5).

Measures, in one run (one core, NUMBA_NUM_THREADS=1, median of repeats):
  1. throughput: neuron-steps/s vs N ∈ {1, 24, 1000, 100000} for each integrator, σ = 0 and σ > 0,
     10 s at 1 kHz fed in 1000-sample chunks through the block's ``__call__``; the bare kernel on
     the same chunks is the baseline (ratio = block / kernel). Bar: ≥ 5e8 for N ≥ 1000 (σ = 0,
     chunks ≥ 1000) and ≥ 1e8 for N = 1 (the ``exp`` integrator; every row is printed);
     1b. the cost of the post-spike current (N = 1000, exp, 4 basis columns, ~140 taps);
  2. throughput vs chunk size (N = 1000, exp, σ = 0);
  3. accuracy vs cost: mean |spike-time error| against the analytic solution (NUMERICS §3.2,
     179 spikes) and µs of CPU per neuron per simulated second, per integrator and dt; the
     threshold-free max |v error| vs dt (orders 1 and 2);
  4. noise: stationary membrane sd vs dt (must be flat for exp) and noisy firing rate vs dt;
  5. with ``--peers``, Brian2's cython target at N = 1000 as the external comparison (when installed).
"""

from __future__ import annotations

import importlib.util
import math

import numpy as np

from flowtact.benchmark import Context, Suite
from flowtact.benchmark.timing import spread, time_call
from flowtact.blocks.spiking.nlif import Nlif
from flowtact.chunk import Chunk, StreamSpec

INTEGRATORS = ("exp", "euler", "exp_interp")
TAU = 0.01


def drive(n_t: int, rate: float) -> np.ndarray:
    t = np.arange(n_t) / rate
    return 1.2 + 0.5 * np.sin(2 * np.pi * 5 * t)


_BLOCKS: dict = {}


def make_block(n: int, integrator: str, sigma: float, rate: float, seed: int = 1, h: tuple = ()) -> Nlif:
    """A bound block, gains spread over 0.8–1.2 (desynchronised spiking); built once, restarted."""
    key = (n, integrator, sigma, rate, h)
    if key not in _BLOCKS:
        gains = list(np.linspace(0.8, 1.2, n))
        _BLOCKS[key] = Nlif(n=n, integrator=integrator, sigma=sigma, tau_s=TAU, gain=gains, h_weights=list(h))
    blk = _BLOCKS[key]
    blk.bind({"x": StreamSpec(rate_hz=rate)}, seed=seed, demanded=frozenset({"spikes"}))
    return blk


# -- 1, 2: throughput ---------------------------------------------------------------------------


def throughput(
    ctx: Context,
    label: str,
    n: int,
    integrator: str,
    sigma: float,
    duration_s: float,
    chunk: int,
    repeats: int | None = None,
    h: tuple = (),
) -> float:
    """Neuron-steps/s of the block (figure ``label``) against the bare kernel on the same chunks
    (figure ``label (kernel)``, its baseline); returns spikes per neuron-second."""
    rate = 1000.0
    n_t = round(duration_s * rate)
    t = np.arange(n_t) / rate
    u = drive(n_t, rate)
    chunks = [Chunk(t[i : i + chunk], u[i : i + chunk]) for i in range(0, n_t, chunk)]
    spikes = [0]

    def setup() -> Nlif:
        return make_block(n, integrator, sigma, rate, h=h)

    def run_block(blk: Nlif) -> None:
        spikes[0] = sum(len(blk(x=c)["spikes"]) for c in chunks)

    def run_kernel(blk: Nlif) -> None:  # the same kernel calls on the block's prepared state
        u2 = [np.ascontiguousarray(c.data).reshape(-1, 1) for c in chunks]
        first = u2[0][0]
        for uc in u2:
            blk.integrate(uc, first)
            first = uc[-1]

    steps = n * n_t
    params = {
        "n": n,
        "integrator": integrator,
        "sigma": sigma,
        "chunk": chunk,
        "duration_s": duration_s,
        "h_weights": list(h),
    }
    ctx.speed(f"{label} (kernel)", run_kernel, steps, "neuron-steps/s", is_baseline=True, setup=setup,
              repeats=repeats, warmup=2, params=params)  # fmt: skip
    ctx.speed(label, run_block, steps, "neuron-steps/s", baseline=f"{label} (kernel)", setup=setup,
              repeats=repeats, warmup=2, params=params)  # fmt: skip
    return spikes[0] / n / duration_s


# -- 3: accuracy vs cost -------------------------------------------------------------------------

W = 2 * np.pi * 5.0


def _vp(t: np.ndarray | float) -> np.ndarray | float:
    return 1.5 + (np.sin(W * t) - W * TAU * np.cos(W * t)) / (1 + (W * TAU) ** 2)


def _vfree(t, t0, v0):  # type: ignore[no-untyped-def]
    return _vp(t) + (v0 - _vp(t0)) * np.exp(-(t - t0) / TAU)


def analytic_spikes(duration: float = 2.0) -> np.ndarray:
    """Threshold crossings of τ dv/dt = −v + 1.5 + sin(2π·5·t), reset 0 (scan + bisection)."""
    times, t0, h = [], 0.0, 1e-5
    while True:
        t = t0 + np.arange(1, int((duration - t0) / h) + 2) * h
        above = np.flatnonzero(_vfree(t, t0, 0.0) > 1.0)
        if not len(above):
            return np.array(times)
        lo, hi = max(t0, t[above[0]] - h), t[above[0]]
        for _ in range(80):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if _vfree(mid, t0, 0.0) <= 1.0 else (lo, mid)
        if hi >= duration:
            return np.array(times)
        times.append(hi)
        t0 = hi


def accuracy(integrator: str, dt: float, ref: np.ndarray, cost_n: int, repeats: int) -> dict:
    rate = 1.0 / dt
    n_t = round(2.0 / dt)
    t = np.arange(n_t) * dt
    x = 1.5 + np.sin(W * t)
    blk = Nlif(n=1, tau_s=TAU, integrator=integrator)
    blk.bind({"x": StreamSpec(rate_hz=rate)})
    parts = [blk(x=Chunk(t[i : i + 1000], x[i : i + 1000]))["spikes"].t for i in range(0, n_t, 1000)]
    parts.append(blk.flush().get("spikes", Chunk(np.empty(0), np.empty(0))).t)
    st = np.concatenate(parts)
    if integrator != "exp_interp":
        st = st + dt  # grid spikes compared at the step end (NUMERICS §3.2)
    st = st[st < 2.0]
    d_n = len(st) - len(ref)
    m = min(len(st), len(ref))
    err = float(np.abs(st[:m] - ref[:m]).mean()) if d_n == 0 else float("nan")
    # threshold-free membrane error (drive × 0.3 never reaches threshold)
    blk = Nlif(n=1, tau_s=TAU, integrator=integrator, gain=0.3)
    blk.bind({"x": StreamSpec(rate_hz=rate)})
    v = np.concatenate(
        [blk(x=Chunk(t[i : i + 1000], x[i : i + 1000]))["v"].data[:, 0] for i in range(0, n_t, 1000)]
    )
    dv = float(np.abs(v - 0.3 * _vfree(t, 0.0, 0.0)).max())
    # cost: cost_n neurons, µs per neuron per simulated second, 1000-sample chunks
    chunks = [Chunk(t[i : i + 1000], x[i : i + 1000]) for i in range(0, n_t, 1000)]

    cost_blk = Nlif(n=cost_n, tau_s=TAU, integrator=integrator)

    def setup() -> Nlif:
        cost_blk.bind({"x": StreamSpec(rate_hz=rate)}, demanded=frozenset({"spikes"}))
        return cost_blk

    def run(b: Nlif) -> None:
        for c in chunks:
            b(x=c)

    cost = spread(time_call(run, repeats, 1, setup)).median / cost_n / 2.0 * 1e6
    return {"integrator": integrator, "dt_ms": dt * 1e3, "dN": d_n, "mean_abs_dt_ms": err * 1e3, "max_dv": dv,
            "us_per_neuron_s": cost}  # fmt: skip


# -- 4: noise --------------------------------------------------------------------------------------


def noise_stats(integrator: str, dt: float, n_sd: int, n_rate: int) -> dict:
    rate = 1.0 / dt
    every = max(1, round(1e-3 / dt))
    # stationary sd (σ = 2, threshold far away), 0.1 s settle + 1 s, sampled every ms
    blk = Nlif(n=n_sd, sigma=2.0, tau_s=TAU, v_leak=-10.0, integrator=integrator)
    blk.bind({"x": StreamSpec(rate_hz=rate)}, seed=3, demanded=frozenset({"v"}))
    n_t = round(1.1 / dt)
    kept = []
    for start in range(0, n_t, 10_000):
        k = min(10_000, n_t - start)
        tt = (start + np.arange(k)) * dt
        out = blk(x=Chunk(tt, np.zeros(k)))["v"].data
        sel = ((start + np.arange(k)) % every == 0) & (tt >= 0.1)
        kept.append(out[sel])
    sd = float((np.concatenate(kept) + 10.0).std())
    # noisy firing rate: u = 0.8 (subthreshold), σ = 4, n_rate neurons × 2 s
    blk = Nlif(n=n_rate, sigma=4.0, tau_s=TAU, integrator=integrator)
    blk.bind({"x": StreamSpec(rate_hz=rate)}, seed=4, demanded=frozenset({"spikes"}))
    n_t = round(2.0 / dt)
    count = 0
    for start in range(0, n_t, 10_000):
        k = min(10_000, n_t - start)
        count += len(blk(x=Chunk((start + np.arange(k)) * dt, np.full(k, 0.8)))["spikes"])
    return {"integrator": integrator, "dt_ms": dt * 1e3, "sd": sd, "sd_theory_ou": 2.0 * math.sqrt(TAU / 2),
            "rate_hz": count / n_rate / 2.0}  # fmt: skip


# -- 5: Brian2 ---------------------------------------------------------------------------------------


def brian2_throughput(n: int, duration_s: float, repeats: int) -> list[float]:
    """Seconds per run of the same population in Brian2 (cython target), every repeat's."""
    import brian2 as b2  # optional external comparison

    b2.prefs.codegen.target = "cython"
    b2.prefs.codegen.runtime.cython.cache_dir = "/tmp/brian2_cython_cache"
    rate = 1000.0
    u = drive(round(duration_s * rate), rate)

    def run() -> None:
        b2.start_scope()
        b2.defaultclock.dt = 1 * b2.ms
        ta = b2.TimedArray(u, dt=1 * b2.ms)
        g = b2.NeuronGroup(n, "dv/dt = (-v + gain*ta(t))/tau : 1\ngain : 1", threshold="v > 1", reset="v = 0",
                           method="exact", namespace={"ta": ta, "tau": TAU * b2.second})  # fmt: skip
        g.gain = np.linspace(0.8, 1.2, n)
        net = b2.Network(g, b2.SpikeMonitor(g))
        net.run(duration_s * b2.second, namespace={})

    return time_call(run, repeats, warmup=1)  # the warm-up compiles (cached afterwards)


def run_throughput(ctx: Context) -> None:
    sizes = (1, 24, 1000) if ctx.quick else (1, 24, 1000, 100_000)
    rows = []
    for integ in INTEGRATORS:
        for sigma in (0.0, 0.5):
            for n in sizes:
                ctx.step(f"throughput {integ} sigma={sigma} N={n}")
                # N = 1 and 24 always run 10 s (10 chunks): shorter runs time mostly the first call
                dur = 2.0 if n == 100_000 else (2.0 if ctx.quick and n == 1000 else 10.0)
                label = f"block {integ}, sigma={sigma:g}, N={n}"
                rate = throughput(ctx, label, n, integ, sigma, dur, 1000, 3 if n == 100_000 else None)
                rows.append([integ, sigma, n, ctx.figures[label].median, ctx.figures[label].ratio, rate])
                if integ == "exp" and sigma == 0.0 and (n >= 1000 or n == 1):
                    bar = 5e8 if n >= 1000 else 1e8
                    fig = ctx.figures[label]
                    ctx.check(
                        f"exp, sigma 0, N={n}: >= {bar:.0e} neuron-steps/s",
                        fig.median >= bar,
                        f"{fig.median:.3g}",
                    )
    ctx.table("Throughput, 1000-sample chunks at 1 kHz", ["integrator", "σ", "N", "neuron-steps/s (block)",
              "block / kernel", "spikes per neuron-s"], rows)  # fmt: skip
    for h in ((), (-0.3, -0.2, -0.1, -0.05)):
        throughput(ctx, f"post-spike current {'on' if h else 'off'}, exp, N=1000", 1000, "exp", 0.0,
                   2.0 if ctx.quick else 10.0, 1000, h=h)  # fmt: skip
    for chunk in (1, 10, 100, 1000) if ctx.quick else (1, 10, 100, 1000, 10_000):
        dur = 1.0 if chunk < 100 else (2.0 if ctx.quick else 10.0)
        throughput(ctx, f"chunk {chunk}, exp, N=1000", 1000, "exp", 0.0, dur, chunk)


def run_accuracy(ctx: Context) -> None:
    ctx.step("accuracy vs cost")
    ref = analytic_spikes()
    dts = (1e-3, 2e-4, 1e-4) if ctx.quick else (1e-3, 5e-4, 2e-4, 1e-4, 5e-5, 2e-5, 1e-5)
    tradeoff = ctx.tradeoff(
        "accuracy_vs_cost",
        "NLIF: spike-time error against cost (analytic oracle, 179 spikes in 2 s)",
        "CPU per neuron per simulated second (µs)",
        "mean |spike-time error| (ms)",
    )
    rows, lost = [], []
    for integ in INTEGRATORS:
        for dt in dts:
            ctx.step(f"accuracy {integ} dt={dt * 1e3:g} ms")
            r = accuracy(integ, dt, ref, 100 if dt < 5e-5 else 1000, 3)
            rows.append([integ, r["dt_ms"], r["dN"], r["mean_abs_dt_ms"], r["max_dv"], r["us_per_neuron_s"]])
            setting = f"{integ} {r['dt_ms']:g} ms"
            if math.isfinite(r["mean_abs_dt_ms"]):
                tradeoff.add(r["us_per_neuron_s"], r["mean_abs_dt_ms"], setting, default=integ == "exp" and dt == 1e-3,
                             series=integ)  # fmt: skip
            else:
                lost.append(f"{setting} ({r['dN']:+d} spikes)")
    ctx.table("Accuracy vs cost (cost: 1000 neurons, 1000-sample chunks)", ["integrator", "dt (ms)", "ΔN spikes",
              "mean |Δt| (ms)", "max |Δv| threshold-free", "µs per neuron-s"], rows)  # fmt: skip
    if lost:
        ctx.note(f"Not plotted (spike count differs from the oracle, so no per-spike error): {', '.join(lost)}. "
                 "The shipped default (exp at dt = 1 ms) is among them when listed here.")  # fmt: skip
    ctx.step("noise vs dt")
    n_sd, n_rate = (100, 100) if ctx.quick else (200, 400)
    noise = [noise_stats(integ, dt, n_sd, n_rate) for integ in INTEGRATORS for dt in dts]
    ctx.table("Noise vs dt: stationary sd (σ = 2; exact OU theory 0.1414) and rate (u = 0.8, σ = 4)",
              ["integrator", "dt (ms)", "sd", "rate (1/s)"],
              [[r["integrator"], r["dt_ms"], r["sd"], r["rate_hz"]] for r in noise])  # fmt: skip
    ctx.data["noise"] = noise


def run(ctx: Context) -> None:
    run_throughput(ctx)
    run_accuracy(ctx)
    if not ctx.peers:
        ctx.note("Brian2 (cython) was not timed: run with --peers.")
    elif importlib.util.find_spec("brian2") is None:
        ctx.note("Brian2 was not timed: it is not installed (pip install brian2).")
    else:
        ctx.step("Brian2")
        secs = brian2_throughput(1000, 2.0 if ctx.quick else 10.0, 3)
        steps = 1000 * (2.0 if ctx.quick else 10.0) * 1000
        ctx.figure(
            "Brian2 cython, N=1000", [steps / s for s in secs], "neuron-steps/s", "higher", is_baseline=True
        )
        ctx.figure("block exp, N=1000 vs Brian2", ctx.figures["block exp, sigma=0, N=1000"].samples, "neuron-steps/s",
                   "higher", baseline="Brian2 cython, N=1000")  # fmt: skip


SUITE = Suite(
    name="nlif",
    title="NLIF population: throughput and accuracy against cost",
    measures="Neuron-steps/s of the `nlif` block for N = 1 … 100 000, every integrator, with and without "
    "noise, against chunk size and with a post-spike current; spike-time error against an analytic "
    "oracle and CPU per neuron-second for each integrator and dt; membrane noise sd vs dt.",
    baseline="the block's bare numba kernel on the same chunks (block / kernel: what the block's "
    "bookkeeping costs); with --peers, Brian2's cython target",
    run=run,
    minutes_quick=1.5,
    minutes_full=6.0,
)
