"""Neuron-steps/s of nlif's last-spike mode (TouchSim's models) against its summed mode, in one run.

The whole hand is the hot path: N afferents (default 17 000) at 5 kHz. Each mode runs the same
per-unit drive (TouchSim-sized currents: a 20 Hz rectified sine, a different phase and amplitude per
unit) for ``--seconds`` of graph time fed in chunks of ``--chunk`` samples through the block, one
thread, CPU time (process_time) of the median of ``--repeats``. Rows:

* ``sum``:  RA.3's parameters with ``history: sum`` (Rager's kernel path) — the baseline;
* ``last``: the same with ``history: last`` and the threshold block (the renewal kernel);
* ``mixed``: ``models:`` cycling through all 17 TouchSim models (per-unit τ, gain, weights);
* ``noisy``: ``mixed`` with each model's noise at the neuron (σ = p8·sqrt(fs): one exact normal per
  unit and step; TouchSim adds it before saturation, which this row ignores — a cost measure only).

    NUMBA_NUM_THREADS=1 python scripts/bench_nlif_history.py
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np

from flowtact.blocks.spiking.nlif import Nlif
from flowtact.blocks.touch.touchsim import TOUCHSIM_RATE_HZ, touchsim_models
from flowtact.chunk import Chunk, StreamSpec


def drive(n: int, chunk: int, scale: np.ndarray) -> np.ndarray:
    rng = np.random.default_rng(0)
    phase = rng.uniform(0, 2 * np.pi, n)
    t = np.arange(chunk) / TOUCHSIM_RATE_HZ
    return np.ascontiguousarray(np.abs(np.sin(2 * np.pi * 20 * t[:, None] + phase[None, :])) * scale[None, :])


def run(block: Nlif, u: np.ndarray, n_chunks: int) -> tuple[float, int]:
    block.bind(
        {"x": StreamSpec(shape=(u.shape[1],), rate_hz=TOUCHSIM_RATE_HZ)},
        seed=1,
        demanded=frozenset({"spikes"}),
    )
    chunk = u.shape[0]
    spikes = 0
    t0 = time.process_time()
    for c in range(n_chunks):
        t = (c * chunk + np.arange(chunk)) / TOUCHSIM_RATE_HZ
        spikes += len(block(x=Chunk(t, u))["spikes"])
    return time.process_time() - t0, spikes


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=17000)
    ap.add_argument("--seconds", type=float, default=1.0)
    ap.add_argument("--chunk", type=int, default=250)
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args()
    p = touchsim_models()
    names = list(p)
    mixed = [names[k % len(names)] for k in range(a.n)]
    cls = np.array([{"SA1": 0.08, "RA": 0.3, "PC": 6.0}[m.split(".")[0]] for m in mixed])
    n_chunks = round(a.seconds * TOUCHSIM_RATE_HZ / a.chunk)
    rows = {
        "sum": (Nlif(n=a.n, preset="touch.RA.3", history="sum", threshold_block_s=0.0), np.full(a.n, 0.3)),
        "last": (Nlif(n=a.n, preset="touch.RA.3"), np.full(a.n, 0.3)),
        "mixed": (Nlif(models=mixed), cls),
        "noisy": (Nlif(models=mixed, sigma=[p[m][8] * TOUCHSIM_RATE_HZ**0.5 for m in mixed]), cls),
    }
    steps = a.n * n_chunks * a.chunk
    print(f"N = {a.n}, {a.seconds} s at 5 kHz in chunks of {a.chunk}; load average {os.getloadavg()}")
    rates = {}
    for name, (block, scale) in rows.items():
        u = drive(a.n, a.chunk, scale)
        run(block, u, 1)  # compile and warm
        times = []
        for _ in range(a.repeats):
            cpu, spikes = run(block, u, n_chunks)
            times.append(cpu)
        rates[name] = steps / statistics.median(times)
        print(
            f"{name:6s} {rates[name]:.3e} neuron-steps/s  ({spikes} spikes, {spikes / a.n / a.seconds:.0f}/s per unit)"
        )
    print(
        f"last / sum = {rates['last'] / rates['sum']:.2f}; mixed / sum = {rates['mixed'] / rates['sum']:.2f}; "
        f"noisy / mixed = {rates['noisy'] / rates['mixed']:.2f}"
    )
    for name in ("mixed", "noisy"):
        print(
            f"real-time factor of the whole hand, one core ({name}): {rates[name] / (a.n * TOUCHSIM_RATE_HZ):.1f}x"
        )
    print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
