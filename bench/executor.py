"""Suite ``executor``: framework overhead and whole-graph speed of the in-process executor.

Measures, in one run (one core, median of repeats):
  1. per-chunk framework overhead, in µs per node-step of a source and 10 pass-through nodes, for 1-
     and 1000-sample chunks: a plain Python call chain (the floor), the blocks' ``step`` called directly
     (their own cost), the same through ``Block.__call__``, and the executor. The executor's framework
     overhead is executor − block steps, per pair of runs timed back to back, divided by ticks × nodes;
     the bar is <= 1 µs per node-step;
  2. the NLIF block inside the executor (N neurons, 1000-sample chunks) in neuron-steps/s, vs the same
     block called directly (ratio), against the bar of 5e8 neuron-steps/s;
  3. graphs/touch.yaml in --fast mode: real-time factor (bar: >= 500x).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path

import numpy as np

from flowtact import Block, Chunk, Config, Example, Port, Source, StreamSpec, param
from flowtact.benchmark import Context, Suite
from flowtact.graphfile.graph import load_graph
from flowtact.running.compile import compile_graph
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


def _pass_along(c: object) -> object:
    return c


def bench_overhead(ctx: Context, chunk: int, n_nodes: int, n_ticks: int) -> list[object]:
    """µs per node-step of a source and a chain of pass-through nodes, four ways, and the executor's
    framework overhead: executor minus the blocks' own ``step`` calls, pair by pair."""
    plan = compile_graph(
        load_graph("chain.yaml", text=chain_graph(n_nodes), allow_modules=["flowtact.bench.executor"])
    )
    tick = chunk / 1000.0
    duration = n_ticks * tick
    blocks = [Pass(node=f"p{i}") for i in range(n_nodes)]
    spec = StreamSpec(shape=(1,), rate_hz=1000.0)
    for b in blocks:
        b.bind({"x": spec})
    src = Src()
    src.bind({})
    chain = [_pass_along] * (n_nodes + 1)

    def plain() -> None:  # the floor: one Python call per node-step, nothing else
        for _ in range(n_ticks):
            c: object = src
            for f in chain:
                c = f(c)

    def steps() -> None:  # the blocks' own work: each ``step`` called directly
        src.restart()
        for k in range(1, n_ticks + 1):
            c = src.step(k * tick)["y"]
            for b in blocks:
                c = b.step(x=c)["y"]

    def called() -> None:  # the same through Block.__call__ (what tests and flowtact.testing use)
        src.restart()
        for k in range(1, n_ticks + 1):
            c = src(k * tick)["y"]
            for b in blocks:
                c = b(x=c)["y"]

    # One round times all four back to back (a fresh executor, built untimed), so each executor run
    # pairs with the block-steps run just before it; the first round only warms up.
    ways = {"plain": plain, "called": called, "steps": steps}
    us: dict[str, list[float]] = {k: [] for k in (*ways, "executor")}
    scale = 1e6 / (n_ticks * (n_nodes + 1))
    ctx.step(f"chain of {n_nodes + 1} nodes, chunk {chunk}")
    for i in range(ctx.repeats + 1):
        times = {}
        for k, fn in ways.items():
            t0 = time.perf_counter()
            fn()
            times[k] = time.perf_counter() - t0
        ex = InprocExecutor(plan, fast=True, tick_s=tick)
        t0 = time.perf_counter()
        ex.run(duration)
        times["executor"] = time.perf_counter() - t0
        if i:
            for k, sec in times.items():
                us[k].append(sec * scale)
    params = {"chunk_samples": chunk, "nodes": n_nodes + 1}
    unit = "µs per node-step"
    floor, own = f"plain Python call chain, chunk {chunk}", f"block steps called directly, chunk {chunk}"
    pl = ctx.figure(floor, us["plain"], unit, "lower", is_baseline=True, reference=True, params=params)
    st = ctx.figure(own, us["steps"], unit, "lower", baseline=floor, paired=True, is_baseline=True,
                    reference=True, params=params)  # fmt: skip
    ca = ctx.figure(f"direct calls through Block.__call__, chunk {chunk}", us["called"], unit, "lower",
                    baseline=own, paired=True, params=params)  # fmt: skip
    fig = ctx.figure(f"executor, chunk {chunk}", us["executor"], unit, "lower", baseline=own, paired=True,
                     params=params)  # fmt: skip
    overhead = [e - b for e, b in zip(us["executor"], us["steps"], strict=True)]
    ov = ctx.figure(f"executor framework overhead, chunk {chunk}", overhead, unit, "lower", params=params)
    ctx.check(
        f"executor framework overhead <= 1 µs per node-step, chunk {chunk}",
        ov.median <= 1.0,
        f"{ov.median:.2f} µs per node-step (executor {fig.median:.2f} − block steps, paired)",
    )
    return [chunk, f"{pl.median:.3f}", f"{st.median:.2f}", f"{ca.median:.2f}", f"{fig.median:.2f}",
            f"{ov.median:.2f}", f"{pl.median / fig.median:.3g}×", f"{st.median / fig.median:.2g}×"]  # fmt: skip


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
    return compile_graph(load_graph("nlif.yaml", text=text, allow_modules=["flowtact.bench.executor"]))


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
    ctx.headline("executor, chunk 1000")  # the executor against the same blocks' steps called directly
    rows = [
        bench_overhead(ctx, chunk, 10, ticks // (2 if ctx.quick else 1))
        for chunk, ticks in ((1, 2000), (1000, 2000))
    ]
    ctx.table(
        "µs per node-step, 11-node chain (a source and 10 pass-through nodes), medians",
        ["chunk samples", "plain call chain", "block steps", "Block.__call__", "executor", "overhead",
         "speed-up vs plain chain", "speed-up vs block steps"],
        rows,
        note="speed-up: the reference's µs ÷ the executor's (> 1: the executor faster; 0.5: twice as slow). "
        "overhead = executor − block steps, pair by pair (each executor run timed right after a run of "
        "the block steps, in the same round); its median is the figure checked against 1 µs.",
    )  # fmt: skip
    for n in (1000, 10000):
        for sigma in (0.0, 1.0):
            bench_nlif(ctx, n, sigma, 5.0 if ctx.quick else 10.0)
    bench_touch(ctx, 30.0 if ctx.quick else 60.0)
    ctx.note(
        "The touch graph's real-time factor has no baseline figure: it is compared with the bar (500×). "
        "Framework overhead per node-step = (wall time of InprocExecutor.run over the chain − wall time of "
        "calling the same blocks' step() directly in a Python loop, source first, passing each output on) / "
        "(ticks × 11 nodes); the executor is built outside the timed call. It is what the executor adds per "
        "node and tick: gathering inputs, calling step, checking each output against its spec, sealing it "
        "read-only, routing it and counting it. The plain call chain (11 Python functions handing an object "
        "on) is the floor of any Python loop; Block.__call__ is what tests and the worker pay per call."
    )


SUITE = Suite(
    name="executor",
    title="In-process executor: framework overhead and whole-graph speed",
    measures="µs per node-step of a source and 10 pass-through nodes (1- and 1000-sample chunks): plain "
    "Python call chain, block steps called directly, Block.__call__, the executor, and its framework overhead "
    "(executor − block steps, bar 1 µs); the NLIF block (N = 1 000 and 10 000, 1000-sample chunks) inside the executor in "
    "neuron-steps/s; graphs/touch.yaml in `--fast` mode as a real-time factor.",
    baseline="the same blocks' step() called directly in a plain Python loop (no executor), and a plain "
    "Python call chain",
    run=run,
    minutes_quick=0.2,
    minutes_full=1.5,
)
