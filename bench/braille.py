"""Suite ``braille``: how well the Braille pathway reads (Bologna et al. 2013), open and closed loop.

* Models: trained here exactly as ``flowtact train-braille`` does by default (graph seeds 1–3,
  260 random letters at 15, 30 and 60 mm/s, counts in 2 time-normalised sub-bins), one per layer
  (24 first-order afferents, 49 cuneate neurons), from the same simulated runs.
* Held-out text: permutations of the alphabet drawn from seed ``HELDOUT_SEED`` (each letter equally
  often), read with graph seeds from ``HELDOUT_SEED`` up, which training refuses: nothing here is
  tuned on it (the controller's setting was chosen on a validation text, seed 500).
* Recognition rate against constant speed (10–80 mm/s, the target range, and on to 300 mm/s with
  the scan's speed limit raised, where reading starts to fail), per letter and the confusion matrix at 30 mm/s;
  robustness to a lateral (±Y) offset at 30 mm/s (models trained on centred lines).
* Information (the paper's Fig. 4A): spike counts per neuron in windows growing from the moment
  the leading taxels reach a cell; the information a cross-validated decoder's confusion matrix
  carries about the letter, bias removed by quadratic extrapolation, 40 trials per letter
  (``braille_metrics``; the estimator's floor, with the letters shuffled, is drawn too).
* Closed loop (graphs/braille.yaml with this run's first-order model): mean reading speed (distance
  over time) and recognition rate, against the constant-speed curve.
"""

from __future__ import annotations

import math
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from flowtact.bench.braille_metrics import confusion, entropy_bits, mi_corrected
from flowtact.benchmark import Context, Suite
from flowtact.blocks.braille.cells import LETTERS
from flowtact.blocks.braille.reading import read_line
from flowtact.blocks.braille.train_braille import HELDOUT_SEED, train_layers
from flowtact.blocks.spiking.nb_model import log_posterior, save_model
from flowtact.blocks.spiking.window_features import window_features

LAYER_NAMES = {"first": "first order (24 afferents)", "second": "second order (49 cuneate)"}
#: Constant speeds beyond 80 mm/s run with the scan's limit raised to this (its default is 100).
FAST_LIMIT_MM_S = 400.0
#: A moderate controller setting within the scan's default 100 mm/s, for comparison.
MODERATE = {
    "min_speed_mm_s": 40.0,
    "max_speed_mm_s": 100.0,
    "unsure": 0.5,
    "sure": 0.99,
    "max_accel_mm_s2": 2000.0,
}
QUICK = {
    "speeds": (10.0, 30.0, 80.0, 150.0, 200.0, 250.0, 300.0),
    "reps": 2,
    "offsets": (-2.0, -1.0, 0.0, 1.0, 2.0),
    "offset_reps": 1,
    "loop_reps": 2,
    "mi_reps": 10,
    "loop_settings": ({}, MODERATE),
}
FULL = {
    "speeds": (10.0, 15.0, 20.0, 30.0, 40.0, 50.0, 60.0, 80.0, 100.0, 150.0, 200.0, 250.0, 300.0),
    "reps": 10,
    "offsets": (-2.0, -1.5, -1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 2.0),
    "offset_reps": 2,
    "loop_reps": 4,
    "mi_reps": 40,
    "loop_settings": (
        {},
        MODERATE,
        {"min_speed_mm_s": 150.0},
        {"unsure": 0.1, "sure": 0.9},
        {"max_speed_mm_s": 250.0},
    ),
}
#: Leading taxel column edge ahead of the finger centre, plus a dot radius (mm): where a cell's first
#: dots start to press on the array before its character window opens (``braille_scan``'s geometry).
LEAD_MM = 3.8 + 1.275


def heldout_text(reps: int) -> str:
    """``reps`` permutations of the alphabet from the held-out seed."""
    rng = np.random.default_rng(HELDOUT_SEED)
    return "".join("".join(rng.permutation(list(LETTERS))) for _ in range(reps))


def _decide(model: Any, spikes: tuple[np.ndarray, np.ndarray], windows: np.ndarray) -> np.ndarray:
    t, u = spikes
    x = window_features(t, u, windows, n_units=model.n_units, n_bins=model.n_bins, kind=model.features)
    return np.argmax(log_posterior(model, x), axis=1)


