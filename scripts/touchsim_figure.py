"""TouchSim's spikes and flowtact's for a few development-set traces, from TouchSim's own currents
(noise off): the figure of docs/touchsim.md, and the agreement over all 68 traces.

Reads tests/blocks/touch/data/touchsim_dev_currents.npz (TouchSim's current ``I`` and spikes per
trace), runs one nlif population with ``models:`` set to each trace's model, prints how many traces
agree spike for spike and draws a raster per chosen trace: TouchSim's spikes (black, its stamps
(n + 1)/fs) above flowtact's (orange, stamped at the input sample's time n/fs).

    python scripts/touchsim_figure.py --out touchsim-rasters.png
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import itertools

import matplotlib.pyplot as plt
import numpy as np

from flowtact.blocks.spiking.nlif import Nlif
from flowtact.testing import run_offline

FS = 5000.0
DATA = (
    Path(__file__).resolve().parent.parent
    / "tests"
    / "blocks"
    / "touch"
    / "data"
    / "touchsim_dev_currents.npz"
)
SHOWN = ("ramp03|SA1|0", "sine50|SA1|2", "sine50|RA|3", "noise7|RA|5", "sine100|PC|1", "noise7|PC|3")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="touchsim-rasters.png", help="the figure file (PNG)")
    a = ap.parse_args()
    z = np.load(DATA)
    names = [str(x) for x in z["names"]]
    bounds = np.concatenate([[0], np.cumsum(z["counts"])])
    theirs = [z["spikes"][i:j] for i, j in itertools.pairwise(bounds)]
    models = [".".join(n.split("|")[1:]) for n in names]
    out = run_offline(Nlif(models=models), x=np.ascontiguousarray(z["I"].T), rate_hz=FS)
    steps = np.rint(out["spikes"].t * FS).astype(np.int64)
    ours = [steps[out["spikes"].data == k] for k in range(len(names))]
    same = sum(np.array_equal(a_, b_) for a_, b_ in zip(theirs, ours, strict=True))
    total = sum(len(s) for s in theirs)
    print(
        f"{same} of {len(names)} traces spike for spike ({total} TouchSim spikes, {len(steps)} flowtact spikes)"
    )

    fig, ax = plt.subplots(figsize=(9, 4.2))
    ticks, labels = [], []
    for row, name in enumerate(SHOWN):
        k = names.index(name)
        y = 2 * (len(SHOWN) - 1 - row)
        ax.vlines((theirs[k] + 1) / FS, y + 0.55, y + 1.35, color="black", lw=0.8)
        ax.vlines(ours[k] / FS, y - 0.35, y + 0.45, color="tab:orange", lw=0.8)
        stim, cls, idx = name.split("|")
        ticks += [y + 0.95, y + 0.05]
        labels += [f"{cls}.{idx} {stim}: TouchSim", f"flowtact ({len(ours[k])} spikes)"]
    ax.set_yticks(ticks, labels, fontsize=8)
    ax.set_xlabel("time (s)")
    ax.set_xlim(0, 0.8)
    ax.set_title(
        f"TouchSim (black) and flowtact nlif (orange) from TouchSim's current: {same}/{len(names)} traces identical",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(a.out, dpi=120)
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
