"""Suite ``nlif``: speed and accuracy of the nlif block (NUMERICS §6 items 3–5).

Measures, in one run (one core, NUMBA_NUM_THREADS=1, median of repeats):
  1. throughput: neuron-steps/s vs N ∈ {1, 24, 1000, 100000} for each integrator, σ = 0 and σ > 0,
     10 s at 1 kHz fed in 1000-sample chunks through the block's ``__call__``; the bare kernel on
     the same chunks is the baseline (ratio = block / kernel). Bars (``exp``; every row is printed):
     ≥ 5e8 for N ≥ 1000 at σ = 0 and ≥ 1e8 for N = 1; with σ = 0.5 (issue 14) ≥ 5e8 at N = 1000
     and ≥ 3e8 at N = 100 000 (full runs only);
     1b. the cost of the post-spike current (N = 1000, exp, 4 basis columns, 212 taps), checked
     against ≤ 2× the plain update, and its two parts: a spike's lags added to the ring, a slot
     read per neuron-step; 1c. the exact normal generator's draws/s against NumPy's (over
     memory, and in the kernels' 4 096-value requests);
  2. throughput vs chunk size (N = 1000, exp, σ = 0);
  3. accuracy vs cost: mean |spike-time error| against the analytic solution (NUMERICS §3.2,
     179 spikes) and µs of CPU per neuron per simulated second, per integrator and dt; the
     threshold-free max |v error| vs dt (orders 1 and 2);
  4. noise: stationary membrane sd vs dt (must be flat for exp) and noisy firing rate vs dt;
  5. with ``--peers``, Brian2's cython target at N = 1000 as the external comparison: speed, and its spikes
     against the block's (identical (step, neuron) pairs required); Brian2 comes from this environment,
     or, when it has none, from a throw-away venv with brian2==2.9.0 (bench/peers/venv.py).
"""

from __future__ import annotations

import importlib.util
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from numba import njit

from flowtact.bench.peers.venv import VENVS, venv_python
from flowtact.benchmark import Context, Suite
from flowtact.benchmark.timing import spread, time_call
from flowtact.blocks.spiking._lif_kernels import NOISE_FILL
from flowtact.blocks.spiking._spike_history import history_table, ring_add
from flowtact.blocks.spiking.nlif import NLIF_DEFAULTS, Nlif
from flowtact.blocks.spiking.normal_draws import fill_normal, seed_state
from flowtact.chunk import Chunk, StreamSpec

INTEGRATORS = ("exp", "euler", "exp_interp")
TAU = 0.01
RATE_HZ = 1000.0
#: The post-spike current's weights in 1b (4 raised-cosine columns, inhibitory: 212 taps at 1 kHz).
H_WEIGHTS = (-0.3, -0.2, -0.1, -0.05)


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
    rate = RATE_HZ
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


BRIAN2_PIN = "brian2==2.9.0"
"""The Brian2 the throw-away venv installs when this environment has none (constraints.txt's pin), beside
this environment's numpy (brian2 2.9.0 breaks with numpy 2.4, which dropped ``ndarray.ptp``)."""
BRIAN2_SCRIPT = Path(__file__).resolve().parents[2] / "peers" / "brian2_lif.py"


def brian2_python() -> tuple[Path | None, str]:
    """This Python if it imports brian2, else the throw-away venv's (pip-installed on first use)."""
    if importlib.util.find_spec("brian2") is not None:
        return Path(sys.executable), "this environment"
    packages = [BRIAN2_PIN, f"numpy=={np.__version__}"]
    return venv_python("brian2", packages, "brian2"), f"throw-away venv {VENVS / 'brian2'}"


