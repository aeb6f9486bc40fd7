"""Suite ``savgol``: the Savitzky–Golay block's throughput vs chunk size, and derivative error vs latency.

(1) Throughput through the block's ``__call__`` (what an executor pays: read-only views, bad-data
    screen, numba kernel, output chunk) for chunks of 1 … 10 000 samples, 1 and 3 channels, both
    modes, against ``scipy.signal.lfilter`` with ``zi`` on the same chunks in the same run (the
    causal filter, streaming; ratio > 1 = the block is faster).
(2) NUMERICS.md §1.3: RMS error of F' and F'' for windows 5…21 × orders 2…4 × causal/centred on
    a tactile-band force (0.5–8 Hz components, ~1 N) plus σ = 0.01 N white noise, 10 s at 1 kHz,
    against the analytic derivative at each output's timestamp. "Latency" is the effective delay
    in samples: the stamping delay ((N−1)/2 centred, 0 causal) plus the filter's lag on a ramp of
    the derivative (a causal order-2 F'' is a centre estimate in disguise: (N−1)/2).
(3) Per window × order × mode: µs per sample of F' through the block (10 s in one chunk + flush)
    against its RMS error (2) and group delay (its effective latency in ms), the paper's 5/4
    starred; centred, ``scipy.signal.savgol_filter`` on the same data in the same run: speed ratio,
    and the largest difference from the block's output in units of eps × Σ|c·x| (bench/agreement.py).
"""

from __future__ import annotations

import math

import numpy as np

from flowtact import Chunk, StreamSpec
from flowtact.benchmark import Context, Suite
from flowtact.benchmark.labels import PointLabel, label_points
from flowtact.blocks.signal.savgol import SavGol, savgol_coeffs

RATE = 1000.0
CHUNKS = (1, 10, 100, 1000, 10_000)
BAR_SAMPLES_PER_S = 4e7  # brief: >= 4e7 samples/s at chunk 1000 through __call__


# -- (1) throughput ---------------------------------------------------------------------------------


def throughput(ctx: Context) -> None:
    """Samples/s through the block (both modes) and through lfilter + zi, per channel count and chunk."""
    from scipy import signal  # the baseline (dev extra)

    chunk_sizes = (1, 100, 1000) if ctx.quick else CHUNKS
    for channels in (1, 3):
        shape: tuple[int, ...] = () if channels == 1 else (channels,)
        for chunk in chunk_sizes:
            n = {1: 5_000, 10: 20_000}.get(chunk, 200_000) // (4 if ctx.quick else 1)
            n = max(n, chunk)
            x = np.random.default_rng(0).normal(size=(n, *shape))
            t = np.arange(n) / RATE
            chunks = [Chunk(t[i : i + chunk], x[i : i + chunk]) for i in range(0, n, chunk)]
            case = f"{channels} ch, chunk {chunk}"
            b = signal.savgol_coeffs(5, 4, deriv=1, delta=1 / RATE, pos=4, use="conv")
            datas = [c.data for c in chunks]

            def run_lfilter(b=b, datas=datas, shape=shape) -> None:
                zi = np.zeros((4, *shape))
                for d in datas:
                    _, zi = signal.lfilter(b, [1.0], d, axis=0, zi=zi)

            base = f"lfilter+zi, {case}"
            params = {"channels": channels, "chunk": chunk}
            ctx.speed(base, run_lfilter, n, "samples/s", is_baseline=True, reference=True, params=params)
            for mode in ("causal", "centred"):
                block = SavGol(window=5, order=4, deriv=1, mode=mode)
                block.bind({"x": StreamSpec(shape=shape, units="N", rate_hz=RATE)})

                def run(block=block, chunks=chunks) -> None:
                    block.restart()
                    for c in chunks:
                        block(x=c)

                fig = ctx.speed(f"block {mode}, {case}", run, n, "samples/s", baseline=base,
                                params={**params, "mode": mode})  # fmt: skip
                if chunk == 1000:
                    ctx.check(f"{mode}, {case}: >= 4e7 samples/s", fig.median >= BAR_SAMPLES_PER_S,
                              f"{fig.median:.3g} samples/s")  # fmt: skip


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


def noisy_force(sigma: float = 0.01, duration_s: float = 10.0) -> tuple[np.ndarray, ...]:
    """Times, the clean force, its F' and F'', and the force plus white noise of ``sigma`` N (seeded)."""
    rng = np.random.default_rng(11)
    n = int(duration_s * RATE)
    t = np.arange(n) / RATE
    force, d1, d2 = tactile_force(t, rng.uniform(0, 2 * math.pi, len(_FREQS_HZ)))
    return t, force, d1, d2, force + rng.normal(0.0, sigma, n)


