"""`flowtact bench touchsim`: TouchSim's afferents in flowtact — agreement, noise, afferents per core.

1. Spike agreement on the 68-trace development set (made by TouchSim, noise off): from TouchSim's
   current through ``nlif`` (``models:``), and from s and d through iir → rectified_gain → nlif
   (the current too, against TouchSim's).
2. Noise: flowtact's chain with noise on (seeded repeats) against TouchSim's own noisy runs, per
   trace and statistic (spike count, first-spike latency, mean interval) by two-sample KS tests at a
   1 % family-wise false-alarm rate (bench/touchsim_noise.py): against the stored reference
   (tests/data/touchsim_noise_ref.npz) always, against a live TouchSim run with ``--peers``.
3. Afferents per core in real time: N afferents × 1 s of stimulus at 5 kHz (the dev set's s and d,
   trace j % 68 in column j, wrapped in time), noise on, through the whole chain in 50-sample chunks;
   N over the CPU seconds. With ``--peers`` TouchSim's own per-afferent model (its ``lif_neuron``,
   one numba thread) on the same N and stimulus, in its throw-away venv (bench/peers/touchsim_peer.py).
   Both flowtact paths are timed: the fused block touchsim_chain (the headline) and the generic chain.
4. The whole hand: graphs/hand.yaml by `flowtact run` in real time at 1 and 2 shards (10 s quick, 60 s
   full): real-time factor, p99 lateness, CPU per graph second, load average (bench/touchsim_hand.py).
"""

from __future__ import annotations

import time

import numpy as np

from flowtact.benchmark import Context, Suite

FS = 5000
STIM_S = 1.0
CHUNK = 50  # 10 ms ticks, as a real-time whole-hand run would step


def stimulus(dev, n: int) -> tuple[np.ndarray, np.ndarray, list[str], np.ndarray, np.ndarray]:
    """s, d (samples × n) for 1 s: trace j % 68 in column j, wrapped in time; models, class, index."""
    cols = np.arange(n) % len(dev.names)
    rows = np.arange(int(STIM_S * FS)) % len(dev.s)
    s = np.ascontiguousarray(dev.s[np.ix_(rows, cols)])
    d = np.ascontiguousarray(dev.d[np.ix_(rows, cols)])
    return s, d, [dev.models[c] for c in cols], dev.cls[cols], dev.idx[cols]


def agreement(got: list[np.ndarray], want: list[np.ndarray]) -> dict:
    """Traces with TouchSim's spike count, with every spike within one sample, and identical."""
    same_n = [len(g) == len(w) for g, w in zip(got, want, strict=True)]
    near = [
        s and (not len(g) or int(np.abs(g - w).max()) <= 1) for s, g, w in zip(same_n, got, want, strict=True)
    ]
    ident = [np.array_equal(g, w) for g, w in zip(got, want, strict=True)]
    return {"traces": len(want), "same_count": sum(same_n), "within_1": sum(near), "identical": sum(ident),
            "spikes": sum(map(len, got)), "touchsim_spikes": sum(map(len, want))}  # fmt: skip


