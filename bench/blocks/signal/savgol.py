"""Benchmark of the savgol block: throughput vs chunk size, and derivative error vs latency.

    python bench/blocks/signal/savgol.py [--quick] [--json out.json] [--plot out.png]

(1) Throughput through the block's ``__call__`` (what an executor pays: read-only views, bad-data
    screen, numba kernel, output chunk) for chunks of 1 … 10 000 samples, 1 and 3 channels, both
    modes, against ``scipy.signal.lfilter`` with ``zi`` on the same chunks in the same run (the
    causal filter; ratio > 1 = the block is faster). One core (threads pinned), median of repeats.
(2) NUMERICS.md §1.3: RMS error of F' and F'' for windows 5…21 × orders 2…4 × causal/centred on
    a tactile-band force (0.5–8 Hz components, ~1 N) plus σ = 0.01 N white noise, 10 s at 1 kHz,
    against the analytic derivative at each output's timestamp. "Latency" is the effective delay
    in samples: the stamping delay ((N−1)/2 centred, 0 causal) plus the filter's lag on a ramp of
    the derivative (a causal order-2 F'' is a centre estimate in disguise: (N−1)/2).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402

import numpy as np  # noqa: E402

BENCH = Path(__file__).resolve().parents[2]  # bench/: its shared helpers (_timing)
if str(BENCH) not in sys.path:
    sys.path.insert(0, str(BENCH))

from _timing import median_time  # noqa: E402
from scipy import signal  # noqa: E402  (bench-only baseline)

from flowtact import Chunk, StreamSpec  # noqa: E402
from flowtact.blocks.signal.savgol import SavGol, savgol_coeffs  # noqa: E402

RATE = 1000.0
CHUNKS = (1, 10, 100, 1000, 10_000)
BAR_SAMPLES_PER_S = 4e7  # brief: >= 4e7 samples/s at chunk 1000 through __call__


# -- (1) throughput ---------------------------------------------------------------------------------


def throughput(quick: bool) -> list[dict]:
    repeats = 3 if quick else 7
    rows = []
    for channels in (1, 3):
        shape: tuple[int, ...] = () if channels == 1 else (channels,)
        for chunk in CHUNKS:
            n = {1: 5_000, 10: 20_000}.get(chunk, 200_000) // (4 if quick else 1)
            n = max(n, chunk)
            x = np.random.default_rng(0).normal(size=(n, *shape))
            t = np.arange(n) / RATE
            chunks = [Chunk(t[i : i + chunk], x[i : i + chunk]) for i in range(0, n, chunk)]
            row = {"channels": channels, "chunk": chunk, "samples": n}
            for mode in ("causal", "centred"):
                block = SavGol(window=5, order=4, deriv=1, mode=mode)
                block.bind({"x": StreamSpec(shape=shape, units="N", rate_hz=RATE)})

                def run(block=block, chunks=chunks) -> None:
                    block.restart()
                    for c in chunks:
                        block(x=c)

                run()  # warm-up (numba compile / cache load)
                row[f"block_{mode}"] = n / median_time(run, repeats)
            b = signal.savgol_coeffs(5, 4, deriv=1, delta=1 / RATE, pos=4, use="conv")
            datas = [c.data for c in chunks]

            def run_lfilter(b=b, datas=datas, shape=shape) -> None:
                zi = np.zeros((4, *shape))
                for d in datas:
                    _, zi = signal.lfilter(b, [1.0], d, axis=0, zi=zi)

            run_lfilter()
            row["lfilter_zi"] = n / median_time(run_lfilter, repeats)
            row["ratio_causal"] = row["block_causal"] / row["lfilter_zi"]
            row["ratio_centred"] = row["block_centred"] / row["lfilter_zi"]
            rows.append(row)
    return rows


def print_throughput(rows: list[dict]) -> None:
    print("\n(1) savgol 5/4 F' throughput, samples/s through SavGol.__call__ (one core, median)")
    print(
        f"{'ch':>3} {'chunk':>6} | {'causal':>9} {'centred':>9} | {'lfilter+zi':>10} | {'causal/lf':>9} {'centred/lf':>10}"
    )
    for r in rows:
        print(
            f"{r['channels']:>3} {r['chunk']:>6} | {r['block_causal']:9.3g} {r['block_centred']:9.3g} | "
            f"{r['lfilter_zi']:10.3g} | {r['ratio_causal']:9.1f} {r['ratio_centred']:10.1f}"
        )
    at1000 = [r for r in rows if r["chunk"] == 1000]
    for r in at1000:
        worst = min(r["block_causal"], r["block_centred"])
        ok = "meets" if worst >= BAR_SAMPLES_PER_S else "MISSES"
        print(f"chunk 1000, {r['channels']} channel(s): {worst:.3g} samples/s (slower mode) {ok} the 4e7 bar")


# -- (2) error vs latency ---------------------------------------------------------------------------

_FREQS_HZ = (0.5, 1.0, 2.0, 3.0, 5.0, 8.0)
_AMPS_N = (0.6, 0.4, 0.25, 0.15, 0.08, 0.05)


def tactile_force(t: np.ndarray, phases: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A smooth ~1 N force with 0.5–8 Hz components, and its exact first and second derivatives."""
    f = np.zeros_like(t)
    d1 = np.zeros_like(t)
    d2 = np.zeros_like(t)
    for fr, a, ph in zip(_FREQS_HZ, _AMPS_N, phases, strict=True):
        w = 2 * math.pi * fr
        f += a * np.sin(w * t + ph)
        d1 += a * w * np.cos(w * t + ph)
        d2 -= a * w * w * np.sin(w * t + ph)
    return f, d1, d2


