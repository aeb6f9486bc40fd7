"""Recognition against constant speed on the varying fingertip: the calibration curve of docs/braille.md.

Trains both layers' decoders by ``flowtact train-braille``'s default recipe on the open-loop graph
(graph seeds 1–3, 260 random letters at 15, 30 and 60 mm/s; the graph's fingertip variation on),
then reads held-out text (permutations of the alphabet from the benchmark's held-out seed, graph
seeds from 100 000 up, never used in training) at each constant speed and prints the share of
letters each layer's decoder recognises (first order: 24 afferents, second: 49 cuneate neurons).

    python scripts/braille_fingertip_curve.py --reps 10 --plot curve.png
    python scripts/braille_fingertip_curve.py --set scan.lateral_sd_mm=0.3   # a variation changed
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from typing import Any

import numpy as np
import yaml

from flowtact.blocks.braille.cells import LETTERS
from flowtact.blocks.braille.reading import read_line
from flowtact.blocks.braille.train_braille import HELDOUT_SEED, train_layers
from flowtact.blocks.spiking.nb_model import log_posterior
from flowtact.blocks.spiking.window_features import window_features

SPEEDS = (10.0, 20.0, 30.0, 40.0, 60.0, 80.0)


def heldout_text(reps: int) -> str:
    """``reps`` permutations of the alphabet from the held-out seed (as the benchmark draws them)."""
    rng = np.random.default_rng(HELDOUT_SEED)
    return "".join("".join(rng.permutation(list(LETTERS))) for _ in range(reps))


def decide(model: Any, spikes: tuple[np.ndarray, np.ndarray], windows: np.ndarray) -> np.ndarray:
    t, u = spikes
    x = window_features(t, u, windows, n_units=model.n_units, n_bins=model.n_bins, kind=model.features)
    return np.argmax(log_posterior(model, x), axis=1)


def overrides(items: list[str]) -> dict[str, dict[str, Any]]:
    out: dict[str, dict[str, Any]] = {}
    for item in items:
        key, _, value = item.partition("=")
        node, _, param = key.partition(".")
        if not param or not value:
            raise SystemExit(f"--set {item}: expected NODE.PARAM=VALUE")
        out.setdefault(node, {})[param] = yaml.safe_load(value)
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument(
        "--reps", type=int, default=10, help="alphabets of held-out text per speed (26 letters each)"
    )
    p.add_argument("--speeds", type=float, nargs="+", default=list(SPEEDS))
    p.add_argument("--set", action="append", default=[], metavar="NODE.PARAM=VALUE", help="graph override")
    p.add_argument("--plot", help="draw the curve into this PNG")
    p.add_argument("--json", help="write the numbers here")
    a = p.parse_args(argv)
    params = overrides(a.set)
    graph = "braille_open"
    if params:  # training reads the graph file: write one with the overrides
        from flowtact.blocks.braille.reading import graph_text

        path, text = graph_text(graph, seed=1, params=params)
        graph = str(path.with_name(f".curve-{os.getpid()}.yaml"))
        with open(graph, "w") as f:
            f.write(text)
    try:
        trained = train_layers(graph=graph, layers=("first", "second"))
    finally:
        if params:
            os.unlink(graph)
    models = {k: m for k, (m, _) in trained.items()}
    text = heldout_text(a.reps)
    rows = []
    print(f"{'speed':>6} {'letters':>7} {'first':>7} {'second':>7}  (chance {1 / 26:.1%})")
    for i, v in enumerate(a.speeds):
        r = read_line(seed=HELDOUT_SEED + i, speed_mm_s=v, text=text, params=params)
        y = np.array([LETTERS.index(c) for c in r.letters])
        acc = {k: float(np.mean(decide(m, r.spikes[k], r.windows) == y)) for k, m in models.items()}
        rows.append({"speed_mm_s": v, "letters": len(y), **acc})
        print(f"{v:6g} {len(y):7d} {acc['first']:7.1%} {acc['second']:7.1%}", flush=True)
    train_acc = {k: p["training_accuracy"] for k, (_, p) in trained.items()}
    print("training accuracy:", ", ".join(f"{k} {v:.1%}" for k, v in train_acc.items()))
    print(f"load average: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"rows": rows, "training": train_acc, "params": params, "argv": sys.argv}, f, indent=1)
    if a.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(6, 4))
        v = [r["speed_mm_s"] for r in rows]
        for k, name in (("first", "first order (24 afferents)"), ("second", "second order (49 cuneate)")):
            acc = np.array([r[k] for r in rows])
            se = 100 * np.sqrt(acc * (1 - acc) / np.array([r["letters"] for r in rows]))  # binomial
            ax.errorbar(v, 100 * acc, yerr=se, fmt="o-", capsize=3, label=f"{name} (± 1 s.e.)")
        ax.plot([30], [89], "r*", ms=14, zorder=5, label="Bologna et al. 2012 abstract: 89 % at 30 mm/s")
        ax.axhline(100 / 26, color="0.5", ls=":", lw=1, label="chance (1/26)")
        ax.set_xlabel("constant scanning speed (mm/s)")
        ax.set_ylabel("held-out letters recognised (%)")
        ax.set_ylim(0, 102)
        ax.set_title(f"Varying fingertip, {rows[0]['letters']} held-out letters per speed", fontsize=10)
        ax.legend(loc="lower left", fontsize=8)
        ax.grid(alpha=0.3)
        fig.tight_layout()
        fig.savefig(a.plot, dpi=110)
    return 0


if __name__ == "__main__":
    sys.exit(main())
