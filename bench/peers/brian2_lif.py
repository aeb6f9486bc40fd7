"""Brian2's run of the nlif suite's LIF population, as a script for any Python that has brian2 and numpy.

    python brian2_lif.py IN.npz OUT.npz --repeats 3 [--target cython]

IN holds ``u`` (the drive, one value per step), ``gains`` (one per neuron), ``tau_s`` and ``dt_s``;
the model is ``dv/dt = (-v + gain u(t)) / tau``, threshold ``v > 1``, reset ``v = 0``, exact
integration. Every repeat builds and runs the network (two warm-ups first: the first compiles, and
the first rerun still pays something more; the cache serves the rest). OUT gets each repeat's seconds
in ``Network.run``, the last run's spikes as step numbers and neuron
indices, the code-generation target used and Brian2's version. It needs no flowtact, so it runs
in a throw-away venv too (bench/peers/venv.py).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import brian2 as b2
import numpy as np


def run_once(
    u: np.ndarray, gains: np.ndarray, tau_s: float, dt_s: float
) -> tuple[np.ndarray, np.ndarray, float]:
    """One build-and-run of the population: its spikes as (step numbers, neuron indices), and the seconds
    ``Network.run`` took (Brian2's per-run code preparation included, building the network not)."""
    b2.start_scope()
    b2.defaultclock.dt = dt_s * b2.second
    drive = b2.TimedArray(u, dt=dt_s * b2.second)
    group = b2.NeuronGroup(len(gains), "dv/dt = (-v + gain*drive(t))/tau : 1\ngain : 1", threshold="v > 1",
                           reset="v = 0", method="exact", namespace={"drive": drive, "tau": tau_s * b2.second})  # fmt: skip
    group.gain = gains
    mon = b2.SpikeMonitor(group)
    net = b2.Network(group, mon)
    t0 = time.perf_counter()
    net.run(len(u) * dt_s * b2.second, namespace={})
    secs = time.perf_counter() - t0
    steps = np.round(np.asarray(mon.t / b2.second) / dt_s).astype(np.int64)
    return steps, np.asarray(mon.i, np.int64), secs


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("inputs", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--target", default="cython", choices=["cython", "numpy"])
    a = ap.parse_args()
    with np.load(a.inputs) as f:
        u, gains, tau_s, dt_s = f["u"], f["gains"], float(f["tau_s"]), float(f["dt_s"])
    b2.prefs.codegen.target = a.target
    b2.prefs.codegen.runtime.cython.cache_dir = str(
        Path(tempfile.gettempdir()) / "flowtact-bench-brian2-cython"
    )
    for _ in range(2):  # warm-ups: compiling, then the first rerun's extra cost
        steps, idx, _ = run_once(u, gains, tau_s, dt_s)
    secs = []
    for _ in range(a.repeats):
        steps, idx, s = run_once(u, gains, tau_s, dt_s)
        secs.append(s)
    np.savez(a.out, secs=np.asarray(secs), steps=steps, idx=idx, target=a.target, version=b2.__version__)


if __name__ == "__main__":
    main()
