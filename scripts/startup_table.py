"""Launch → graph time 0 of the shipped graphs: first run after an install and cached, idle and
loaded, with the parts the start-up is made of.

    python scripts/startup_table.py                          # the whole table, markdown, on stdout
    python scripts/startup_table.py --graphs touch --rounds 5 --load 2
    FLOWTACT_NO_FORK=1 python scripts/startup_table.py ...   # workers as their own interpreters

A first run after an install is emulated by an empty numba cache (``NUMBA_CACHE_DIR`` set to a new
temporary folder: every kernel compiles, as from a wheel just installed). "Loaded" runs ``--load``
CPU-bound busy loops (default 2: one per core of a 2-core machine) for the whole measurement, as a
laptop running a browser and a compile would. Each figure is the median over ``--rounds`` runs of
``flowtact run GRAPH --duration 0.5 --json`` in real time, read from its ``startup_s`` and
``startup_parts`` (docs/running.md says what each part holds); the load average is printed under
the table.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from flowtact.bench.startup import graph_startup

ROOT = Path(__file__).resolve().parent.parent
GRAPHS = ("touch", "slip", "teleop", "braille")
PARTS = ("launch", "kernels", "start", "build", "warm_up", "bind", "wiring", "other")


@contextmanager
def busy_loops(n: int) -> Iterator[None]:
    """``n`` processes that each keep one core busy until the block ends."""
    loops = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]
    try:
        yield
    finally:
        for p in loops:
            p.kill()
            p.wait()


def start_up(graph: str, cache: str | None) -> dict[str, float]:
    """One real-time run of ``graph``: its start-up (``total``) and parts (s); numba's cache in
    ``cache`` (None: the usual one). The measurement is the startup bench suite's own."""
    try:
        run = graph_startup(str(ROOT / "graphs" / f"{graph}.yaml"), cache=cache)
    except RuntimeError as e:
        raise SystemExit(f"{graph}: {str(e).strip()[-500:]}") from None
    return {"total": run["startup_s"], **run["parts"]}


def measure(graph: str, first: bool, rounds: int) -> list[dict[str, float]]:
    """``rounds`` start-ups of ``graph``: each from an empty numba cache (``first``) or a warm one."""
    out = []
    if not first:
        start_up(graph, None)  # fills the cache this condition reads
    for _ in range(rounds):
        if first:
            with tempfile.TemporaryDirectory(prefix="flowtact-numba-") as cache:
                out.append(start_up(graph, cache))
        else:
            out.append(start_up(graph, None))
    return out


def row(graph: str, cache: str, load: str, runs: list[dict[str, float]]) -> str:
    """A table row: the median start-up (min–max) and each part's median."""
    totals = [r["total"] for r in runs]
    spread = f" ({min(totals):.2f}–{max(totals):.2f})" if len(runs) > 1 else ""
    parts = [f"{statistics.median(r.get(p, 0.0) for r in runs):.2f}" for p in PARTS]
    return (
        f"| {graph} | {cache} | {load} | {statistics.median(totals):.2f}{spread} | "
        + " | ".join(parts)
        + " |"
    )


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--graphs", nargs="+", default=list(GRAPHS), choices=GRAPHS)
    p.add_argument("--rounds", type=int, default=3, help="runs per condition (default 3)")
    p.add_argument("--load", type=int, default=2, help="busy loops for the loaded rows (default 2)")
    p.add_argument("--only", choices=("idle", "loaded"), help="measure one load condition only")
    args = p.parse_args(argv)
    head = "| graph | numba cache | load | launch → graph time 0, s (min–max) | " + " | ".join(PARTS) + " |"
    print(head)
    print("|" + "---|" * (4 + len(PARTS)))
    loads = [c for c in ("idle", "loaded") if args.only in (None, c)]
    averages = {}
    for load in loads:
        with busy_loops(args.load if load == "loaded" else 0):
            for graph in args.graphs:
                for first in (True, False):
                    runs = measure(graph, first, args.rounds)
                    print(row(graph, "empty (first run)" if first else "warm", load, runs), flush=True)
            averages[load] = os.getloadavg()[0]
    mode = "own interpreters (FLOWTACT_NO_FORK)" if os.environ.get("FLOWTACT_NO_FORK") else "forked"
    said = ", ".join(f"{k} {v:.1f}" for k, v in averages.items())
    print(f"\nworkers {mode}; {args.rounds} runs per row; load average (1 min) at the end of each: {said}; "
          f"{os.cpu_count()} cores")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