def effective_lag(window: int, order: int, deriv: int, mode: str) -> float:
    """Samples between the instant an estimate describes and the sample it is stamped/emitted at."""
    pos = window - 1 if mode == "causal" else (window - 1) // 2
    c = savgol_coeffs(window, order, deriv, pos=pos)  # per sample
    z = np.arange(window) - pos
    bias = float(c @ (z ** (deriv + 1))) / math.factorial(deriv + 1)  # estimate of the ramp z at 0 → −lag
    return round((window - 1 - pos) - bias, 9) + 0.0  # + 0.0: no '-0.00'


def error_table(quick: bool, sigma: float = 0.01, duration_s: float = 10.0) -> list[dict]:
    rng = np.random.default_rng(11)
    n = int(duration_s * RATE)
    t = np.arange(n) / RATE
    force, d1, d2 = tactile_force(t, rng.uniform(0, 2 * math.pi, len(_FREQS_HZ)))
    noisy = force + rng.normal(0.0, sigma, n)
    truth = {1: d1, 2: d2}
    windows = (5, 11, 21) if quick else (5, 7, 11, 15, 21)
    rows = []
    for window in windows:
        for order in (2, 3, 4):
            if order >= window:
                continue
            for mode in ("centred", "causal"):
                row = {"window": window, "order": order, "mode": mode}
                for deriv in (1, 2):
                    block = SavGol(window=window, order=order, deriv=deriv, mode=mode)
                    block.bind({"x": StreamSpec(units="N", rate_hz=RATE)})
                    y = block(x=Chunk(t, noisy))["y"]
                    tail = block.flush().get("y")
                    ty = np.concatenate([y.t, tail.t]) if tail else y.t
                    vy = np.concatenate([y.data, tail.data]) if tail else y.data
                    idx = np.rint(ty * RATE).astype(int)
                    keep = (idx >= window) & (idx < n - window)  # leave out the zero-padding transients
                    err = vy[keep] - truth[deriv][idx[keep]]
                    clean = SavGol(window=window, order=order, deriv=deriv, mode=mode)
                    clean.bind({"x": StreamSpec(units="N", rate_hz=RATE)})
                    yc = clean(x=Chunk(t, force))["y"]
                    idc = np.rint(yc.t * RATE).astype(int)
                    kc = (idc >= window) & (idc < n - window)
                    row[f"d{deriv}_latency"] = effective_lag(window, order, deriv, mode)
                    row[f"d{deriv}_rms"] = float(np.sqrt(np.mean(err**2)))
                    row[f"d{deriv}_bias_rms"] = float(
                        np.sqrt(np.mean((yc.data[kc] - truth[deriv][idc[kc]]) ** 2))
                    )
                    pos = window - 1 if mode == "causal" else None
                    coef = savgol_coeffs(window, order, deriv, pos=pos, rate_hz=RATE)
                    row[f"d{deriv}_noise_pred"] = sigma * float(np.linalg.norm(coef))
                rows.append(row)
    truth_rms = {1: float(np.sqrt(np.mean(d1**2))), 2: float(np.sqrt(np.mean(d2**2)))}
    for r in rows:
        r["true_rms_d1"], r["true_rms_d2"] = truth_rms[1], truth_rms[2]
    return rows


