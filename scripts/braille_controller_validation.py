"""How the closed loop's settings (graphs/braille.yaml) were chosen: on a validation text.

Reads permutations of the alphabet drawn from seed 500 (graph seeds 500 up: neither a training seed
of ``flowtact train-braille``, 1–3, nor the benchmark's held-out text, 100 000 up) with the
shipped first-order model, on the graphs' varying fingertip:

1. at constant speeds in the paper's range (10–80 mm/s): recognition without a reject option and
   each window's largest posterior probability; the decoder's reject ``threshold`` is the one
   minimising Chow's risk (errors + ½ × abstentions) pooled over those speeds
   (``flowtact.bench.braille_metrics.chow_threshold``);
2. in closed loop under a grid of controller settings within 10–80 mm/s, with that threshold:
   recognition, non-classification and mean reading speed, and the fastest constant speed that
   recognises as well (interpolated on step 1's curve with the same threshold). The setting
   printed last reads fastest among those beating the constant-speed curve by most.

    python scripts/braille_controller_validation.py            # 8 alphabets (208 letters) per point
    python scripts/braille_controller_validation.py --reps 2   # a quick look
"""

from __future__ import annotations

import argparse
import itertools
import os
from pathlib import Path

import numpy as np

from flowtact.bench.braille import fastest_constant, read_scored
from flowtact.bench.braille_metrics import chow_threshold
from flowtact.blocks.braille.cells import LETTERS
from flowtact.blocks.braille.reading import read_line
from flowtact.blocks.spiking.nb_model import decide, load_model, log_posterior
from flowtact.blocks.spiking.window_features import window_features

SEED = 500
ROOT = Path(__file__).resolve().parent.parent
MODEL = ROOT / "blocks/braille/models/braille_first.npz"
SPEEDS = (10.0, 20.0, 30.0, 40.0, 60.0, 80.0)
#: (min, max) mm/s, (unsure, sure), max_accel mm/s²
GRID = (
    ((10.0, 80.0), (20.0, 80.0), (30.0, 80.0)),
    ((0.5, 0.95), (0.9, 0.999), (0.99, 0.99999)),
    (1000.0, 4000.0),
)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--reps", type=int, default=8, help="alphabets of validation text (26 letters each)")
    a = p.parse_args(argv)
    m = load_model(MODEL)
    rng = np.random.default_rng(SEED)
    text = "".join("".join(rng.permutation(list(LETTERS))) for _ in range(a.reps))
    tops, right, per_speed = [], [], []
    for i, v in enumerate(SPEEDS):
        r = read_line(seed=SEED + i, speed_mm_s=v, text=text, layers=("first",))
        t, u = r.spikes["first"]
        x = window_features(t, u, r.windows, n_units=m.n_units, n_bins=m.n_bins)
        post = np.exp(log_posterior(m, x))
        y = np.array([LETTERS.index(c) for c in r.letters])
        tops.append(post.max(axis=1))
        right.append(np.argmax(post, axis=1) == y)
        per_speed.append((v, post, y))
        print(f"constant {v:4.0f} mm/s: {np.mean(right[-1]):6.1%} of {len(y)} (no reject option)", flush=True)
    thr = chow_threshold(np.concatenate(tops), np.concatenate(right), cost=0.5)
    print(f"reject threshold (Chow, cost of abstaining ½ an error, pooled 10-80 mm/s): {thr:.6g}")
    curve = []
    for v, post, y in per_speed:
        d = decide(post, thr)
        rec, nc = float(np.mean(d == y)), float(np.mean(d == len(LETTERS)))
        curve.append((v, rec))
        print(f"constant {v:4.0f} mm/s: recognised {rec:6.1%}, not classified {nc:5.1%}")
    best = None
    for (lo, hi), (unsure, sure), accel in itertools.product(*GRID):
        ctl = {
            "min_speed_mm_s": lo,
            "max_speed_mm_s": hi,
            "unsure": unsure,
            "sure": sure,
            "max_accel_mm_s2": accel,
        }
        rec, nc, speed, n = read_scored(ctl, MODEL, thr, text, SEED + 50)
        ref = fastest_constant(curve, rec)
        margin = speed - ref if np.isfinite(ref) else speed - SPEEDS[0]
        print(
            f"loop {lo:g}-{hi:g} mm/s, unsure {unsure:g}, sure {sure:g}, {accel:g} mm/s²: recognised {rec:6.1%}, "
            f"not classified {nc:5.1%}, {speed:5.1f} mm/s (constant speed of equal recognition: up to "
            f"{ref:5.1f} mm/s), {n} letters",
            flush=True,
        )
        if best is None or margin > best[0]:
            best = (margin, ctl, rec, speed)
    assert best is not None
    print(f"chosen: {best[1]} ({best[2]:.1%} at {best[3]:.1f} mm/s, {best[0]:+.1f} mm/s over constant speed)")
    print(f"load average: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