def brian2_run(
    py: Path, n: int, duration_s: float, repeats: int, rate: float = 1000.0, target: str = "cython"
) -> dict:
    """Seconds per ``Network.run`` of the population in Brian2 (bench/peers/brian2_lif.py run by ``py``),
    and its spikes as step numbers and neuron indices."""
    u = drive(round(duration_s * rate), rate)
    env = dict(os.environ)
    if py != Path(sys.executable):  # a throw-away venv: nothing of this environment's
        env = {k: v for k, v in env.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    with tempfile.TemporaryDirectory(prefix="ftbench-brian2-") as tmp:
        inp, out = Path(tmp, "in.npz"), Path(tmp, "out.npz")
        np.savez(inp, u=u, gains=np.linspace(0.8, 1.2, n), tau_s=TAU, dt_s=1.0 / rate)
        cmd = [str(py), str(BRIAN2_SCRIPT), str(inp), str(out), "--repeats", str(repeats), "--target", target]
        r = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=900)
        if r.returncode != 0 or not out.exists():
            tail = "\n".join((r.stderr or r.stdout).strip().splitlines()[-5:])
            raise RuntimeError(f"Brian2 run exited with {r.returncode}:\n{tail}")
        with np.load(out) as f:
            return {"secs": f["secs"].tolist(), "steps": f["steps"], "idx": f["idx"], "target": str(f["target"]),
                    "version": str(f["version"])}  # fmt: skip


def block_spikes(n: int, duration_s: float, rate: float = 1000.0) -> tuple[np.ndarray, np.ndarray]:
    """The nlif block's spikes (exp, σ = 0) for Brian2's population and drive: step numbers, neuron indices."""
    blk = Nlif(n=n, integrator="exp", tau_s=TAU, gain=list(np.linspace(0.8, 1.2, n)))
    blk.bind({"x": StreamSpec(rate_hz=rate)}, demanded=frozenset({"spikes"}))
    n_t = round(duration_s * rate)
    t, u = np.arange(n_t) / rate, drive(n_t, rate)
    parts = [blk(x=Chunk(t[i : i + 1000], u[i : i + 1000]))["spikes"] for i in range(0, n_t, 1000)]
    steps = np.round(np.concatenate([p.t for p in parts]) * rate).astype(np.int64)
    return steps, np.concatenate([p.data for p in parts]).astype(np.int64)


def spike_agreement(ours: tuple[np.ndarray, np.ndarray], theirs: tuple[np.ndarray, np.ndarray]) -> dict:
    """How two spike trains of one population agree, as sets of (step, neuron) pairs."""
    a = set(zip(ours[0].tolist(), ours[1].tolist(), strict=True))
    b = set(zip(theirs[0].tolist(), theirs[1].tolist(), strict=True))
    return {"flowtact": len(a), "brian2": len(b), "common": len(a & b), "only_flowtact": len(a - b),
            "only_brian2": len(b - a), "identical": a == b}  # fmt: skip


