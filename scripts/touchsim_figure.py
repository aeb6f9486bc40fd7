"""TouchSim's development set against flowtact, the two figures of docs/touchsim.md, and the agreement
over all 68 traces.

Reads TouchSim's development set (tests/data/touchsim_dev.npz through its loader,
flowtact.bench.touchsim_dev_set; ``FLOWTACT_TOUCHSIM_DEV`` names another copy; noise off).

``--out``: from TouchSim's own currents, one nlif population with ``models:`` set to each trace's
model; prints how many traces agree spike for spike and draws a raster per chosen trace:
TouchSim's spikes (black, its stamps (n + 1)/fs) above flowtact's (orange, stamped at the input
sample's time n/fs).

``--current``: the whole chain from TouchSim's s and d (prefilter, rectified weighting, membrane;
bench/touchsim_chain.py) for one trace of each class: per model its inputs s and d, TouchSim's
current and flowtact's, and both spike trains.

    python scripts/touchsim_figure.py --out touchsim-rasters.png --current touchsim-current.png
"""

from __future__ import annotations

import argparse
import sys

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np

from flowtact.bench.touchsim_chain import TouchSimChain
from flowtact.bench.touchsim_dev_set import DevSet, dev_set_path, load_dev_set
from flowtact.blocks.spiking.nlif import Nlif
from flowtact.testing import run_offline

FS = 5000.0
SHOWN = ("ramp03|SA1|0", "sine50|SA1|2", "sine50|RA|3", "noise7|RA|5", "sine100|PC|1", "noise7|PC|3")
#: One trace per class for --current, and the time shown (ms): SA1 on the whole ramp-and-hold, RA and
#: PC on five and six cycles of their sines (the counts in the raster labels are the whole 0.8 s).
CHAIN = {"ramp03|SA1|0": (0, 800), "sine50|RA|3": (100, 200), "sine100|PC|1": (100, 160)}
STIMULI = {
    "ramp03": "0.3 mm ramp-and-hold",
    "sine50": "50 Hz sine, 0.05 mm",
    "sine100": "100 Hz sine, 0.03 mm",
    "noise7": "10–200 Hz noise, 0.08 mm",
}
THEIRS, OURS = "black", "tab:orange"