def _labels(letters: tuple[str, ...]) -> np.ndarray:
    return np.array([LETTERS.index(c) for c in letters], np.int64)


def run(ctx: Context) -> None:
    cfg = QUICK if ctx.quick else FULL
    ctx.step("training (3 runs)")
    trained = train_layers(layers=("first", "second"))
    models = {k: m for k, (m, _) in trained.items()}
    ctx.data["training"] = {k: p for k, (_, p) in trained.items()}
    for k, (_, p) in trained.items():
        ctx.note(
            f"Model {k}: {p['windows']} training windows, training accuracy {p['training_accuracy']:.1%}, "
            f"running temperature {p['running_temperature']:.3f}."
        )
    text = heldout_text(cfg["reps"])
    curve, at30 = _constant_speeds(ctx, cfg, models, text)
    _per_letter(ctx, at30)
    _information(ctx, cfg)
    _offsets(ctx, cfg, models)
    with tempfile.TemporaryDirectory(prefix="flowtact-braille-") as tmp:
        model_path = save_model(Path(tmp) / "first.npz", models["first"], ctx.data["training"]["first"])
        _closed_loop(ctx, cfg, model_path, curve)


def _constant_speeds(
    ctx: Context, cfg: dict[str, Any], models: dict[str, Any], text: str
) -> tuple[dict[str, list[tuple[float, float]]], dict[str, Any]]:
    curve: dict[str, list[tuple[float, float]]] = {"first": [], "second": []}
    at30: dict[str, Any] = {}
    rows = []
    for i, v in enumerate(cfg["speeds"]):
        ctx.step(f"constant {v:g} mm/s")
        r = read_line(
            seed=HELDOUT_SEED + i,
            speed_mm_s=v,
            text=text,
            params={"scan": {"max_speed_mm_s": FAST_LIMIT_MM_S}},
        )
        y = _labels(r.letters)
        row: list[Any] = [f"{v:g}", len(y)]
        for layer, m in models.items():
            pred = _decide(m, r.spikes[layer], r.windows)
            acc = float(np.mean(pred == y))
            curve[layer].append((v, acc))
            row.append(f"{acc:.1%}")
            ctx.figure(f"recognition {layer} at {v:g} mm/s", acc * 100.0, "%", "higher")
            if v == 30.0:
                at30[layer] = {"pred": pred, "true": y}
        if v == 30.0:
            at30["reading"] = r
        rows.append(row)
    ctx.table(
        "Recognition rate of held-out letters at constant speed",
        ["speed (mm/s)", "letters", "first order", "second order"],
        rows,
    )
    ctx.data["constant"] = curve

    def draw(fig: Any) -> None:
        ax = fig.add_subplot(1, 1, 1)
        for layer, pts in curve.items():
            v, a = zip(*pts, strict=True)
            ax.plot(v, np.array(a) * 100, "o-", label=LAYER_NAMES[layer])
        ax.axhline(98, color="0.5", ls=":", lw=1, label="98 % (the bar)")
        ax.axvspan(10, 80, color="0.93", zorder=0, label="10–80 mm/s (the target range)")
        ax.set_xscale("log")
        ax.set_xticks([10, 20, 30, 50, 80, 150, 300], ["10", "20", "30", "50", "80", "150", "300"])
        ax.set_xlabel("scanning speed (mm/s, log scale)")
        ax.set_ylabel("letters recognised (%)")
        ax.set_ylim(0, 102)
        ax.legend(loc="lower left")
        ax.grid(alpha=0.3)

    ctx.plot("recognition_vs_speed", draw, "Recognition of held-out letters against constant scanning speed")
    if "first" in at30:
        acc = float(np.mean(at30["first"]["pred"] == at30["first"]["true"]))
        n = len(at30["first"]["true"])
        ctx.check(
            "26 letters recognised >= 98 % at 30 mm/s (first order, held-out text)",
            acc >= 0.98,
            f"{acc:.1%} of {n} letters (second order: "
            f"{float(np.mean(at30['second']['pred'] == at30['second']['true'])):.1%})",
        )
    return curve, at30


