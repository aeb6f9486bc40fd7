"""TouchSim's own noisy runs of the development set, reduced to the statistics the noise test compares.

    python scripts/touchsim_noise_reference.py [--repeats 400] [--out tests/data/touchsim_noise_ref.npz]

Runs TouchSim's per-afferent model (its ``lif_neuron``: prefilter, weights, noise p8·ξ before
saturation, membrane) with noise on, on the s and d of all 68 development traces, ``--repeats``
times (its noise is not seedable: every repeat is a fresh draw), in a throw-away venv with TouchSim
installed from its public source (bench/peers/touchsim_peer.py; ``FLOWTACT_TOUCHSIM_SOURCE`` names a
local clone where GitHub cannot be reached; ``--python`` uses a Python that has touchsim already).
First it checks the installed code against the development set with noise off (every spike of the
68 traces). Writes, per repeat and trace, the spike count, the first spike's sample and the mean
inter-spike interval (bench/touchsim_noise.py), with TouchSim's commit and the repeats.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from flowtact.bench.peers.touchsim_peer import TOUCHSIM_COMMIT, touchsim_python, touchsim_run, touchsim_source
from flowtact.bench.touchsim_dev_set import dev_set_path, load_dev_set
from flowtact.bench.touchsim_noise import STATS, spike_stats

ROOT = Path(__file__).resolve().parents[1]


def split(counts: np.ndarray, spikes: np.ndarray) -> list[np.ndarray]:
    """TouchSim's flat spikes, repeat by repeat and afferent by afferent, as one array per run."""
    return np.split(spikes, np.cumsum(counts.ravel())[:-1])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=400)
    ap.add_argument("--out", type=Path, default=ROOT / "tests" / "data" / "touchsim_noise_ref.npz")
    ap.add_argument(
        "--python", type=Path, help="a Python that imports touchsim (default: the throw-away venv)"
    )
    a = ap.parse_args()
    path = dev_set_path()
    if path is None:
        print("touchsim_noise_reference: no development set (tests/data/touchsim_dev.npz)", file=sys.stderr)
        return 2
    dev = load_dev_set(path)
    py = a.python or touchsim_python()[0]
    if py is None:
        print(
            f"touchsim_noise_reference: TouchSim could not be installed from {touchsim_source()}",
            file=sys.stderr,
        )
        return 1
    clean = touchsim_run(py, dev.s, dev.d, dev.cls, dev.idx, 1, noise=False)
    got = split(clean["counts"], clean["spikes"])
    bad = [n for n, g, w in zip(dev.names, got, dev.spikes, strict=True) if not np.array_equal(g, w)]
    if bad:
        print(
            f"touchsim_noise_reference: this TouchSim misses the dev set's spikes on {bad[:5]}",
            file=sys.stderr,
        )
        return 1
    print(
        f"TouchSim ({py}) reproduces all 68 development traces with noise off ({sum(map(len, got))} spikes)"
    )
    noisy = touchsim_run(py, dev.s, dev.d, dev.cls, dev.idx, a.repeats, noise=True)
    stats = spike_stats(split(noisy["counts"], noisy["spikes"]))
    shape = (a.repeats, len(dev.names))
    a.out.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(
        a.out,
        names=np.array(dev.names),
        **{k: stats[k].reshape(shape) for k in STATS},  # float64: a float32 interval differs from ours
        repeats=a.repeats,
        touchsim_commit=TOUCHSIM_COMMIT,
    )
    mean = stats["count"].reshape(shape).mean()
    print(f"{a.repeats} noisy repeats of 68 traces: {mean:.1f} spikes per trace on average -> {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