def rasters(dev: DevSet, out: str) -> None:
    """The raster figure (six traces) and the spike-for-spike agreement over all traces."""
    run = run_offline(Nlif(models=dev.models), x=np.ascontiguousarray(dev.current), rate_hz=FS)
    steps = np.rint(run["spikes"].t * FS).astype(np.int64)
    ours = [steps[run["spikes"].data == k] for k in range(len(dev.names))]
    same = sum(np.array_equal(a_, b_) for a_, b_ in zip(dev.spikes, ours, strict=True))
    total = sum(len(s) for s in dev.spikes)
    print(
        f"{same} of {len(dev.names)} traces spike for spike ({total} TouchSim spikes, {len(steps)} flowtact spikes)"
    )
    fig, ax = plt.subplots(figsize=(9, 4.2))
    ticks, labels = [], []
    for row, name in enumerate(SHOWN):
        k = dev.names.index(name)
        y = 2 * (len(SHOWN) - 1 - row)
        ax.vlines((dev.spikes[k] + 1) / FS, y + 0.55, y + 1.35, color=THEIRS, lw=0.8)
        ax.vlines(ours[k] / FS, y - 0.35, y + 0.45, color=OURS, lw=0.8)
        stim, cls, idx = name.split("|")
        ticks += [y + 0.95, y + 0.05]
        labels += [f"{cls}.{idx} {stim}: TouchSim", f"flowtact ({len(ours[k])} spikes)"]
    ax.set_yticks(ticks, labels, fontsize=8)
    ax.set_xlabel("time (s)")
    ax.set_xlim(0, 0.8)
    ax.set_title(
        f"TouchSim (black) and flowtact nlif (orange) from TouchSim's current: {same}/{len(dev.names)} traces identical",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    print(f"wrote {out}")


def chain_figure(dev: DevSet, out: str) -> None:
    """Per model of CHAIN (a column): s and d; TouchSim's current and flowtact's; both spike trains."""
    ks = [dev.names.index(n) for n in CHAIN]
    chain = TouchSimChain([dev.models[k] for k in ks], noise=False)
    ours = chain.run(dev.s[:, ks], dev.d[:, ks], chunk=997, keep_current=True)
    t = np.arange(dev.s.shape[0]) / FS * 1e3  # ms
    fig, axes = plt.subplots(3, len(ks), figsize=(12, 7.2), sharex="col", height_ratios=(1.2, 1.6, 0.7))
    for j, (k, (t0, t1)) in enumerate(zip(ks, CHAIN.values(), strict=True)):
        stim, cls, idx = dev.names[k].split("|")
        top, mid, low = axes[:, j]
        shown = "" if (t0, t1) == (0, 800) else f" ({t0}–{t1} ms of 800)"
        top.set_title(f"{cls}.{idx} — {STIMULI[stim]}{shown}", fontsize=10)
        top.plot(t, dev.s[:, k], color="tab:blue", lw=1.0, label="s (static term)")
        top.set_ylabel("s (TouchSim a.u.)", color="tab:blue", fontsize=8)
        twin = top.twinx()
        twin.plot(t, dev.d[:, k], color="tab:green", lw=0.8, label="d (dynamic term)")
        twin.set_ylabel("d (TouchSim a.u.)", color="tab:green", fontsize=8)
        for a in (top, twin):
            a.tick_params(labelsize=7)
        if j == 0:
            top.legend([top.lines[0], twin.lines[0]], ["s (static)", "d (dynamic)"], fontsize=7, loc="center")
        theirs_i, ours_i = dev.current[:, k], chain.current_out[:, j]
        mid.plot(t, theirs_i, color=THEIRS, lw=3.0, alpha=0.35, label="TouchSim's current I")
        mid.plot(t, ours_i, color=OURS, lw=0.9, ls="--", label="flowtact: iir → rectified_gain")
        diff = np.abs(ours_i - theirs_i).max()
        mid.set_title(f"max |flowtact − TouchSim| = {diff:.1e}", fontsize=8)
        mid.set_ylabel("current I (per 0.2 ms sample;\nthreshold 1)", fontsize=8)
        mid.tick_params(labelsize=7)
        if j == 0:
            mid.legend(fontsize=7, loc="lower right")
        spk_t = (dev.spikes[k] + 1) / FS * 1e3
        low.vlines(spk_t, 0.55, 1.35, color=THEIRS, lw=0.9)
        low.vlines(ours[j] / FS * 1e3, -0.35, 0.45, color=OURS, lw=0.9)
        said = [f"TouchSim ({len(spk_t)} in 0.8 s)", f"flowtact ({len(ours[j])})"]
        low.set_yticks([0.95, 0.05], said, fontsize=7)
        low.set_ylim(-0.6, 1.6)
        low.set_xlabel("time (ms)", fontsize=8)
        low.set_xlim(t0, t1)
        low.tick_params(axis="x", labelsize=7)
    fig.suptitle(
        "TouchSim's development set (noise off) through flowtact's whole chain from s and d: "
        "TouchSim grey/black, flowtact orange",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="touchsim-rasters.png", help="the raster figure (PNG)")
    ap.add_argument("--current", metavar="FILE", help="also draw the chain figure (s, d, current, spikes)")
    a = ap.parse_args()
    path = dev_set_path()
    if path is None:
        print(
            "touchsim_figure: no development set (tests/data/touchsim_dev.npz; FLOWTACT_TOUCHSIM_DEV)",
            file=sys.stderr,
        )
        return 2
    dev = load_dev_set(path)
    rasters(dev, a.out)
    if a.current:
        chain_figure(dev, a.current)
    return 0


if __name__ == "__main__":
    sys.exit(main())