def _per_letter(ctx: Context, at30: dict[str, Any]) -> None:
    if "first" not in at30:
        return
    mats = {k: confusion(at30[k]["true"], at30[k]["pred"], 26) for k in ("first", "second")}
    rows = []
    for i, c in enumerate(LETTERS):
        rows.append([c, *(f"{m[i, i] / max(m[i].sum(), 1):.0%}" for m in mats.values())])
    ctx.table("Per-letter recognition at 30 mm/s", ["letter", "first order", "second order"], rows)
    ctx.data["confusion at 30 mm/s"] = {k: m.tolist() for k, m in mats.items()}

    def draw(fig: Any) -> None:
        grid = fig.add_gridspec(1, 3, width_ratios=[1, 1, 0.05])
        for j, (layer, m) in enumerate(mats.items()):
            ax = fig.add_subplot(grid[0, j])
            frac = m / np.maximum(m.sum(axis=1, keepdims=True), 1)
            im = ax.imshow(frac * 100, cmap="Blues", vmin=0, vmax=100)
            ax.set_xticks(range(26), list(LETTERS), fontsize=6)
            ax.set_yticks(range(26), list(LETTERS), fontsize=6)
            ax.set_xlabel("decided letter")
            ax.set_ylabel("letter read")
            ax.set_title(f"{LAYER_NAMES[layer]}: {np.trace(m) / m.sum():.1%}", fontsize=9)
        fig.colorbar(im, cax=fig.add_subplot(grid[0, 2]), label="% of the letter's trials")

    ctx.plot("confusion_30", draw, "Confusion matrices at 30 mm/s, held-out text (rows: letter read)")


def _information(ctx: Context, cfg: dict[str, Any]) -> None:
    ctx.step("information: reading")
    r = read_line(seed=HELDOUT_SEED + 300, speed_mm_s=30.0, text=heldout_text(cfg["mi_reps"]))
    y = _labels(r.letters)
    lead = LEAD_MM / 30.0
    onsets = r.windows[:, 0] - lead
    span = float(np.median(r.windows[:, 1] - r.windows[:, 0])) + 2 * lead
    ts = np.arange(0.02, span + 1e-9, 0.02)
    h_s = entropy_bits(np.bincount(y, minlength=26))
    mi: dict[str, list[float]] = {}
    floor: dict[str, list[float]] = {}
    for layer in ("first", "second"):
        ctx.step(f"information, {layer} order")
        t, u = r.spikes[layer]
        vals, zero = [], []
        for T in ts:
            x = window_features(t, u, np.column_stack([onsets, onsets + T]), n_units=r.n_units[layer])
            vals.append(mi_corrected(x, y, 26)[0])
            zero.append(mi_corrected(x, y, 26, shuffle=True)[0])
        mi[layer], floor[layer] = vals, zero
    ctx.data["information"] = {"t_s": ts.tolist(), "H(S)": h_s, **mi, "floor": floor}
    window = float(np.median(r.windows[:, 1] - r.windows[:, 0]))

    def draw(fig: Any) -> None:
        for j, layer in enumerate(("first", "second")):
            ax = fig.add_subplot(1, 2, j + 1)
            ax.plot(ts * 1e3, mi[layer], "-", color="C0", label="information I(S;R)")
            ax.plot(ts * 1e3, h_s - np.array(mi[layer]), "--", color="C3", label="conditional entropy H(S|R)")
            ax.plot(ts * 1e3, floor[layer], ":", color="0.4", label="estimator floor (letters shuffled)")
            ax.axvspan(lead * 1e3, (lead + window) * 1e3, color="0.9", label="character window")
            ax.set_xlabel("time since the cell reaches the taxels (ms)")
            ax.set_ylabel("bits")
            ax.axhline(h_s, color="0.6", lw=0.8)
            ax.annotate(f"H(S) = {h_s:.2f} bits", (ts[0] * 1e3, h_s), xytext=(0, 3), textcoords="offset points",
                        fontsize=7, color="0.4")  # fmt: skip
            ax.set_yticks(range(int(h_s) + 1))
            ax.set_ylim(0, h_s * 1.6)  # headroom above H(S) for the legend
            ax.set_title(LAYER_NAMES[layer], fontsize=9)
            if j == 0:  # one legend serves both panels
                ax.legend(loc="upper right", fontsize=7)

    ctx.plot(
        "information_30",
        draw,
        f"Information about the letter in spike counts of growing windows at 30 mm/s ({len(y)} trials, "
        f"H(S) = {h_s:.2f} bits; 5-fold cross-validated decoder, bias removed by quadratic extrapolation)",
    )
    ctx.table(
        "Information at the end of the character window (30 mm/s)",
        ["layer", "I(S;R) (bits)", "of H(S)"],
        [
            [
                LAYER_NAMES[k],
                f"{np.interp(lead + window, ts, mi[k]):.2f}",
                f"{np.interp(lead + window, ts, mi[k]) / h_s:.0%}",
            ]
            for k in mi
        ],
    )