def print_errors(rows: list[dict]) -> None:
    d1_err, d2_err = "F' err", 'F" err'
    print(
        f"\n(2) RMS error vs latency, σ = 0.01 N, 10 s at 1 kHz; true RMS F' = {rows[0]['true_rms_d1']:.2f} N/s, "
        f"F'' = {rows[0]['true_rms_d2']:.0f} N/s²"
    )
    print(
        f"{'N/p':>5} {'mode':>8} | {'lat':>5} {d1_err:>8} {'σ‖c‖':>8} {'bias':>7} | "
        f"{'lat':>5} {d2_err:>9} {'σ‖c‖':>9} {'bias':>7}"
    )
    for r in rows:
        print(
            f"{r['window']:>2}/{r['order']:<2} {r['mode']:>8} | {r['d1_latency']:5.2f} {r['d1_rms']:8.3g} "
            f"{r['d1_noise_pred']:8.3g} {r['d1_bias_rms']:7.2g} | {r['d2_latency']:5.2f} {r['d2_rms']:9.4g} "
            f"{r['d2_noise_pred']:9.4g} {r['d2_bias_rms']:7.2g}"
        )
    print(
        "lat: effective latency in samples; err: RMS error; σ‖c‖: predicted noise; bias: error without noise"
    )


def plot(rows: list[dict], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, d, unit in ((axes[0], 1, "N/s"), (axes[1], 2, "N/s²")):
        for mode, marker in (("centred", "o"), ("causal", "s")):
            for order, color in ((2, "C0"), (3, "C1"), (4, "C2")):
                sel = [r for r in rows if r["mode"] == mode and r["order"] == order]
                if sel:
                    ax.plot(
                        [r[f"d{d}_latency"] for r in sel],
                        [r[f"d{d}_rms"] for r in sel],
                        marker=marker,
                        color=color,
                        linestyle="-" if mode == "centred" else "--",
                        label=f"order {order}, {mode}",
                    )
        for r in rows:
            if r["mode"] == "centred" and r["order"] == 2:
                ax.annotate(
                    f"N={r['window']}",
                    (r[f"d{d}_latency"], r[f"d{d}_rms"]),
                    fontsize=7,
                    textcoords="offset points",
                    xytext=(3, -10),
                )
        ax.axhline(rows[0][f"true_rms_d{d}"], color="k", lw=0.8, ls=":", label="true RMS of the signal")
        ax.set_yscale("log")
        ax.set_xlabel("effective latency (samples at 1 kHz)")
        ax.set_ylabel(f"RMS error ({unit})")
        ax.set_title(("F'" if d == 1 else "F''") + " — Savitzky–Golay, σ = 0.01 N (causal: all at latency 0)")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    print(f"plot written to {path}")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer samples, repeats and windows")
    ap.add_argument("--json", metavar="OUT", help="write all figures to this JSON file")
    ap.add_argument("--plot", metavar="PNG", help="draw RMS error vs latency")
    args = ap.parse_args(argv)
    print(f"savgol bench — {platform.python_version()}, numpy {np.__version__}, one core")
    tp = throughput(args.quick)
    print_throughput(tp)
    err = error_table(args.quick)
    print_errors(err)
    if args.plot:
        plot(err, args.plot)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"throughput": tp, "error_vs_latency": err, "quick": args.quick}, fh, indent=1)


if __name__ == "__main__":
    main()
