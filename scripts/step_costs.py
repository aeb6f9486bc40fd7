"""What each node of a graph costs per step, run in process at a fixed tick: where a tick's CPU goes.

Runs the graph twice with the in-process executor in ``--fast`` semantics after a warm-up run: once
plain, for the CPU per tick of the whole run, then with every block's ``step`` timed (µs per call,
mean and median, wall clock around the call; the timing adds ~0.3 µs a call).

``--wake S`` sleeps S seconds before the first node of each process in every tick, as a real-time
worker sleeps until its clock or its input: the steps then run with the cold caches they meet in a
real run (on this shared 2-core VM, 3-4x their cost in a hot loop; the whole-run CPU is not measured).

    python scripts/step_costs.py bench/graphs/chain.yaml               # 1 ms ticks, 10 graph seconds
    python scripts/step_costs.py bench/graphs/chain.yaml --wake 0.0003 --duration 3
    python scripts/step_costs.py graphs/touch.yaml --tick 0.005 --duration 20
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections import defaultdict
from collections.abc import Callable
from typing import Any

from flowtact.graphfile.graph import load_graph
from flowtact.running.compile import compile_graph
from flowtact.runtime.inproc import InprocExecutor
from flowtact.runtime.placement import place


def _timed(step: Callable[..., Any], into: list[int], wake_s: float) -> Callable[..., Any]:
    def step_timed(*args: Any, **kwargs: Any) -> Any:
        if wake_s:
            time.sleep(wake_s)
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
    ap.add_argument("--wake", type=float, default=0.0, metavar="S",
                    help="sleep S s before each process's first node in every tick (cold steps, as in a real run)")  # fmt: skip
    args = ap.parse_args(argv)
    plan = compile_graph(load_graph(args.graph))
    ticks = round(args.duration / args.tick)

    InprocExecutor(plan, fast=True, tick_s=args.tick).run(min(args.duration, 1.0))  # compile, warm caches
    cpu_us = None
    if not args.wake:
        cpu0 = time.process_time()
        InprocExecutor(plan, fast=True, tick_s=args.tick).run(args.duration)
        cpu_us = (time.process_time() - cpu0) / ticks * 1e6

    ex = InprocExecutor(plan, fast=True, tick_s=args.tick)
    groups = place(plan, fast=True).groups  # the processes a real run would start, nodes in order
    woken = {nodes[0] for nodes in groups.values()} if args.wake else set()
    calls: dict[str, list[int]] = defaultdict(list)
    for name, block in ex.blocks.items():
        block.step = _timed(block.step, calls[name], args.wake if name in woken else 0.0)  # type: ignore[method-assign]
    ex.run(args.duration)

    wake = f", a {args.wake * 1e3:g} ms sleep before {', '.join(sorted(woken))}" if woken else ""
    print(f"{args.graph}: {ticks} ticks of {args.tick * 1e3:g} ms{wake}")
    for name, ns in calls.items():
        if ns:
            mean, median = statistics.fmean(ns) / 1e3, statistics.median(ns) / 1e3
            print(f"  {name:16s} {mean:8.2f} µs per step, median {median:.2f}  ({len(ns)} steps)")
    steps_us = sum(sum(ns) for ns in calls.values()) / ticks / 1e3
    whole = "" if cpu_us is None else f"; the whole run: {cpu_us:.1f} µs of CPU per tick"
    print(f"blocks' steps: {steps_us:.1f} µs per tick{whole}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