def error_table(quick: bool, sigma: float = 0.01, duration_s: float = 10.0) -> list[dict]:
    t, force, d1, d2, noisy = noisy_force(sigma, duration_s)
    n = len(t)
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


def error_rows(rows: list[dict]) -> list[list]:
    return [
        [f"{r['window']}/{r['order']}", r["mode"], r["d1_latency"], r["d1_rms"], r["d1_noise_pred"], r["d1_bias_rms"],
         r["d2_latency"], r["d2_rms"], r["d2_noise_pred"], r["d2_bias_rms"]]
        for r in rows
    ]  # fmt: skip


def draw_errors(rows: list[dict]):
    def draw(fig) -> None:  # type: ignore[no-untyped-def]
        axes = fig.subplots(1, 2)
        fig.set_size_inches(11, 4.2)
        for ax, d, unit in ((axes[0], 1, "N/s"), (axes[1], 2, "N/s²")):
            for mode, marker in (("centred", "o"), ("causal", "s")):
                for order, color in ((2, "C0"), (3, "C1"), (4, "C2")):
                    sel = [r for r in rows if r["mode"] == mode and r["order"] == order]
                    if sel:
                        ax.plot([r[f"d{d}_latency"] for r in sel], [r[f"d{d}_rms"] for r in sel], marker=marker,
                                color=color, linestyle="-" if mode == "centred" else "--",
                                label=f"order {order}, {mode}")  # fmt: skip
            for r in rows:
                if r["mode"] == "centred" and r["order"] == 2:
                    ax.annotate(f"N={r['window']}", (r[f"d{d}_latency"], r[f"d{d}_rms"]), fontsize=7,
                                textcoords="offset points", xytext=(3, -10))  # fmt: skip
            ax.axhline(rows[0][f"true_rms_d{d}"], color="k", lw=0.8, ls=":", label="true RMS of the signal")
            ax.set_yscale("log")
            ax.set_xlabel("effective latency (samples at 1 kHz)")
            ax.set_ylabel(f"RMS error ({unit})")
            ax.set_title(
                ("F'" if d == 1 else "F''") + " — σ = 0.01 N (causal: all at latency 0)", fontsize=10
            )
            ax.grid(True, which="both", alpha=0.3)
        axes[0].legend(fontsize=7)

    return draw


# -- (3) cost vs error vs group delay; scipy.signal.savgol_filter side by side ----------------------

#: The paper's filter (Rager et al.): window 5, order 4. The shipped graphs (touch.yaml, slip.yaml)
#: run it causal; the block's default mode is centred.
PAPER_SETTING = (5, 4)
SHIPPED_MODE = "causal"


def sweep(ctx: Context, rows: list[dict], sigma: float = 0.01, duration_s: float = 10.0) -> list[dict]:
    """Per (window, order, mode) of ``rows``: µs per sample of F' through the block (the whole run
    in one chunk, then flush), and scipy on the same data in the same run (centred:
    ``savgol_filter``; causal: ``savgol_coeffs(pos=N−1)`` through ``lfilter``): its time (the
    baseline) and its largest difference from the block's output."""
    from scipy import signal

    from flowtact.bench.agreement import EPS, fir_agreement

    t, _, _, _, noisy = noisy_force(sigma, duration_s)
    n = len(t)
    chunk = Chunk(t, noisy)
    repeats = 3 * ctx.repeats  # a run is ~0.1 ms: cheap, and noisy on a shared machine
    out = []
    for r in rows:
        window, order, mode = r["window"], r["order"], r["mode"]
        setting = f"{window}/{order} {mode}"
        block = SavGol(window=window, order=order, deriv=1, mode=mode)
        block.bind({"x": StreamSpec(units="N", rate_hz=RATE)})

        def through_block(block=block) -> np.ndarray:
            block.restart()
            y = block(x=chunk)["y"].data
            tail = block.flush().get("y")
            return np.concatenate([y, tail.data]) if tail else y

        params = {"window": window, "order": order, "mode": mode}
        row = {**params, "d1_rms": r["d1_rms"], "group_delay_ms": r["d1_latency"] / RATE * 1e3}
        pos = (window - 1) // 2 if mode == "centred" else window - 1
        sp_coef = signal.savgol_coeffs(window, order, deriv=1, delta=1 / RATE, pos=pos, use="dot")
        if mode == "centred":

            def with_scipy(window=window, order=order) -> np.ndarray:
                return signal.savgol_filter(noisy, window, order, deriv=1, delta=1 / RATE, mode="constant")

            base = f"savgol_filter, {setting}"
        else:  # scipy has no causal savgol_filter: its causal coefficients through lfilter (zero initial state)
            b_causal = sp_coef[::-1].copy()  # lfilter's taps: newest sample first

            def with_scipy(b=b_causal) -> np.ndarray:
                return signal.lfilter(b, [1.0], noisy)

            base = f"savgol_coeffs(pos=N-1) + lfilter, {setting}"
        sp = ctx.duration(base, with_scipy, scale=1e6 / n, unit="µs per sample", is_baseline=True, reference=True,
                          params=params, repeats=repeats)  # fmt: skip
        coef = savgol_coeffs(window, order, 1, pos=pos, rate_hz=RATE)
        agree = fir_agreement(through_block(), with_scipy(), coef, noisy, pos)
        coef_eps = float(np.max(np.abs(sp_coef - coef)) / (EPS * np.max(np.abs(coef))))
        row.update(scipy_us=sp.median, agree_max_abs=agree["max_abs"], agree_eps=agree["eps_units"],
                   scipy_coef_eps=coef_eps)  # fmt: skip
        fig = ctx.duration(f"block, {setting}", through_block, scale=1e6 / n, unit="µs per sample",
                           baseline=base, params=params, repeats=repeats)  # fmt: skip
        row["block_us"] = fig.median
        row["ratio"] = fig.ratio
        out.append(row)
    return out