def run_agreement(ctx: Context, dev) -> None:
    from flowtact.bench.touchsim_chain import TouchSimChain
    from flowtact.blocks.spiking.nlif import Nlif
    from flowtact.testing import run_offline

    ctx.step("agreement: from TouchSim's current")
    out = run_offline(Nlif(models=dev.models), x=np.ascontiguousarray(dev.current), rate_hz=FS, chunk=997)
    sp = out["spikes"]
    idx, unit = np.rint(sp.t * FS).astype(np.int64), sp.data.astype(np.int64)
    from_current = agreement([idx[unit == k] for k in range(len(dev.names))], dev.spikes)
    ctx.step("agreement: from s and d through the chain")
    chain = TouchSimChain(dev.models, noise=False)
    from_sd = agreement(chain.run(dev.s, dev.d, chunk=CHUNK, keep_current=True), dev.spikes)
    rel = float(np.abs(chain.current_out - dev.current).max() / np.abs(dev.current).max())
    ctx.step("agreement: from s and d through touchsim_chain (the fused block)")
    fused = TouchSimChain(dev.models, noise=False, fused=True)
    from_fused = agreement(fused.run(dev.s, dev.d, chunk=CHUNK, keep_current=True), dev.spikes)
    same = bool(np.array_equal(fused.current_out, chain.current_out))
    paths = (("TouchSim's current → nlif", from_current), ("s, d → iir → rectified_gain → nlif", from_sd),
             ("s, d → touchsim_chain (fused)", from_fused))  # fmt: skip
    rows = [[name, r["same_count"], r["within_1"], r["identical"], f"{r['spikes']} / {r['touchsim_spikes']}"]
            for name, r in paths]  # fmt: skip
    ctx.table("Spike agreement on the development set (68 traces, noise off)",
              ["path", "same count", "every spike within one sample", "identical", "spikes flowtact / TouchSim"],
              rows, note=f"Chain's current against TouchSim's: largest difference {rel:.1e} of its largest value "
              "(tests/blocks/touch/test_touchsim_graph.py holds it to a derived float64 bound); the fused block's "
              f"current is the chain's {'bit for bit' if same else 'NOT bit for bit'}.")  # fmt: skip
    ctx.data["agreement"] = {"from_current": from_current, "from_s_d": from_sd, "from_fused": from_fused,
                             "current_rel_diff": rel, "fused_current_bit_identical": same}  # fmt: skip
    ctx.check("touchsim_chain's current is the generic chain's, bit for bit (68 traces, noise off)", same)
    for name, r in (("from TouchSim's current", from_current), ("from s and d through the chain", from_sd),
                    ("from s and d through touchsim_chain", from_fused)):  # fmt: skip
        ctx.check(f"every dev trace: TouchSim's spike count, every spike within one sample ({name})",
                  r["within_1"] == r["traces"], f"{r['within_1']} of {r['traces']} traces ({r['identical']} identical)")  # fmt: skip


def run_noise(ctx: Context, dev, py) -> None:
    from flowtact.bench.touchsim_chain import TouchSimChain
    from flowtact.bench.touchsim_noise import STATS, compare, spike_stats

    reps = 100 if ctx.quick else 200
    ctx.step(f"noise: {reps} seeded repeats of the 68 traces")
    chain = TouchSimChain(dev.models * reps, seed=1)
    stats = spike_stats(chain.run(np.tile(dev.s, (1, reps)), np.tile(dev.d, (1, reps)), chunk=1000))
    ours = {k: v.reshape(reps, len(dev.names)) for k, v in stats.items()}
    rows = []
    from flowtact.bench.touchsim_dev_set import dev_set_path

    ref = dev_set_path().parent / "touchsim_noise_ref.npz"
    sources = []
    if ref.is_file():
        with np.load(ref) as z:
            sources.append(
                (f"stored reference ({int(z['repeats'])} TouchSim repeats)", {k: z[k] for k in STATS})
            )
    if py is not None:
        from flowtact.bench.peers.touchsim_peer import touchsim_run

        ctx.step(f"noise: TouchSim, {reps} repeats")
        try:
            r = touchsim_run(py, dev.s, dev.d, dev.cls, dev.idx, reps, noise=True)
        except RuntimeError as e:
            ctx.note(f"TouchSim's noisy runs failed: {str(e).splitlines()[0]}")
        else:
            live = spike_stats(np.split(r["spikes"], np.cumsum(r["counts"].ravel())[:-1]))
            sources.append(
                (f"TouchSim run now ({reps} repeats)", {k: v.reshape(reps, -1) for k, v in live.items()})
            )
    for label, theirs in sources:
        res = compare(ours, theirs, dev.names)
        sd_ours, sd_theirs = np.nanstd(ours["first"], axis=0), np.nanstd(theirs["first"], axis=0)
        rows.append([label, res.tests, len(res.rejected), f"{res.threshold:.1e}",
                     f"{np.nanmedian(sd_ours) / FS * 1e3:.2f} / {np.nanmedian(sd_theirs) / FS * 1e3:.2f}"])  # fmt: skip
        ctx.check(f"noisy spike statistics match TouchSim's ({label}): no KS test rejects at 1 % family-wise",
                  not res.rejected, res.summary())  # fmt: skip
    if rows:
        ctx.table(f"Noise on: flowtact ({reps} seeded repeats per trace) against TouchSim's noisy runs",
                  ["against", "KS tests", "rejected", "per-test threshold", "median first-spike jitter (sd, ms) flowtact / TouchSim"],
                  rows, note="Per trace: spike count, first spike's sample, mean inter-spike interval; two-sample "
                  "Kolmogorov–Smirnov, Bonferroni-corrected to a 1 % family-wise false-alarm rate (conservative on "
                  "these discrete statistics). A trace's statistic is tested where both sides define it in ≥ 20 repeats.")  # fmt: skip
    else:
        ctx.note(
            "Noise was not compared: no stored reference (tests/data/touchsim_noise_ref.npz) and no --peers."
        )


