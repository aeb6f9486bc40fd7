"""How the closed loop's controller setting (graphs/braille.yaml) was chosen: on a validation text.

Reads 4 permutations of the alphabet (seed 500: neither a training seed of ``flowtact train-braille``
nor the benchmark's held-out text) at constant speeds and in closed loop under a few controller
settings, with the shipped first-order model, and prints recognition and mean reading speed. (The
scan's speed limit is raised to 400 mm/s here to see where constant-speed reading breaks down.)

    python scripts/braille_controller_validation.py
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

from flowtact.blocks.braille.cells import LETTERS
from flowtact.blocks.braille.reading import read_line
from flowtact.blocks.spiking.nb_model import load_model, log_posterior
from flowtact.blocks.spiking.window_features import window_features

SEED = 500
ROOT = Path(__file__).resolve().parent.parent
MODEL = "blocks/braille/models/braille_first.npz"


def main() -> None:
    m = load_model(ROOT / MODEL)
    rng = np.random.default_rng(SEED)
    text = "".join("".join(rng.permutation(list(LETTERS))) for _ in range(4))
    truth = lambda r: np.array([LETTERS.index(c) for c in r.letters])  # noqa: E731
    for v in (80, 100, 150, 200, 250, 300):
        r = read_line(
            seed=SEED, speed_mm_s=v, text=text, layers=("first",), params={"scan": {"max_speed_mm_s": 250.0}}
        )
        t, u = r.spikes["first"]
        x = window_features(t, u, r.windows, n_units=m.n_units, n_bins=m.n_bins)
        acc = np.mean(np.argmax(log_posterior(m, x), axis=1) == truth(r))
        print(f"constant {v:4.0f} mm/s: {acc:6.1%}")
    settings = [
        (40.0, 100.0, 0.5, 0.99),
        (100.0, 300.0, 0.05, 0.5),
        (150.0, 300.0, 0.05, 0.5),
        (150.0, 300.0, 0.1, 0.9),
    ]
    for (lo, hi, unsure, sure), accel in itertools.product(settings, (10000.0, 20000.0)):
        ctl = {
            "min_speed_mm_s": lo,
            "max_speed_mm_s": hi,
            "sure": sure,
            "unsure": unsure,
            "max_accel_mm_s2": accel,
        }
        r = read_line(
            "braille", seed=SEED, text=text, layers=("first",), tick_s=0, extra=["decoder.decision", "scan.position"],
            params={"control": ctl, "decoder": {"model": str(ROOT / MODEL)}, "scan": {"min_speed_mm_s": lo, "max_speed_mm_s": 400.0}},
        )  # fmt: skip
        d = np.asarray(r.streams["decoder.decision"].data, np.int64)
        acc = np.mean(d == truth(r)[: len(d)])
        pos = r.streams["scan.position"]
        speed = (pos.data[-1] - pos.data[0]) / (pos.t[-1] - pos.t[0])
        print(
            f"closed loop {lo:g}-{hi:g} mm/s, unsure {unsure:g}, sure {sure:g}, {accel:g} mm/s²: {acc:6.1%} at {speed:5.1f} mm/s"
        )


if __name__ == "__main__":
    main()