def run_brian2(ctx: Context) -> None:
    """5. Brian2 on the N = 1000 population of the throughput figures: speed ratio and spike agreement."""
    py, where = brian2_python()
    if py is None:
        ctx.note(f"Brian2 was not timed: its throw-away venv could not be made (pip install {BRIAN2_PIN}).")
        return
    ctx.step("Brian2")
    n, dur = 1000, 2.0 if ctx.quick else 10.0
    try:
        b = brian2_run(py, n, dur, 3)
    except (RuntimeError, subprocess.TimeoutExpired) as e:
        ctx.note(f"Brian2 was not timed: {str(e).splitlines()[0]}")
        return
    name = f"Brian2 {b['version']} {b['target']}, N={n}"
    ctx.figure(name, [n * dur * 1000 / s for s in b["secs"]], "neuron-steps/s", "higher", is_baseline=True, reference=True,
               params={"python": where, "duration_s": dur})  # fmt: skip
    ctx.figure("block exp, N=1000 vs Brian2", ctx.figures["block exp, sigma=0, N=1000"].samples, "neuron-steps/s",
               "higher", baseline=name)  # fmt: skip
    agree = spike_agreement(block_spikes(n, dur), (b["steps"], b["idx"]))
    ctx.data["brian2"] = {"python": where, "version": b["version"], "target": b["target"], **agree}
    ctx.check(f"same spikes as Brian2 (exp vs Brian2 'exact', N={n}, {dur:g} s at 1 kHz): every (step, neuron) pair",
              agree["identical"], f"{agree['common']} common, {agree['only_flowtact']} only flowtact's, "
              f"{agree['only_brian2']} only Brian2's")  # fmt: skip
    ctx.note(f"Brian2 {b['version']} ({b['target']}) ran from {where}, in its own process, on the same population, "
             "drive and dt. Its figure times Network.run per repeat (after two warm-ups that compile; Brian2's "
             "per-run code preparation included, building the network not), flowtact's the block's calls on "
             "1000-sample chunks. Agreement is exact or a failed check: the same (step, neuron) spike pairs, no "
             "tolerance.")  # fmt: skip


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
                if integ == "exp" and (n >= 1000 or (n == 1 and sigma == 0.0)):
                    check_rate(ctx, label, sigma, n)
    ctx.table("Throughput, 1000-sample chunks at 1 kHz", ["integrator", "σ", "N", "neuron-steps/s (block)",
              "speed-up vs kernel", "spikes per neuron-s"], rows)  # fmt: skip
    for h in ((), H_WEIGHTS):
        spike_rate = throughput(ctx, f"post-spike current {'on' if h else 'off'}, exp, N=1000", 1000, "exp",
                                0.0, 2.0 if ctx.quick else 10.0, 1000, h=h)  # fmt: skip
    on, off = (ctx.figures[f"post-spike current {w}, exp, N=1000"].median for w in ("on", "off"))
    ctx.note(  # no bar: the exact summed history is Rager's model, and it stays the default (a decision)
        f"Post-spike current (exact summed history) against the plain update: speed-up {on / off:.2f} "
        f"({on:.3g} on, {off:.3g} off neuron-steps/s). TouchSim's models use the last spike's kernel only "
        "(history: last), which costs less."
    )
    history_parts(ctx, spike_rate / RATE_HZ, off)
    normal_draw_rate(ctx)
    for chunk in (1, 10, 100, 1000) if ctx.quick else (1, 10, 100, 1000, 10_000):
        dur = 1.0 if chunk < 100 else (2.0 if ctx.quick else 10.0)
        throughput(ctx, f"chunk {chunk}, exp, N=1000", 1000, "exp", 0.0, dur, chunk)


@njit(cache=True)
def _ring_adds(ring: np.ndarray, h_table: np.ndarray, rows: np.ndarray) -> None:
    """One spike per entry of ``rows`` into the ring, each at the next slot (the kernels' helper)."""
    p = 0
    for k in rows:
        ring_add(ring, p, k, h_table, 0.0)
        p = p + 1 if p + 1 < ring.shape[1] else 0


@njit(cache=True)
def _ring_reads(ring: np.ndarray, drive: np.ndarray, n_steps: int) -> None:
    """The kernels' per-step read: every neuron's slot into its drive, then cleared."""
    p = 0
    for _ in range(n_steps):
        column = ring[:, p]
        for k in range(drive.shape[0]):
            drive[k] += column[k]
            column[k] = 0.0
        p = p + 1 if p + 1 < ring.shape[1] else 0


def history_parts(ctx: Context, spikes_per_step: float, plain_rate: float) -> None:
    """1b's post-spike cost split into the ring's two parts (the kernels' own ``ring_add`` and read
    loop), to show what the <= 2x bar leaves: adding a spike's lags, with the 1 000-neuron ring and
    with an 8-neuron one that stays in L1, and reading and clearing one slot per neuron-step."""
    h_table = history_table(H_WEIGHTS, NLIF_DEFAULTS["h_peaks_s"], NLIF_DEFAULTS["h_offset_s"], 1 / RATE_HZ)
    n_lags = len(h_table) - 1
    rows = np.random.default_rng(1).integers(0, 1000, 200_000)
    add_ns = {}
    for n in (1000, 8):
        ring = np.zeros((n, n_lags))
        label = f"post-spike ring, one spike's {n_lags} lags added, {n}-neuron ring"
        fig = ctx.speed(label, lambda r, rows=rows % n: _ring_adds(r, h_table, rows), len(rows), "spikes/s",
                        setup=lambda ring=ring: ring, warmup=1)  # fmt: skip
        add_ns[n] = 1e9 / fig.median
    ring, drive = np.zeros((1000, n_lags)), np.zeros(1000)
    fig = ctx.speed("post-spike ring, a slot read and cleared per neuron-step, 1000-neuron ring",
                    lambda r: _ring_reads(r, drive, 2000), 1000 * 2000, "neuron-steps/s", setup=lambda: ring,
                    warmup=1)  # fmt: skip
    read_ns, budget_ns = 1e9 / fig.median, 1e9 / plain_rate
    parts = read_ns + spikes_per_step * add_ns[1000]
    ctx.note(
        f"Post-spike current, its parts: {spikes_per_step:.4f} spikes per neuron-step x {add_ns[1000]:.0f} ns "
        f"per spike + {read_ns:.2f} ns per read = {parts:.2f} ns per neuron-step; the <= 2x bar leaves "
        f"{budget_ns:.2f} ns (the plain update's cost). The spikes' adds alone, with the ring in L1 "
        f"({add_ns[8]:.0f} ns per spike), cost {spikes_per_step * add_ns[8]:.2f} ns."
    )