def draw_sweep(rows: list[dict]):
    """Cost against F' RMSE, colour = group delay, the paper's 5/4 starred, scipy beside the centred points."""

    def draw(fig) -> None:  # type: ignore[no-untyped-def]
        import matplotlib as mpl

        ax = fig.add_subplot(1, 1, 1)
        fig.set_size_inches(9, 5.2)
        delays = [r["group_delay_ms"] for r in rows]
        norm = mpl.colors.Normalize(vmin=min(delays), vmax=max(delays))
        for mode, marker in (("centred", "o"), ("causal", "s")):
            sel = [r for r in rows if r["mode"] == mode]
            sc = ax.scatter([r["block_us"] * 1e3 for r in sel], [r["d1_rms"] for r in sel], c=[r["group_delay_ms"] for r in sel],
                            cmap="viridis", norm=norm, marker=marker, s=46, edgecolors="k", linewidths=0.4,
                            label=f"flowtact savgol, {mode}", zorder=3)  # fmt: skip
        for mode, marker, what in (
            ("centred", "x", "savgol_filter (centred)"),
            ("causal", "+", "lfilter (causal)"),
        ):
            sp = [r for r in rows if r["mode"] == mode]
            ax.scatter([r["scipy_us"] * 1e3 for r in sp], [r["d1_rms"] for r in sp], marker=marker, color="0.45", s=34,
                       label=f"scipy {what}", zorder=2)  # fmt: skip
        labels = []
        for r in rows:
            paper = (r["window"], r["order"]) == PAPER_SETTING
            shipped = paper and r["mode"] == SHIPPED_MODE
            text = f"{r['window']}/{r['order']}" + ("" if r["mode"] == "centred" else " c")
            if paper:
                ax.plot([r["block_us"] * 1e3], [r["d1_rms"]], "*", ms=18 if shipped else 14, mfc="none",
                        mec="r" if shipped else "k", mew=1.5, zorder=4)  # fmt: skip
                text += ": shipped (touch/slip.yaml)" if shipped else ": block default"
            labels.append(PointLabel(r["block_us"] * 1e3, r["d1_rms"], text, bold=paper))
        fig.colorbar(sc, ax=ax, label="group delay of F' (ms at 1 kHz; causal F': 0)")
        ax.set_yscale("log")
        ax.set_xlabel("cost (ns per sample, 10 s at 1 kHz in one chunk, one core)")
        ax.set_ylabel("F' RMS error vs analytic (N/s)")
        ax.set_title("Savitzky–Golay F': cost vs error vs group delay (σ = 0.01 N)", fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, loc="upper right")
        fig.tight_layout()  # labels are placed against the final layout
        label_points(ax, labels)

    return draw


