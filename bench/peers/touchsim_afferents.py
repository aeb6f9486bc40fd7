"""TouchSim's own per-afferent model on given s and d, as a script for a Python that has touchsim.

    python touchsim_afferents.py IN.npz OUT.npz [--repeats 3] [--noise-off]

IN holds ``s`` and ``d`` (samples × afferents at 5 kHz: the static and dynamic terms at each
receptor), ``cls`` (0 SA1, 1 RA, 2 PC per afferent) and ``idx`` (the model within its class). Each
repeat builds nothing: it calls TouchSim's ``transduction.lif_neuron`` (prefilter, rectified weights,
noise p8·ξ before saturation, membrane, post-spike current, blocked threshold) on fresh copies of s
and d, after one warm-up call. OUT gets each repeat's CPU seconds of that call (``time.process_time``,
every thread of the process), and every repeat's spikes as sample indices (spike time × 5000 − 1):
``counts`` (repeats × afferents) and ``spikes`` (all indices, repeat by repeat, afferent by
afferent). TouchSim's noise is not seedable: each repeat is a fresh draw. It needs no flowtact and
copies no code of TouchSim's (which has no licence): it imports and runs it, in a throw-away venv
(bench/peers/venv.py).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import touchsim as ts
from touchsim.transduction import lif_neuron

FS = 5000.0
CLASSES = ("SA1", "RA", "PC")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("inputs", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--noise-off", action="store_true")
    a = ap.parse_args()
    with np.load(a.inputs) as f:
        s, d, cls, idx = f["s"], f["d"], f["cls"], f["idx"]
    affs = [ts.Afferent(CLASSES[c], idx=int(i), noisy=not a.noise_off) for c, i in zip(cls, idx, strict=True)]
    pop = ts.AfferentPopulation(*affs)
    lif_neuron(pop, s.copy(), d.copy())  # warm-up (its kernels are compiled at import; caches, pages)
    secs, counts, spikes = [], [], []
    for _ in range(a.repeats):
        s1, d1 = s.copy(), d.copy()  # lif_neuron filters its inputs in place
        t0 = time.process_time()
        out = lif_neuron(pop, s1, d1)
        secs.append(time.process_time() - t0)
        idxs = [np.rint(np.asarray(t) * FS).astype(np.int64) - 1 for t in out]
        counts.append([len(x) for x in idxs])
        spikes.extend(idxs)
    np.savez(
        a.out,
        secs=np.array(secs),
        counts=np.array(counts, np.int64),
        spikes=np.concatenate(spikes) if spikes else np.zeros(0, np.int64),
        version=getattr(ts, "__version__", "0.1.1"),
    )


if __name__ == "__main__":
    main()