def chain_rate(
    models: list[str], s: np.ndarray, d: np.ndarray, repeats: int, fused: bool = False
) -> list[float]:
    """Afferents per core in real time: n × 1 s over the CPU seconds of each repeat's run (after a
    warm-up); ``fused``: through touchsim_chain, else iir → rectified_gain → nlif. Timed: the
    blocks' steps up to their spike stream, what a graph runs (sorting the spikes out by afferent
    for the comparisons is not, as TouchSim's own timing leaves out its spikes' conversion)."""
    from flowtact.bench.touchsim_chain import TouchSimChain

    TouchSimChain(models, seed=99, fused=fused).spike_chunks(s, d, chunk=CHUNK)
    out = []
    for r in range(repeats):
        chain = TouchSimChain(models, seed=r, fused=fused)
        t0 = time.process_time()
        chain.spike_chunks(s, d, chunk=CHUNK)
        out.append(len(models) * STIM_S / (time.process_time() - t0))
    return out


def run_speed(ctx: Context, dev, py) -> str:
    sizes = (1000,) if ctx.quick else (1000, 17000)
    reps = max(3, ctx.repeats)
    head = ""
    for n in sizes:
        s, d, models, cls, idx = stimulus(dev, n)
        base = None
        if py is not None:
            from flowtact.bench.peers.touchsim_peer import touchsim_run

            ctx.step(f"speed: TouchSim N={n}")
            try:
                r = touchsim_run(py, s, d, cls, idx, reps, noise=True)
            except RuntimeError as e:
                ctx.note(f"TouchSim was not timed at N={n}: {str(e).splitlines()[0]}")
            else:
                base = f"TouchSim lif_neuron, noise on, N={n}"
                ctx.figure(base, [n * STIM_S / x for x in r["secs"]], "afferents per core in real time", "higher",
                           is_baseline=True, reference=True, params={"version": r["version"], "numba_threads": 1})  # fmt: skip
        ctx.step(f"speed: flowtact touchsim_chain N={n}")
        key = f"flowtact touchsim_chain (fused), noise on, N={n}"
        ctx.figure(key, chain_rate(models, s, d, reps, fused=True), "afferents per core in real time", "higher",
                   baseline=base, params={"chunk": CHUNK, "stimulus_s": STIM_S, "rate_hz": FS})  # fmt: skip
        ctx.step(f"speed: flowtact iir + rectified_gain + nlif N={n}")
        generic = f"flowtact iir + rectified_gain + nlif, noise on, N={n}"
        ctx.figure(generic, chain_rate(models, s, d, reps), "afferents per core in real time", "higher",
                   baseline=base, params={"chunk": CHUNK, "stimulus_s": STIM_S, "rate_hz": FS})  # fmt: skip
        if base is not None:
            ratio = ctx.figures[key].median / ctx.figures[base].median
            ctx.check(f"≥ 10× TouchSim's afferents per core (N={n}, noise on, same stimulus)", ratio >= 10,
                      f"{ratio:.1f}× ({ctx.figures[key].median:,.0f} against {ctx.figures[base].median:,.0f})")  # fmt: skip
        head = head or key
    return head


