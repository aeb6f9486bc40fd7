"""Suite ``executor``: framework overhead and whole-graph speed of the in-process executor.

Measures, in one run (one core, median of repeats):
  1. per-chunk framework overhead: a chain of pass-through nodes run by the executor vs the same
     blocks called directly in a loop (the baseline), in µs per node-step, for 1- and 1000-sample chunks;
  2. the NLIF block inside the executor (N neurons, 1000-sample chunks) in neuron-steps/s, vs the same
     block called directly (ratio), against the bar of 5e8 neuron-steps/s;
  3. graphs/touch.yaml in --fast mode: real-time factor (bar: >= 500x).
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path

import numpy as np

from flowtact import Block, Chunk, Config, Example, Port, Source, StreamSpec, param
from flowtact.benchmark import Context, Suite
from flowtact.compile import compile_graph
from flowtact.graph import load_graph
from flowtact.runtime.inproc import InprocExecutor


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
    nodes = ['  src: {block: "flowtact.bench.executor:Src"}'] + [
        f'  p{i}: {{block: "flowtact.bench.executor:Pass"}}' for i in range(n_nodes)
    ]
    edges = ["  - src.y -> p0.x"] + [f"  - p{i}.y -> p{i + 1}.x" for i in range(n_nodes - 1)]
    return "nodes:\n" + "\n".join(nodes) + "\nedges:\n" + "\n".join(edges) + f"\nrecord: [p{n_nodes - 1}.y]\n"


def bench_overhead(ctx: Context, chunk: int, n_nodes: int, n_ticks: int) -> None:
    """µs per node-step: the executor running the chain vs the same blocks called directly."""
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

    steps = n_ticks * (n_nodes + 1)
    params = {"chunk_samples": chunk, "nodes": n_nodes + 1}
    base = f"direct calls, chunk {chunk}"
    ctx.duration(
        base,
        direct,
        scale=1e6 / steps,
        unit="µs per node-step",
        is_baseline=True,
        reference=True,
        params=params,
    )
    ctx.duration(f"executor, chunk {chunk}", framework, scale=1e6 / steps, unit="µs per node-step",
                 baseline=base, params=params)  # fmt: skip


class Ones(Src):
    """Ones at rate_hz, one value per sample: a constant drive for the NLIF population."""

    def specs(self, inputs):  # noqa: ARG002 — a source: its outputs come from its config
        return {"y": StreamSpec(shape=(), rate_hz=self.config.rate_hz)}

    def step(self, now):
        out = super().step(now)["y"]
        return {"y": Chunk(out.t, np.ones(len(out)))}


def nlif_plan(n: int, sigma: float):
    text = f"""
nodes:
  src: {{block: "flowtact.bench.executor:Ones"}}
  pop: {{block: nlif, params: {{n: {n}, tau_s: 0.01, v_leak: 0.0, gain: 1.2, sigma: {sigma}, refractory_s: 0.0}}}}
edges:
  - src.y -> pop.x
record: [pop.spikes]
"""
    return compile_graph(load_graph("nlif.yaml", text=text))


def bench_nlif(ctx: Context, n: int, sigma: float, seconds: float) -> None:
    """Neuron-steps/s of the NLIF block inside the executor vs the same block called directly."""
    from flowtact.blocks.spiking.nlif import Nlif  # the measured block (the harness itself knows no blocks)

    plan = nlif_plan(n, sigma)
    n_t = round(seconds * 1000)
    t = np.arange(n_t) / 1000.0
    x = np.ones(n_t)
    chunks = [Chunk(t[i : i + 1000], x[i : i + 1000]) for i in range(0, n_t, 1000)]
    blk = Nlif(n=n, tau_s=0.01, v_leak=0.0, gain=1.2, sigma=sigma, refractory_s=0.0)

    def direct() -> None:
        blk.bind({"x": StreamSpec(rate_hz=1000.0)}, seed=1, demanded=frozenset({"spikes"}))
        for c in chunks:
            blk(x=c)

    params = {"n": n, "sigma": sigma}
    base = f"NLIF block called directly, N={n}, sigma={sigma:g}"
    ctx.speed(
        base, direct, n * n_t, "neuron-steps/s", is_baseline=True, reference=True, params=params, warmup=2
    )
    fig = ctx.speed(f"NLIF in the executor, N={n}, sigma={sigma:g}",
                    lambda: InprocExecutor(plan, fast=True, tick_s=1.0).run(seconds), n * n_t, "neuron-steps/s",
                    baseline=base, params=params, warmup=2)  # fmt: skip
    if sigma == 0:
        ctx.check(f"NLIF N={n} in the executor >= 5e8 neuron-steps/s", fig.median >= 5e8, f"{fig.median:.3g}")


def bench_touch(ctx: Context, seconds: float) -> None:
    """graphs/touch.yaml --fast: its real-time factor, against the bar of 500x."""
    plan = compile_graph(load_graph(Path(str(files("flowtact.graphs") / "touch.yaml"))))
    InprocExecutor(plan, fast=True).run(1.0)  # warm up numba caches
    fig = ctx.speed("graphs/touch.yaml --fast", lambda: InprocExecutor(plan, fast=True).run(seconds), seconds,
                    "× real time", params={"graph_seconds": seconds})  # fmt: skip
    ctx.check("touch.yaml --fast >= 500x real time", fig.median >= 500, f"{fig.median:.0f}x")


def run(ctx: Context) -> None:
    for chunk, ticks in ((1, 2000), (1000, 200)):
        bench_overhead(ctx, chunk, 10, ticks // (2 if ctx.quick else 1))
    for n in (1000, 10000):
        for sigma in (0.0, 1.0):
            bench_nlif(ctx, n, sigma, 5.0 if ctx.quick else 10.0)
    bench_touch(ctx, 30.0 if ctx.quick else 60.0)
    ctx.note(
        "The touch graph's real-time factor has no baseline figure: it is compared with the bar (500×). "
        "The executor's cost per node-step beyond direct calls is the framework overhead."
    )


SUITE = Suite(
    name="executor",
    title="In-process executor: framework overhead and whole-graph speed",
    measures="µs per node-step of a chain of 10 pass-through nodes run by the executor (1- and 1000-sample "
    "chunks); the NLIF block (N = 1 000 and 10 000, 1000-sample chunks) inside the executor in "
    "neuron-steps/s; graphs/touch.yaml in `--fast` mode as a real-time factor.",
    baseline="the same blocks called directly in a plain Python loop (no executor)",
    run=run,
    minutes_quick=0.5,
    minutes_full=1.5,
)