def report_sweep(ctx: Context, rows: list[dict]) -> None:
    ctx.data["sweep"] = rows
    ctx.table(
        "F' (σ = 0.01 N, 10 s at 1 kHz): cost through the block vs scipy on the same data (savgol_filter centred, "
        "lfilter causal)",
        ["N/p", "mode", "group delay (ms)", "F' RMS err (N/s)", "block µs/sample", "scipy µs/sample",
         "speed ratio (>1: block faster)", "max |block − scipy| (N/s)", "… in eps·Σ|c·x|", "scipy coef err (eps·max|c|)"],
        [[f"{r['window']}/{r['order']}", r["mode"], r["group_delay_ms"], r["d1_rms"], r["block_us"],
          r.get("scipy_us", "—"), r["ratio"] if r["ratio"] is not None else "—",
          r.get("agree_max_abs", "—"), r.get("agree_eps", "—"), r.get("scipy_coef_eps", "—")] for r in rows],
        "scipy's savgol_filter has no causal mode: causal rows compare with scipy's causal coefficients "
        "(savgol_coeffs(pos=N−1)) through lfilter. Agreement: the block's output over the whole run (flush included, "
        "zero padding) against scipy's (savgol_filter(mode='constant') centred); "
        "eps·Σ|c·x| is the float64 rounding scale of each output's dot product. The block's coefficients are the "
        "correctly rounded exact least-squares weights; scipy's come from a float lstsq and differ from them by the "
        "last column (in eps of the largest weight), which accounts for the larger disagreements.",
    )  # fmt: skip
    ctx.plot("cost_vs_error", draw_sweep(rows), "Savitzky–Golay F': µs per sample against RMS error, colour = group "
             "delay; the paper's 5/4 starred (red: causal, as shipped in touch.yaml/slip.yaml); grey × and +: scipy")  # fmt: skip
    worst = max(rows, key=lambda r: r["agree_eps"] / (100 + 3 * r["scipy_coef_eps"]))
    ctx.check("block == scipy within 100 + 3 × scipy's coefficient error, in eps·Σ|c·x| (every setting)",
              worst["agree_eps"] <= 100 + 3 * worst["scipy_coef_eps"],
              f"tightest {worst['agree_eps']:.3g} (coef err {worst['scipy_coef_eps']:.3g}) at "
              f"{worst['window']}/{worst['order']} {worst['mode']}; a different filter is ~1e10")  # fmt: skip
    shipped = next(r for r in rows if (r["window"], r["order"], r["mode"]) == (*PAPER_SETTING, SHIPPED_MODE))
    best = min((r for r in rows if r["mode"] == "causal"), key=lambda r: r["d1_rms"])
    ctx.note(f"The shipped F' filter (5/4 causal, touch.yaml/slip.yaml) has the largest error of this sweep: "
             f"{shipped['d1_rms']:.3g} N/s RMS at σ = 0.01 N, against {best['d1_rms']:.3g} N/s for "
             f"{best['window']}/{best['order']} causal at the same zero group delay and "
             f"a speed-up of {shipped['block_us'] / best['block_us']:.2g} against it (> 1: faster); the graphs use 5/4 "
             "because it is the paper's filter.")  # fmt: skip
    slower = [
        f"{r['window']}/{r['order']} {r['mode']} (speed-up {r['ratio']:.2f})"
        for r in rows
        if r["ratio"] is not None and r["ratio"] < 1
    ]
    if slower:
        ctx.note("The block (one chunk + flush) is slower than scipy on the whole array for "
                 f"{', '.join(slower)}; the block streams (state, time stamps, bad-data screen), scipy does not.")  # fmt: skip


def run(ctx: Context) -> None:
    throughput(ctx)
    ctx.step("error vs latency")
    rows = error_table(ctx.quick)
    ctx.data["error_vs_latency"] = rows
    ctx.table(
        f"RMS error vs latency, σ = 0.01 N, 10 s at 1 kHz; true RMS F' = {rows[0]['true_rms_d1']:.2f} N/s, "
        f"F'' = {rows[0]['true_rms_d2']:.0f} N/s²",
        ["N/p", "mode", "F' lat (samples)", "F' RMS err (N/s)", "F' σ‖c‖", "F' bias", "F'' lat", "F'' RMS err (N/s²)",
         "F'' σ‖c‖", "F'' bias"],
        error_rows(rows),
        "lat: effective latency in samples; err: RMS error; σ‖c‖: predicted noise; bias: error without noise. "
        "The paper's 5/4 filter is exact interpolation, so its F' is noise-dominated and F'' pure noise.",
    )  # fmt: skip
    ctx.plot(
        "error_vs_latency", draw_errors(rows), "Savitzky–Golay F' and F'' RMS error against effective latency"
    )
    ctx.step("cost vs error vs scipy")
    report_sweep(ctx, sweep(ctx, rows))


SUITE = Suite(
    name="savgol",
    title="Savitzky–Golay block: throughput, and derivative error vs latency",
    measures="Samples/s of the 5/4 first derivative through `SavGol.__call__` for chunks of 1 … 10 000 "
    "samples (1 and 3 channels, causal and centred), and the RMS error of F' and F'' against latency for "
    "windows 5…21 × orders 2…4 on a noisy known force (NUMERICS §1.3); per window × order × mode, µs per "
    "sample against F' RMS error and group delay, side by side with `scipy.signal.savgol_filter` (speed ratio, "
    "and its largest difference from the block in float64 rounding units).",
    baseline="`scipy.signal.lfilter` with `zi` running the same causal filter on the same chunks (throughput); "
    "`scipy.signal.savgol_filter` on the same whole run (cost vs error)",
    run=run,
    needs=("scipy",),
    minutes_quick=0.2,
    minutes_full=1.0,
)
