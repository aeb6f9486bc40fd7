"""What each node of a graph costs per step, run in process at a fixed tick: where a tick's CPU goes.

Runs the graph twice with the in-process executor in ``--fast`` semantics after a warm-up run: once
plain, for the CPU per tick of the whole run, then with every block's ``step`` timed (µs per call,
wall clock around the call; the timing adds ~0.3 µs a call).

    python scripts/step_costs.py bench/graphs/chain.yaml               # 1 ms ticks, 10 graph seconds
    python scripts/step_costs.py graphs/touch.yaml --tick 0.005 --duration 20
"""

from __future__ import annotations

import argparse
import time
from collections import defaultdict
from collections.abc import Callable
from typing import Any

from flowtact.compile import compile_graph
from flowtact.graph import load_graph
from flowtact.runtime.inproc import InprocExecutor


def _timed(step: Callable[..., Any], into: list[int]) -> Callable[..., Any]:
    def step_timed(*args: Any, **kwargs: Any) -> Any:
        t0 = time.perf_counter_ns()
        try:
            return step(*args, **kwargs)
        finally:
            into.append(time.perf_counter_ns() - t0)

    return step_timed


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("graph", help="a graph file")
    ap.add_argument("--tick", type=float, default=0.001, help="tick in s (default 0.001)")
    ap.add_argument("--duration", type=float, default=10.0, help="graph seconds per run (default 10)")
    args = ap.parse_args(argv)
    plan = compile_graph(load_graph(args.graph))
    ticks = round(args.duration / args.tick)

    InprocExecutor(plan, fast=True, tick_s=args.tick).run(min(args.duration, 1.0))  # compile, warm caches
    cpu0 = time.process_time()
    InprocExecutor(plan, fast=True, tick_s=args.tick).run(args.duration)
    cpu_us = (time.process_time() - cpu0) / ticks * 1e6

    ex = InprocExecutor(plan, fast=True, tick_s=args.tick)
    calls: dict[str, list[int]] = defaultdict(list)
    for name, block in ex.blocks.items():
        block.step = _timed(block.step, calls[name])  # type: ignore[method-assign]
    ex.run(args.duration)

    print(f"{args.graph}: {ticks} ticks of {args.tick * 1e3:g} ms")
    for name, ns in calls.items():
        if ns:
            print(f"  {name:16s} {sum(ns) / len(ns) / 1e3:8.2f} µs per step  ({len(ns)} steps)")
    steps_us = sum(sum(ns) for ns in calls.values()) / ticks / 1e3
    print(f"blocks' steps: {steps_us:.1f} µs per tick; the whole run: {cpu_us:.1f} µs of CPU per tick")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