def _offsets(ctx: Context, cfg: dict[str, Any], models: dict[str, Any]) -> None:
    text = heldout_text(cfg["offset_reps"])
    res: dict[str, list[float]] = {"first": [], "second": []}
    for i, dy in enumerate(cfg["offsets"]):
        ctx.step(f"offset {dy:+g} mm")
        r = read_line(
            seed=HELDOUT_SEED + 100 + i, speed_mm_s=30.0, text=text, params={"scan": {"y_offset_mm": dy}}
        )
        y = _labels(r.letters)
        for layer, m in models.items():
            res[layer].append(float(np.mean(_decide(m, r.spikes[layer], r.windows) == y)))
    ctx.data["offsets"] = {"offset_mm": list(cfg["offsets"]), **res}
    ctx.table(
        "Recognition at 30 mm/s with the finger off the line's centre (±Y)",
        ["offset (mm)", "first order", "second order"],
        [
            [f"{dy:+g}", f"{a:.0%}", f"{b:.0%}"]
            for dy, a, b in zip(cfg["offsets"], res["first"], res["second"], strict=True)
        ],
        note=f"{len(text)} letters per offset; models trained on centred lines.",
    )

    def draw(fig: Any) -> None:
        ax = fig.add_subplot(1, 1, 1)
        for layer, a in res.items():
            ax.plot(cfg["offsets"], np.array(a) * 100, "o-", label=LAYER_NAMES[layer])
        ax.set_xlabel("lateral offset of the finger (mm)")
        ax.set_ylabel("letters recognised (%)")
        ax.set_ylim(0, 102)
        ax.legend(loc="center")
        ax.grid(alpha=0.3)

    ctx.plot("offsets_30", draw, "Robustness to a lateral (±Y) position error at 30 mm/s")


def _fastest_constant(curve: list[tuple[float, float]], accuracy: float) -> float:
    """The fastest speed on the piecewise-linear constant-speed curve still reaching ``accuracy``."""
    v, a = (np.array(x) for x in zip(*curve, strict=True))
    fine = np.linspace(v[0], v[-1], 2000)
    ok = fine[np.interp(fine, v, a) >= accuracy - 1e-12]
    return float(ok.max()) if len(ok) else math.nan


def shipped_control() -> dict[str, Any]:
    """The controller parameters graphs/braille.yaml ships (what the check holds to the bar)."""
    from flowtact.graphfile.graph import resolve_graph_path

    doc = yaml.safe_load(resolve_graph_path("braille").read_text())
    return dict(doc["nodes"]["control"]["params"])


def _up_to(v: float, curve: list[tuple[float, float]]) -> str:
    top = max(p[0] for p in curve)
    return f"{v:.1f} mm/s" + (" (the fastest tested: at least)" if v >= top else "")


