"""Normals per second of the exact generator (normal_draws.fill_normal) against NumPy's
Generator.standard_normal in the same process, under numba's CPU tunings: this host's, and Intel
AVX-512's default (``skylake-avx512``, which prefers 256-bit vectors) with and without
``-prefer-256-bit``. Each tuning runs in a child with its own NUMBA_CACHE_DIR (a fresh compile).

    python scripts/normal_draws_tuning.py            # prints one line per tuning and request size

Ratios, not absolute rates, compare across runs: the load average is printed with each line.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

TUNINGS = {
    "host": {},
    "skylake-avx512 (Intel's default tuning)": {"NUMBA_CPU_NAME": "skylake-avx512"},
    "skylake-avx512, -prefer-256-bit": {"NUMBA_CPU_NAME": "skylake-avx512", "FEATURES": "-prefer-256-bit"},
}


def measure() -> None:
    """In the child: median rates of 7 rounds, 4 096 (the kernels' request) and 1e6 values per call."""
    from flowtact.blocks.spiking.normal_draws import fill_normal, seed_state

    def rate(fill, size: int, calls: int) -> float:
        out = np.empty(size)
        fill(out)
        rounds = []
        for _ in range(7):
            t = time.process_time()
            for _ in range(calls):
                fill(out)
            rounds.append(size * calls / (time.process_time() - t))
        return statistics.median(rounds)

    gen, state = np.random.default_rng(1), seed_state(np.random.default_rng(1))
    for size, calls in ((4096, 2500), (1_000_000, 10)):
        base = rate(lambda o: gen.standard_normal(out=o), size, calls)
        ours = rate(lambda o: fill_normal(state, o), size, calls)
        print(f"  {size:>9,} per call: numpy {base:.3g}/s, fill_normal {ours:.3g}/s, ratio {ours / base:.2f}"
              f" (load {os.getloadavg()[0]:.1f})", flush=True)  # fmt: skip


def main() -> None:
    if sys.argv[1:] == ["--child"]:
        measure()
        return
    import llvmlite.binding as llvm

    features = llvm.get_host_cpu_features().flatten()
    print(f"host: {llvm.get_host_cpu_name()}")
    for name, env in TUNINGS.items():
        child = dict(os.environ)
        extra = env.get("FEATURES")
        child.update({k: v for k, v in env.items() if k != "FEATURES"})
        if extra:
            child["NUMBA_CPU_FEATURES"] = f"{features},{extra}"
        with tempfile.TemporaryDirectory() as cache:
            child["NUMBA_CACHE_DIR"] = cache
            print(name, flush=True)
            subprocess.run([sys.executable, __file__, "--child"], env=child, check=True)


if __name__ == "__main__":
    main()