def check_rate(ctx: Context, label: str, sigma: float, n: int) -> None:
    """Without noise: >= 5e8 neuron-steps/s for N >= 1000 (1e8 at N = 1). With noise there is no
    absolute bar: the goal is the whole hand, noise on, in real time on two cores (population
    shards; ``flowtact bench touchsim``)."""
    if sigma != 0.0:
        return
    bar = 5e8 if n >= 1000 else 1e8
    fig = ctx.figures[label]
    ctx.check(
        f"exp, sigma {sigma:g}, N={n}: >= {bar:.0e} neuron-steps/s", fig.median >= bar, f"{fig.median:.3g}"
    )


def normal_draw_rate(ctx: Context) -> None:
    """The kernels' exact normal generator (normal_draws) against NumPy's Generator.standard_normal,
    both filling a preallocated buffer: 1e6 values 10 times (the rate over memory), and NOISE_FILL
    (4 096) values at a time, the kernels' own request, in cache."""
    ctx.step("normal draws")
    _draw_pair(ctx, 1_000_000, 10, "")
    _draw_pair(ctx, NOISE_FILL, 10_000_000 // NOISE_FILL, f", {NOISE_FILL} per call")


def _draw_pair(ctx: Context, size: int, calls: int, tag: str) -> None:
    """NumPy's and the kernels' generator, each filling one buffer of ``size`` ``calls`` times."""
    out = np.empty(size)
    gen = np.random.default_rng(1)
    state = seed_state(np.random.default_rng(1))

    def numpy_draws(_: None) -> None:
        for _ in range(calls):
            gen.standard_normal(out=out)

    def flowtact_draws(_: None) -> None:
        for _ in range(calls):
            fill_normal(state, out)

    base = f"normal draws, numpy Generator.standard_normal{tag}"
    ctx.speed(base, numpy_draws, size * calls, "draws/s", is_baseline=True, setup=lambda: None, warmup=1)
    ctx.speed(f"normal draws, nlif kernel (normal_draws.fill_normal){tag}", flowtact_draws, size * calls,
              "draws/s", baseline=base, setup=lambda: None, warmup=1)  # fmt: skip


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
    ctx.headline("block exp, sigma=0, N=1000")  # the shipped integrator, a touch-sized population
    run_throughput(ctx)
    run_accuracy(ctx)
    if ctx.peers:
        run_brian2(ctx)
    else:
        ctx.note("Brian2 (cython) was not run: run with --peers (from this environment, or a throw-away venv "
                 f"with {BRIAN2_PIN} under ~/.cache/flowtact-bench/ made on first use).")  # fmt: skip


SUITE = Suite(
    name="nlif",
    title="NLIF population: throughput and accuracy against cost",
    measures="Neuron-steps/s of the `nlif` block for N = 1 … 100 000, every integrator, with and without "
    "noise, against chunk size and with a post-spike current; spike-time error against an analytic "
    "oracle and CPU per neuron-second for each integrator and dt; membrane noise sd vs dt.",
    baseline="the block's bare numba kernel on the same chunks (a speed-up below 1: what the "
    "block's bookkeeping costs); with --peers, Brian2's cython target",
    run=run,
    minutes_quick=0.5,
    minutes_full=6.0,
)
