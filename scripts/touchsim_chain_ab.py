"""Two versions of ``touchsim_chain`` against each other, alternated in one process: CPU ns per
afferent-sample on `flowtact bench touchsim`'s stimulus, and whether both fire the same spikes.

A kernel change is judged by this A/B, not by two timings minutes apart: on a shared 2-core machine
the same code moves by ±30 % from run to run, but a ratio of runs taken in turn holds. Each version
is a copy of blocks/touch/touchsim_chain.py (``git show REV:blocks/touch/touchsim_chain.py > A.py``,
edit a copy to B.py); each is imported under its own name, bound from rest for every repeat, and
fed 1 s of the development set's s and d (trace j mod 68 in column j) in 50-sample chunks, noise on.

    python scripts/touchsim_chain_ab.py A.py B.py --n 1000 --repeats 7

``installed`` names the installed flowtact's own file (``installed installed``: the block against
itself, B/A ≈ 1 and the same spikes — what the spread of the machine is).

Prints A's and B's median, the median of the paired ratios B/A (< 1: B is faster), the spike counts
(equal when B computes what A does) and the load average. Needs the development set (tests/data).
"""

from __future__ import annotations

import argparse
import hashlib
import importlib.util
import os
import sys
import time
from types import ModuleType

import numpy as np

from flowtact.bench.touchsim import CHUNK, FS, stimulus
from flowtact.bench.touchsim_dev_set import dev_set_path, load_dev_set
from flowtact.chunk import Chunk, StreamSpec


def load(path: str) -> ModuleType:
    """Import the module file ``path`` (``installed``: flowtact's own module). A copy is imported
    under a name made from its path: numba's cache of a file records the module name it was
    compiled under, so a file must come back under the same name."""
    if path == "installed":
        import flowtact.blocks.touch.touchsim_chain as shipped

        return shipped
    full = os.path.realpath(path)
    name = "touchsim_chain_" + hashlib.sha1(full.encode()).hexdigest()[:12]
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, full)
    if spec is None or spec.loader is None:
        raise SystemExit(f"touchsim_chain_ab: cannot import {path}")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


def run_once(
    mod: ModuleType, s: np.ndarray, d: np.ndarray, models: list[str], seed: int
) -> tuple[float, int]:
    """CPU ns per afferent-sample of one run from rest (binding not timed), and its spike count."""
    n = s.shape[1]
    spec = StreamSpec(dtype="float64", shape=(n,), rate_hz=float(FS))
    block = mod.TouchsimChain(models=list(models))
    block.bind({"s": spec, "d": spec}, seed=seed, demanded=frozenset({"spikes"}))
    t_all = np.arange(len(s)) / FS
    spikes = 0
    t0 = time.process_time_ns()
    for i in range(0, len(s), CHUNK):
        t = t_all[i : i + CHUNK]
        spikes += len(block(s=Chunk(t, s[i : i + CHUNK]), d=Chunk(t, d[i : i + CHUNK]))["spikes"])
    tail = block.flush().get("spikes")
    spikes += 0 if tail is None else len(tail)
    return (time.process_time_ns() - t0) / s.size, spikes


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("a", help="version A: a copy of touchsim_chain.py, or 'installed'")
    ap.add_argument("b", help="version B: a copy of touchsim_chain.py, or 'installed'")
    ap.add_argument("--n", type=int, default=1000, help="afferents (default 1000)")
    ap.add_argument("--repeats", type=int, default=7, help="pairs of runs (default 7)")
    args = ap.parse_args()
    path = dev_set_path()
    if path is None:
        raise SystemExit("touchsim_chain_ab: the development set (tests/data/touchsim_dev.npz) was not found")
    s, d, models, _, _ = stimulus(load_dev_set(path), args.n)
    a, b = load(args.a), load(args.b)
    run_once(a, s, d, models, 0), run_once(b, s, d, models, 0)  # compile or load both first
    ta, tb, ratio = [], [], []
    for r in range(args.repeats):
        (x, na), (y, nb) = run_once(a, s, d, models, r), run_once(b, s, d, models, r)
        ta.append(x)
        tb.append(y)
        ratio.append(y / x)
    load_avg = ", ".join(f"{v:.1f}" for v in os.getloadavg())
    print(f"A {np.median(ta):.3f} ns  B {np.median(tb):.3f} ns per afferent-sample (N = {args.n})")
    print(f"B/A {np.median(ratio):.3f} (paired, {min(ratio):.3f}–{max(ratio):.3f}); spikes A {na}, B {nb}")
    print(f"load average {load_avg}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
