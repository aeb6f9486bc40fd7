"""Speed and accuracy of the nlif block (NUMERICS §6 items 3–5).

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
  5. optionally (``--brian2``) Brian2's cython target at N = 1000 as the external comparison.

    python bench/blocks/spiking/nlif.py [--quick] [--json out.json] [--plot out.png] [--brian2]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import numpy as np

BENCH = Path(__file__).resolve().parents[2]  # bench/: its shared helpers (_timing)
if str(BENCH) not in sys.path:
    sys.path.insert(0, str(BENCH))

from _timing import median_time  # noqa: E402  (bench/ is on sys.path now)

from flowtact.blocks.spiking.nlif import Nlif  # noqa: E402
from flowtact.chunk import Chunk, StreamSpec  # noqa: E402

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
    n: int, integrator: str, sigma: float, duration_s: float, chunk: int, repeats: int, h: tuple = ()
) -> dict:
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

    for _ in range(3):  # compile, then warm up (the first timed runs of a process are slower)
        run_block(setup())
        run_kernel(setup())
    tb = median_time(run_block, repeats, setup)
    tk = median_time(run_kernel, repeats, setup)
    steps = n * n_t
    return {
        "n": n, "integrator": integrator, "sigma": sigma, "chunk": chunk, "duration_s": duration_s,
        "block_steps_per_s": steps / tb, "kernel_steps_per_s": steps / tk, "ratio": tk / tb,
        "spikes_per_neuron_s": spikes[0] / n / duration_s, "h_weights": list(h),
    }  # fmt: skip


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

    run(setup())
    cost = median_time(run, repeats, setup) / cost_n / 2.0 * 1e6
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


def brian2_throughput(n: int, duration_s: float, repeats: int) -> dict:
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

    run()  # cython compile (cached afterwards)
    return {"n": n, "brian2_cython_steps_per_s": n * len(u) / median_time(run, repeats)}


# -- report ------------------------------------------------------------------------------------------


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer sizes and repeats (a smoke run)")
    ap.add_argument("--json", help="write the results here")
    ap.add_argument("--plot", help="draw the curves into this PNG")
    ap.add_argument("--brian2", action="store_true", help="also time Brian2 (cython) at N = 1000")
    args = ap.parse_args()
    quick = args.quick
    reps = 3 if quick else 5
    res: dict = {"throughput": [], "chunks": [], "accuracy": [], "noise": []}

    print("1. throughput, 1000-sample chunks at 1 kHz, neuron-steps/s (block via __call__ / bare kernel)")
    print(f"{'integrator':>11} {'sigma':>5} {'N':>7} {'block':>9} {'kernel':>9} {'ratio':>6} {'spk/s/n':>8}")
    sizes = (1, 24, 1000, 100_000)
    for integ in INTEGRATORS:
        for sigma in (0.0, 0.5):
            for n in sizes:
                # N = 1 and 24 always run 10 s (10 chunks): shorter runs time mostly the first call
                dur = 2.0 if n == 100_000 else (2.0 if quick and n == 1000 else 10.0)
                r = throughput(n, integ, sigma, dur, 1000, 3 if n == 100_000 else reps)
                res["throughput"].append(r)
                print(f"{integ:>11} {sigma:>5} {n:>7} {r['block_steps_per_s']:9.3g} {r['kernel_steps_per_s']:9.3g} "
                      f"{r['ratio']:6.2f} {r['spikes_per_neuron_s']:8.1f}")  # fmt: skip

    print("\n1b. post-spike current (4 raised cosines, ~140 taps) vs none, N = 1000, exp, sigma = 0")
    res["history"] = []
    for h in ((), (-0.3, -0.2, -0.1, -0.05)):
        r = throughput(1000, "exp", 0.0, 2.0 if quick else 10.0, 1000, reps, h=h)
        res["history"].append(r)
        print(f"  h {'on ' if h else 'off'}: block {r['block_steps_per_s']:9.3g}  spikes/s/neuron "
              f"{r['spikes_per_neuron_s']:.1f}")  # fmt: skip

    print("\n2. throughput vs chunk size (N = 1000, exp, sigma = 0)")
    for chunk in (1, 10, 100, 1000, 10_000):
        dur = 1.0 if chunk < 100 else (2.0 if quick else 10.0)
        r = throughput(1000, "exp", 0.0, dur, chunk, reps)
        res["chunks"].append(r)
        print(
            f"  chunk {chunk:>6}: block {r['block_steps_per_s']:9.3g}  kernel {r['kernel_steps_per_s']:9.3g}"
        )

    print(
        "\n3. accuracy vs cost (analytic oracle, 179 spikes in 2 s; cost: 1000 neurons, 1000-sample chunks)"
    )
    ref = analytic_spikes()
    print(f"{'integrator':>11} {'dt ms':>6} {'dN':>4} {'mean|dt| ms':>12} {'max|dv|':>9} {'us/neuron-s':>12}")
    dts = (1e-3, 2e-4, 1e-4) if quick else (1e-3, 5e-4, 2e-4, 1e-4, 5e-5, 2e-5, 1e-5)
    for integ in INTEGRATORS:
        for dt in dts:
            r = accuracy(integ, dt, ref, 100 if dt < 5e-5 else 1000, 3)
            res["accuracy"].append(r)
            print(f"{integ:>11} {r['dt_ms']:6.2f} {r['dN']:4d} {r['mean_abs_dt_ms']:12.5f} {r['max_dv']:9.2e} "
                  f"{r['us_per_neuron_s']:12.3f}")  # fmt: skip

    print("\n4. noise vs dt: stationary sd (sigma 2, theory for exact OU 0.1414) and rate (u 0.8, sigma 4)")
    n_sd, n_rate = (100, 100) if quick else (200, 400)
    for integ in INTEGRATORS:
        for dt in dts:
            r = noise_stats(integ, dt, n_sd, n_rate)
            res["noise"].append(r)
            print(f"{integ:>11} dt {r['dt_ms']:5.2f} ms: sd {r['sd']:.4f}  rate {r['rate_hz']:6.2f} /s")

    if args.brian2:
        r = brian2_throughput(1000, 2.0 if quick else 10.0, 3)
        res["brian2"] = r
        ours = next(
            x for x in res["throughput"] if x["n"] == 1000 and x["integrator"] == "exp" and not x["sigma"]
        )
        print(f"\n5. Brian2 cython, N = 1000: {r['brian2_cython_steps_per_s']:.3g} neuron-steps/s "
              f"(nlif exp block: {ours['block_steps_per_s'] / r['brian2_cython_steps_per_s']:.1f}x faster)")  # fmt: skip

    print("\nbars (exp integrator, sigma = 0, 1000-sample chunks):")
    for r in res["throughput"]:
        if r["integrator"] == "exp" and r["sigma"] == 0.0 and (r["n"] >= 1000 or r["n"] == 1):
            bar = 5e8 if r["n"] >= 1000 else 1e8
            ok = "PASS" if r["block_steps_per_s"] >= bar else "FAIL"
            print(f"  N = {r['n']:>6}: {r['block_steps_per_s']:.3g} >= {bar:.0e}  {ok}")

    if args.json:
        with open(args.json, "w") as f:
            json.dump(res, f, indent=1)
    if args.plot:
        plot(res, args.plot)


def plot(res: dict, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(2, 2, figsize=(11, 8))
    for integ in INTEGRATORS:
        for sigma, ls in ((0.0, "-"), (0.5, "--")):
            rows = [r for r in res["throughput"] if r["integrator"] == integ and r["sigma"] == sigma]
            ax[0, 0].loglog([r["n"] for r in rows], [r["block_steps_per_s"] for r in rows], ls, marker="o",
                            label=f"{integ} σ={sigma}")  # fmt: skip
        rows = [r for r in res["accuracy"] if r["integrator"] == integ and r["dN"] == 0]
        ax[0, 1].loglog([r["us_per_neuron_s"] for r in rows], [r["mean_abs_dt_ms"] for r in rows], marker="o",
                        label=integ)  # fmt: skip
        rows = [r for r in res["accuracy"] if r["integrator"] == integ]
        ax[1, 0].loglog([r["dt_ms"] for r in rows], [r["max_dv"] for r in rows], marker="o", label=integ)
        rows = [r for r in res["noise"] if r["integrator"] == integ]
        ax[1, 1].semilogx(
            [r["dt_ms"] for r in rows], [r["sd"] for r in rows], marker="o", label=f"sd {integ}"
        )
    ax[0, 0].axhline(5e8, color="k", lw=0.5)
    ax[0, 0].set(xlabel="neurons", ylabel="neuron-steps/s (block)", title="throughput, 1000-sample chunks")
    ax[0, 1].set(
        xlabel="µs CPU per neuron-second", ylabel="mean |spike-time error| (ms)", title="accuracy vs cost"
    )
    ax[1, 0].set(xlabel="dt (ms)", ylabel="max |v error|, threshold-free", title="membrane error vs dt")
    ax[1, 1].axhline(2.0 * math.sqrt(TAU / 2), color="k", lw=0.5)
    ax[1, 1].set(xlabel="dt (ms)", ylabel="stationary sd", title="noise sd vs dt (σ = 2)")
    for a in ax.flat:
        a.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    main()