def _closed_loop(
    ctx: Context, cfg: dict[str, Any], model: Path, curve: dict[str, list[tuple[float, float]]]
) -> None:
    text = heldout_text(cfg["loop_reps"])
    pts = []
    for i, change in enumerate(cfg["loop_settings"]):
        setting = {**shipped_control(), **change}
        ctx.step(f"closed loop {i + 1}/{len(cfg['loop_settings'])}")
        r = read_line(
            "braille",
            seed=HELDOUT_SEED + 200,
            text=text,
            layers=("first",),
            tick_s=0,
            params={
                "control": setting,
                "decoder": {"model": str(model)},
                "scan": {
                    "min_speed_mm_s": setting["min_speed_mm_s"],
                    "max_speed_mm_s": setting["max_speed_mm_s"],
                },
            },
            extra=["decoder.decision", "scan.position"],
        )
        dec = np.asarray(r.streams["decoder.decision"].data, np.int64)
        y = _labels(r.letters)
        n = min(len(dec), len(y))
        acc = float(np.mean(dec[:n] == y[:n])) if n else 0.0
        pos = r.streams["scan.position"]
        speed = float((pos.data[-1] - pos.data[0]) / (pos.t[-1] - pos.t[0]))
        pts.append((setting, speed, acc, n))
    shipped = pts[0]
    best = _fastest_constant(curve["first"], shipped[2])
    ctx.figure("closed loop reading speed", shipped[1], "mm/s", "higher")
    ctx.figure("closed loop recognition", shipped[2] * 100, "%", "higher")
    ctx.check(
        "closed loop reads faster than the fastest constant speed of equal accuracy",
        bool(shipped[1] > best) if math.isfinite(best) else True,
        f"closed loop {shipped[1]:.1f} mm/s at {shipped[2]:.1%} ({shipped[3]} letters); constant speed "
        + (
            f"reaches that accuracy up to {_up_to(best, curve['first'])}"
            if math.isfinite(best)
            else "never reaches it"
        ),
    )
    ctx.table(
        "Closed loop (graphs/braille.yaml) on held-out text: controller settings",
        [
            "min–max (mm/s)",
            "unsure / sure",
            "mean speed (mm/s)",
            "recognised",
            "letters",
            "constant speed of equal accuracy",
        ],
        [
            [
                f"{s['min_speed_mm_s']:g}–{s['max_speed_mm_s']:g}",
                f"{s['unsure']:g} / {s['sure']:g}",
                f"{v:.1f}",
                f"{a:.1%}",
                n,
                f"up to {_up_to(_fastest_constant(curve['first'], a), curve['first'])}",
            ]
            for s, v, a, n in pts
        ],
        note="first row: the graph's setting (the check); the others show the trade-off.",
    )
    ctx.data["closed loop"] = [
        {"setting": s, "speed_mm_s": v, "accuracy": a, "letters": n} for s, v, a, n in pts
    ]

    def draw(fig: Any) -> None:
        ax = fig.add_subplot(1, 1, 1)
        v, a = zip(*curve["first"], strict=True)
        ax.plot(v, np.array(a) * 100, "o-", color="C0", label="constant speed (first order)")
        for k, (s, sp, acc, _) in enumerate(pts):
            style = (
                {"marker": "*", "ms": 14, "color": "C3"}
                if k == 0
                else {"marker": "s", "ms": 6, "color": "C1"}
            )
            ax.plot(
                [sp], [acc * 100], ls="none", **style, label="closed loop (graph setting)" if k == 0 else None
            )
            ax.annotate(f"{s['min_speed_mm_s']:g}–{s['max_speed_mm_s']:g}, sure {s['sure']:g}", (sp, acc * 100),
                        textcoords="offset points", xytext=(6, -10), fontsize=7)  # fmt: skip
        ax.plot([], [], "s", color="C1", label="closed loop (other settings)")
        ax.set_xlabel("mean reading speed (mm/s)")
        ax.set_ylabel("letters recognised (%)")
        ax.set_ylim(min(50.0, min(p[2] * 100 for p in pts) - 5), 102)
        ax.legend(loc="lower left")
        ax.grid(alpha=0.3)

    ctx.plot(
        "closed_loop", draw, "Closed-loop reading: mean speed and accuracy against the constant-speed curve"
    )


SUITE = Suite(
    name="braille",
    title="Braille reading (Bologna et al. 2013): recognition, information, robustness, closed loop",
    measures=__doc__.split("\n\n", 1)[1] if __doc__ else "",
    baseline="constant-speed reading of the same held-out text (recognition rates are absolute; the paper: "
    "89 % at 30 mm/s; the bar: ≥ 98 %)",
    run=run,
    needs=("matplotlib",),
    minutes_quick=0.8,
    minutes_full=5.0,
    processes=(1, 1),  # recognition and reading speed: the same in every process, no timing ratios
)