def run_hand(ctx: Context) -> None:
    """graphs/hand.yaml in real time at 1 and 2 shards (bench/touchsim_hand.py)."""
    from importlib.resources import files
    from pathlib import Path

    from flowtact.bench.touchsim_hand import BUDGET_MS
    from flowtact.bench.touchsim_hand import run_hand as run_one

    src = Path(str(files("flowtact.graphs").joinpath("hand.yaml")))
    if not src.is_file():
        ctx.note("The whole hand was not run: the shipped graphs/hand.yaml was not found.")
        return
    duration = 10.0 if ctx.quick else 60.0
    rows = []
    for k in (1, 2):
        ctx.step(f"whole hand: {k} shard(s), {duration:g} s in real time")
        try:
            r = run_one(src, k, duration)
        except (RuntimeError, OSError, ValueError) as e:
            ctx.note(f"The whole hand at {k} shard(s) failed: {str(e).splitlines()[0]}")
            continue
        tag = f"whole hand (16 900 afferents, noise on, 5 kHz), {k} shard(s)"
        p = {
            "duration_s": duration,
            "load_before": round(r["load"][0], 2),
            "load_after": round(r["load"][1], 2),
        }
        ctx.figure(f"{tag}: real-time factor", r["realtime_factor"], "× real time", "higher", params=p)
        ctx.figure(
            f"{tag}: CPU per graph second", r["cpu_per_graph_s"], "CPU s per graph s", "lower", params=p
        )
        if r["p99_ms"] is not None:
            ctx.figure(f"{tag}: p99 lateness", r["p99_ms"], "ms", "lower", params=p)
        p99 = "—" if r["p99_ms"] is None else f"{r['p99_ms']:.1f}"
        rows.append([k, f"{r['realtime_factor']:.2f}", "yes" if r["kept_up"] else "no", p99,
                     f"{r['max_lag_s']:.2f}", f"{r['cpu_per_graph_s']:.2f}", f"{r['load'][0]:.1f} → {r['load'][1]:.1f}"])  # fmt: skip
        if k == 2:
            ok = r["kept_up"] and r["p99_ms"] is not None and r["p99_ms"] <= BUDGET_MS
            ctx.check(f"the whole hand keeps up in real time with p99 lateness ≤ {BUDGET_MS:g} ms (2 shards)", ok,
                      f"real-time factor {r['realtime_factor']:.2f}, p99 {p99} ms, load {r['load'][1]:.1f} "
                      f"(CPU {r['cpu_per_graph_s']:.2f} s per graph s on 2 cores)")  # fmt: skip
    if rows:
        ctx.table(f"The whole hand in real time: `flowtact run graphs/hand.yaml --duration {duration:g}`",
                  ["shards", "real-time factor", "kept up", "p99 lateness (ms)", "max lag (s)",
                   "CPU s per graph s", "load average before → after"],
                  rows, note="Lateness: p99 latency of the deadline path probe → afferents (a tick's samples to "
                  "their spikes, merged across the shards). CPU: every process while the graph ran, per graph "
                  "second — what must fit in the 2 cores; the other columns depend on what else loads them.")  # fmt: skip


def run(ctx: Context) -> None:
    from flowtact.bench.touchsim_dev_set import dev_set_path, load_dev_set

    path = dev_set_path()
    if path is None:
        ctx.skip("no TouchSim development set: run from a source checkout (tests/data/touchsim_dev.npz) "
                 "or set FLOWTACT_TOUCHSIM_DEV")  # fmt: skip
    dev = load_dev_set(path)
    py = None
    if ctx.peers:
        from flowtact.bench.peers.touchsim_peer import touchsim_python

        ctx.step("TouchSim's venv")
        py, where = touchsim_python()
        if py is None:
            ctx.note(f"TouchSim was not run: its throw-away venv could not be made ({where}).")
        else:
            ctx.note(f"TouchSim ran from {where}, in its own process with one numba thread; its figure is the CPU "
                     "time of its lif_neuron (prefilter, weights, noise, membrane) per call, flowtact's the CPU time "
                     "of the block calls on 50-sample chunks (touchsim_chain filters s, as TouchSim does, for SA1 "
                     "only; the generic chain for every afferent).")  # fmt: skip
    else:
        ctx.note("TouchSim's own code was not run: with --peers it is pip-installed from its public source "
                 "(FLOWTACT_TOUCHSIM_SOURCE: a local clone) into a throw-away venv under ~/.cache/flowtact-bench/.")  # fmt: skip
    ctx.headline(run_speed(ctx, dev, py))
    run_agreement(ctx, dev)
    run_noise(ctx, dev, py)
    run_hand(ctx)


SUITE = Suite(
    name="touchsim",
    title="TouchSim's afferents: agreement, noise and afferents per core in real time",
    measures="Spike agreement on TouchSim's 68-trace development set (from its current and from s, d through "
    "iir → rectified_gain → nlif); noisy spike statistics against TouchSim's own noisy runs (KS tests); "
    "afferents per core in real time (1 s at 5 kHz, noise on, CPU time); the whole hand (graphs/hand.yaml) in "
    "real time at 1 and 2 shards: real-time factor, p99 lateness, CPU per graph second, load average.",
    baseline="with --peers, TouchSim's own per-afferent model (hsaal/touchsim, throw-away venv) on the same "
    "afferents and stimulus",
    run=run,
    minutes_quick=2.0,
    minutes_full=5.0,
    processes=(1, 1),
    needs=("scipy",),
)
