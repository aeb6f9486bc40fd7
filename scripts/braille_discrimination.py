"""Sanity check of the Braille pathway's tuning: are the letters discriminable from spike counts?

Runs graphs/braille_open.yaml twice on random text (a training seed and a held-out seed), counts
each neuron's spikes in every character window (a run of equal non-gap ``scan.char`` values, see
docs/braille.md) and classifies the held-out windows by the nearest centroid of the training
windows of each letter, for the first-order (afferents) and the second-order (cuneate) spikes.
This is not the decoder (``naive_bayes``); it only shows the response carries the letter.

    python scripts/braille_discrimination.py --letters 520 --speed 30
"""

from __future__ import annotations

import argparse
import re
import sys
import tempfile
from pathlib import Path

import numpy as np

from flowtact.chunk import Chunk
from flowtact.testing import run_graph

GRAPH = Path(__file__).resolve().parent.parent / "graphs" / "braille_open.yaml"
LAYERS = ("afferents", "cuneate")


def windows(char: Chunk) -> list[tuple[float, float, int]]:
    """(start, end, category) of each run of equal non-gap ``char`` samples; end is one sample past."""
    c = np.asarray(char.data)
    t = np.asarray(char.t)
    dt = float(t[1] - t[0]) if len(t) > 1 else 0.0
    edges = np.flatnonzero(np.diff(c) != 0) + 1
    out = []
    for a, b in zip(np.r_[0, edges], np.r_[edges, len(c)], strict=True):
        if c[a] != 0:
            out.append((float(t[a]), float(t[b - 1]) + dt, int(c[a])))
    return out


def counts(spikes: Chunk, n_units: int, wins: list[tuple[float, float, int]]) -> np.ndarray:
    """(windows, units) spike counts of each unit in each window [start, end)."""
    out = np.zeros((len(wins), n_units))
    for i, (a, b, _) in enumerate(wins):
        sel = (spikes.t >= a - 1e-9) & (spikes.t < b - 1e-9)
        out[i] = np.bincount(np.asarray(spikes.data[sel], np.int64), minlength=n_units)
    return out


def run(seed: int, letters: int, speed: float, sets: list[str] = ()) -> dict[str, Chunk]:
    """One run of the open-loop graph on ``letters`` random letters, graph seed ``seed``."""
    text = re.sub(r"(?m)^seed: .*$", f"seed: {seed}", GRAPH.read_text())
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "braille_open.yaml"
        path.write_text(text)
        scan = ["scan.text=''", f"scan.random_letters={letters}", f"scan.speed_mm_s={speed}"]
        return run_graph(path, overrides=[*scan, *sets], tick_s=0.2)


def features(out: dict[str, Chunk]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    wins = windows(out["scan.char"])
    labels = np.array([w[2] for w in wins])
    return labels, {p: counts(out[f"{p}.spikes"], {"afferents": 24, "cuneate": 49}[p], wins) for p in LAYERS}


def nearest_centroid(x_train: np.ndarray, y_train: np.ndarray, x_test: np.ndarray) -> np.ndarray:
    classes = np.unique(y_train)
    centroids = np.stack([x_train[y_train == c].mean(axis=0) for c in classes])
    d = ((x_test[:, None, :] - centroids[None]) ** 2).sum(axis=2)
    return classes[np.argmin(d, axis=1)]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--letters", type=int, default=520, help="random letters per run (default 520)")
    ap.add_argument("--speed", type=float, default=30.0, help="scanning speed, mm/s (default 30)")
    ap.add_argument("--seeds", type=int, nargs=2, default=(1, 2), help="training and held-out graph seeds")
    ap.add_argument(
        "--set", action="append", default=[], metavar="NODE.PARAM=VALUE", help="override a parameter"
    )
    a = ap.parse_args(argv)
    y_tr, f_tr = features(run(a.seeds[0], a.letters, a.speed, a.set))
    y_te, f_te = features(run(a.seeds[1], a.letters, a.speed, a.set))
    print(f"{len(y_tr)} training and {len(y_te)} held-out character windows at {a.speed:g} mm/s")
    for p in LAYERS:
        pred = nearest_centroid(f_tr[p], y_tr, f_te[p])
        acc = float((pred == y_te).mean())
        per_unit = f_te[p].mean()
        active = f_te[p].max(axis=0)
        print(
            f"{p:9s}: nearest-centroid accuracy {acc:.1%}; spikes per unit per window: mean {per_unit:.1f}, "
            f"max {f_te[p].max():.0f}; units silent in every window: {int((active == 0).sum())}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
