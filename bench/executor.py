"""Framework overhead and whole-graph speed of the in-process executor.

Measures, in one run (one core, median of repeats):
  1. per-chunk framework overhead: a chain of pass-through nodes run by the executor vs the same
     blocks called directly in a loop (the baseline), in µs per node-step, for 1- and 1000-sample chunks;
  2. the NLIF block inside the executor (N neurons, 1000-sample chunks) in neuron-steps/s, vs the same
     block called directly (ratio), against the bar of 5e8 neuron-steps/s;
  3. graphs/touch.yaml in --fast mode: real-time factor (bar: >= 500x).

    python bench/executor.py [--quick] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from dataclasses import dataclass
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import numpy as np
from _timing import median_time

from flowtact import Block, Chunk, Config, Example, Port, Source, StreamSpec, param
from flowtact.compile import compile_graph
from flowtact.graph import load_graph
from flowtact.runtime.inproc import InprocExecutor
from flowtact.runtime.stats import format_factor

ROOT = Path(__file__).resolve().parent.parent


@dataclass(frozen=True)
class SrcConfig(Config):
    rate_hz: float = param(1000.0, doc="rate", gt=0)
    channels: int = param(1, doc="channels", ge=1)


class Src(Source):
    """Zeros at rate_hz."""

    config_cls = SrcConfig
    outputs = {"y": Port(doc="zeros")}

    def specs(self, inputs):  # noqa: ARG002 — a source: its outputs come from its config
        return {"y": StreamSpec(shape=(self.config.channels,), rate_hz=self.config.rate_hz)}

    def reset(self):
        self.i = 0

    def step(self, now):
        n = self.due(now, self.config.rate_hz) - self.i
        t = (self.i + np.arange(n)) / self.config.rate_hz
        self.i += n
        return {"y": Chunk(t, np.zeros((n, self.config.channels)))}

    @classmethod
    def example(cls):
        return Example()


class Pass(Block):
    """y = x."""

    config_cls = Config
    inputs = {"x": Port(doc="in")}
    outputs = {"y": Port(doc="out")}

    def step(self, x):
        return {"y": x}


def chain_graph(n_nodes: int) -> str:
    nodes = ['  src: {block: "__main__:Src"}'] + [
        f'  p{i}: {{block: "__main__:Pass"}}' for i in range(n_nodes)
    ]
    edges = ["  - src.y -> p0.x"] + [f"  - p{i}.y -> p{i + 1}.x" for i in range(n_nodes - 1)]
    return "nodes:\n" + "\n".join(nodes) + "\nedges:\n" + "\n".join(edges) + f"\nrecord: [p{n_nodes - 1}.y]\n"


def bench_overhead(chunk: int, n_nodes: int, n_ticks: int, repeats: int) -> dict:
    plan = compile_graph(load_graph("chain.yaml", text=chain_graph(n_nodes)))
    tick = chunk / 1000.0
    duration = n_ticks * tick

    def framework():
        InprocExecutor(plan, fast=True, tick_s=tick).run(duration)

    blocks = [Pass(node=f"p{i}") for i in range(n_nodes)]
    spec = StreamSpec(shape=(1,), rate_hz=1000.0)
    for b in blocks:
        b.bind({"x": spec})
    src = Src()
    src.bind({})

    def direct():
        src.restart()
        for k in range(1, n_ticks + 1):
            c = src(k * tick)["y"]
            for b in blocks:
                c = b(x=c)["y"]

    t_fw = median_time(framework, repeats)
    t_direct = median_time(direct, repeats)
    steps = n_ticks * (n_nodes + 1)
    return {
        "chunk_samples": chunk,
        "nodes": n_nodes + 1,
        "executor_us_per_node_step": 1e6 * t_fw / steps,
        "direct_us_per_node_step": 1e6 * t_direct / steps,
        "framework_overhead_us_per_node_step": 1e6 * (t_fw - t_direct) / steps,
        "ratio_executor_vs_direct": t_fw / t_direct,
    }


class Ones(Src):
    """Ones at rate_hz, one value per sample: a constant drive for the NLIF population."""

    def specs(self, inputs):  # noqa: ARG002 — a source: its outputs come from its config
        return {"y": StreamSpec(shape=(), rate_hz=self.config.rate_hz)}

    def step(self, now):
        out = super().step(now)["y"]
        return {"y": Chunk(out.t, np.ones(len(out)))}


def bench_nlif(n: int, sigma: float, seconds: float, repeats: int) -> dict:
    text = f"""
nodes:
  src: {{block: "__main__:Ones"}}
  pop: {{block: nlif, params: {{n: {n}, tau_s: 0.01, v_leak: 0.0, gain: 1.2, sigma: {sigma}, refractory_s: 0.0}}}}
edges:
  - src.y -> pop.x
record: [pop.spikes]
"""
    plan = compile_graph(load_graph("nlif.yaml", text=text))

    def framework():
        InprocExecutor(plan, fast=True, tick_s=1.0).run(seconds)

    framework()  # compile the numba kernels first
    t = median_time(framework, repeats)
    return {"n": n, "sigma": sigma, "neuron_steps_per_s": n * seconds * 1000 / t, "wall_s": t}


def bench_touch(seconds: float, repeats: int) -> dict:
    plan = compile_graph(load_graph(ROOT / "graphs" / "touch.yaml"))
    InprocExecutor(plan, fast=True).run(1.0)  # warm up numba caches
    t = median_time(lambda: InprocExecutor(plan, fast=True).run(seconds), repeats)
    return {"graph_seconds": seconds, "wall_s": t, "realtime_factor": seconds / t}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer repeats and shorter runs")
    ap.add_argument("--json", help="write results to this file")
    args = ap.parse_args()
    reps = 3 if args.quick else 7
    results: dict = {"overhead": [], "nlif": [], "touch": None}
    print("1. framework overhead per node-step (10 pass-through nodes after a source)")
    print(f"   {'chunk':>6} {'executor µs':>12} {'direct µs':>10} {'overhead µs':>12} {'ratio':>6}")
    for chunk, ticks in ((1, 2000), (1000, 200)):
        r = bench_overhead(chunk, 10, ticks // (2 if args.quick else 1), reps)
        results["overhead"].append(r)
        print(
            f"   {chunk:>6} {r['executor_us_per_node_step']:>12.2f} {r['direct_us_per_node_step']:>10.2f} "
            f"{r['framework_overhead_us_per_node_step']:>12.2f} {r['ratio_executor_vs_direct']:>6.2f}"
        )
    print("2. NLIF block inside the executor, 1000-sample chunks (bar: >= 5e8 neuron-steps/s for N >= 1000)")
    for n in (1000, 10000):
        for sigma in (0.0, 1.0):
            r = bench_nlif(n, sigma, 5.0 if args.quick else 10.0, reps)
            results["nlif"].append(r)
            print(f"   N={n:>6} sigma={sigma:<4} {r['neuron_steps_per_s']:.3g} neuron-steps/s")
    print("3. graphs/touch.yaml --fast (bar: >= 500x real time)")
    r = bench_touch(30.0 if args.quick else 60.0, reps)
    results["touch"] = r
    print(
        f"   {r['graph_seconds']:.0f} s of graph time in {r['wall_s']:.3f} s: {format_factor(r['realtime_factor'])} real time"
    )
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2))


if __name__ == "__main__":
    sys.exit(main())
