"""The in-process executor: every active node of a plan in one loop, deterministic.

Each tick, sources are stepped with the graph time ``now`` and every other node, in topological
order, receives what its upstream produced during the tick (or, through a delay port, during the
previous tick). Only demanded outputs travel; recorded streams go to the recorder. At the end
every node is flushed in order so held-back samples (a centred filter's tail) reach the sinks.
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from flowtact.block import Block
from flowtact.chunk import Chunk, StreamSpec, concat
from flowtact.errors import NodeError
from flowtact.running.compile import CompiledGraph
from flowtact.runtime.clock import LAG_WARN_S, Clock, FastClock, RealtimeClock, tick_for
from flowtact.runtime.sealing import sealed
from flowtact.runtime.stats import format_factor
from flowtact.runtime.step_plan import NodePlan, OutPlan, build_plans, takes_first, tallies
from flowtact.runtime.warm_up import warm_up_here

__all__ = ["InprocExecutor", "RunSummary", "block_summaries", "check_chunk", "explain_counters"]


class Sink(Protocol):
    """What the executor writes recorded streams to (a :class:`flowtact.recording.hdf5.Recorder`)."""

    def write(self, stream: str, chunk: Chunk) -> None: ...

    def maybe_flush(self) -> None: ...


@dataclass
class RunSummary:
    """What a run did: samples, spikes per population, wall time, real-time factor, counters."""

    graph: str
    duration_s: float
    wall_s: float
    stopped_by: str
    running_s: float | None = None
    """Seconds from graph time 0 (the first tick's clock start) to the end of the last tick
    (multi-process: the last worker's end), without the start-up that ``wall_s`` includes."""
    startup_s: float | None = None
    """Seconds from launch to graph time 0: making and opening blocks, compiling or loading kernels
    (warming up), and (multi-process) spawning and wiring the workers. Shown apart from the
    real-time factor. An in-process --fast executor made without ``warm_up`` loads its kernels in
    its blocks' first steps, inside the running time (``flowtact run`` and sweeps warm up)."""
    samples: dict[str, int] = field(default_factory=dict)
    events: dict[str, int] = field(default_factory=dict)
    event_units: dict[str, int] = field(default_factory=dict)
    counters: dict[str, dict[str, int]] = field(default_factory=dict)
    pruned: list[str] = field(default_factory=list)
    ticks: int = 0
    processes: dict[str, dict[str, Any]] = field(default_factory=dict)
    """Multi-process runs: per process group, pid, host, nodes, CPU % of one core, restarts."""
    supervisor_cpu_pct: float | None = None
    """Multi-process runs: the supervisor's own CPU (% of one core) over the workers' window."""
    streams: dict[str, dict[str, Any]] = field(default_factory=dict)
    """Multi-process runs: per cross-process stream, messages, samples, drops, latency (µs)."""
    paths: dict[str, dict[str, Any]] = field(default_factory=dict)
    """Declared deadlines: latency p50/p99/max (µs), budget and violations per path."""
    counter_docs: dict[str, dict[str, str]] = field(default_factory=dict)
    """What each reported counter means, per node (its block's ``counter_docs``; see explain_counters)."""
    realtime: bool | None = None
    """Real-time runs: did every tick run within :data:`LAG_WARN_S` of the wall clock? None: --fast."""
    max_lag_s: float = 0.0
    """Real-time runs: the furthest any tick ran behind the wall clock (s)."""
    late_nodes: list[str] = field(default_factory=list)
    """Real-time runs that fell behind: the nodes that took most of the wall time then."""
    notes: list[str] = field(default_factory=list)
    """Things the run should tell (a played-back file that ended before the run did)."""
    block_summaries: dict[str, str] = field(default_factory=dict)
    """What blocks said of their run (:meth:`flowtact.block.Block.summary`), per node: ``read 26
    letters, 26 right``; printed under the counters."""

    @property
    def realtime_factor(self) -> float:
        """Graph seconds per *running* second (from graph time 0; start-up is ``startup_s``, apart):
        1.0 for a real-time run that kept up. ``wall_s`` stands in when no running span is known."""
        span = self.running_s if self.running_s is not None else self.wall_s
        return self.duration_s / span if span > 0 else math.inf

    @property
    def shown_paths(self) -> dict[str, dict[str, Any]]:
        """Deadline paths worth telling: none on the virtual clock (``--fast``), whose wall-clock
        latencies say nothing about the budgets a deadline declares."""
        return {} if self.realtime is None else self.paths

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "graph": self.graph,
            "duration_s": self.duration_s,
            "wall_s": self.wall_s,
            "running_s": self.running_s,
            "startup_s": self.startup_s,
            "realtime_factor": self.realtime_factor,
            "stopped_by": self.stopped_by,
            "realtime": self.realtime,
            "max_lag_s": self.max_lag_s,
            "late_nodes": self.late_nodes,
            "ticks": self.ticks,
            "samples": self.samples,
            "events": self.events,
            "event_rate_hz_per_unit": {k: self.rate(k) for k in self.events},
            "counters": self.counters,
            "counter_docs": self.counter_docs,
            "pruned": self.pruned,
            "processes": self.processes,
            "supervisor": {"cpu_pct": self.supervisor_cpu_pct},
            "streams": self.streams,
            "paths": self.shown_paths,
            "notes": self.notes,
            "block_summaries": self.block_summaries,
        }

    def rate(self, stream: str) -> float:
        """Mean events per second per unit on an event stream."""
        units = max(self.event_units.get(stream, 1), 1)
        return self.events[stream] / units / self.duration_s if self.duration_s > 0 else 0.0

    def _headline(self) -> str:
        """``touch: 3.000 s of graph time in 3.002 s (1.0× real time, duration); start-up 9.8 s``:
        the factor over the running span, the start-up apart (see :attr:`realtime_factor`)."""
        running = self.running_s if self.running_s is not None else self.wall_s
        startup = f"; start-up {self.startup_s:.1f} s" if self.startup_s is not None else ""
        return (
            f"{self.graph}: {self.duration_s:.3f} s of graph time in {running:.3f} s "
            f"({format_factor(self.realtime_factor)} real time, {self.stopped_by}){startup}"
        )

    def format(self) -> str:
        """A short human summary."""
        lines = [self._headline()]
        if self.realtime is False:
            busiest = f"; busiest nodes: {', '.join(self.late_nodes)}" if self.late_nodes else ""
            lines.append(
                f"  NOT real time: ticks ran up to {self.max_lag_s:.2f} s behind the wall clock{busiest} "
                "(late ticks were merged: same outputs, later)"
            )
        for k, n in self.samples.items():
            lines.append(f"  {k:<28} {n:>10,} samples")
        for k, n in self.events.items():
            lines.append(
                f"  {k:<28} {n:>10,} events  ({self.rate(k):.1f}/s per unit, {self.event_units.get(k, 1)} units)"
            )
        counted = [
            (f"{node}: {k}={v}", self.counter_docs.get(node, {}).get(k))
            for node, cs in self.counters.items()
            for k, v in sorted(cs.items())
        ]
        width = max((len(c) for c, _ in counted), default=0)
        lines += [f"  {c:<{width}}  {doc}" if doc else f"  {c}" for c, doc in counted]
        lines += [f"  {node}: {text}" for node, text in self.block_summaries.items()]
        for name, p in self.processes.items():
            cpu = f"{p['cpu_pct']:.1f}% CPU" if p.get("cpu_pct") is not None else "CPU n/a"
            restarts = f", {p['restarts']} restart(s)" if p.get("restarts") else ""
            lines.append(f"  process {name:<20} {cpu}{restarts}  [{', '.join(p['nodes'])}]")
        if self.supervisor_cpu_pct is not None:
            lines.append(f"  supervisor {'':<17} {self.supervisor_cpu_pct:.1f}% CPU  [control, recording]")
        for name, st in self.streams.items():
            lat = st["latency_us"]
            latency = (
                f"latency p50 {lat['p50']:.0f} µs p99 {lat['p99']:.0f} µs" if lat.get("n") else "no latency"
            )
            dropped = f", {st['dropped']} dropped" if st["dropped"] else ""
            lines.append(
                f"  stream {name:<21} {st['messages']:>8,} msgs ({st['policy']}), {latency}{dropped}"
            )
        for name, pa in self.shown_paths.items():
            if pa.get("n"):
                lines.append(
                    f"  deadline {name}: p50 {pa['p50_us']:.0f} µs, p99 {pa['p99_us']:.0f} µs "
                    f"(budget {pa['budget_us']:.0f} µs, {pa['violations']} missed)"
                )
        if self.pruned:
            lines.append(f"  not started: {', '.join(self.pruned)}")
        lines += [f"  note: {n}" for n in self.notes]
        return "\n".join(lines)


class InprocExecutor:
    """Runs a :class:`~flowtact.running.compile.CompiledGraph` in this process."""

    def __init__(
        self,
        plan: CompiledGraph,
        *,
        fast: bool = True,
        tick_s: float | None = None,
        recorder: Sink | None = None,
        progress: Callable[[float, float | None], None] | None = None,
        warm_up: bool | None = None,
    ) -> None:
        self.plan = plan
        self.fast = fast
        self.warm_up = not fast if warm_up is None else warm_up
        """Load or compile kernels before graph time 0 (:func:`warm_up_here`, on throwaway copies
        of the blocks, as a worker does): always in real time; in --fast when asked (``flowtact
        run --inproc``, sweeps), so their kernel loading is start-up, not running time."""
        self.tick_s = tick_for(fast, tick_s)
        self.recorder = recorder
        self.progress = progress
        self.blocks: dict[str, Block] = {n: plan.graph.nodes[n].make() for n in plan.order}
        for n, block in self.blocks.items():
            plan.bind(n, block)
        self.nodes, self._delay_ports = build_plans(plan, self.blocks)
        self._delivered: list[OutPlan] = []  # outputs counted in the summary, by first delivery
        self._made = time.perf_counter()  # start-up counts from here: the blocks were just made

    def _step(self, nodes: Iterable[NodePlan], now: float, at_end: bool, flush: bool = False) -> None:  # noqa: C901 — the hot loop, inline on purpose (see the docstring)
        """Step each node in ``nodes`` on its inboxes (a non-source only when something came), or
        ``flush`` it, and hand each demanded output, admitted (:meth:`_admit`), to its consumers
        and recorder (``at_end``: delayed outputs go straight to their consumers).

        Inputs reach ``step`` as they left their producer (read-only, see :meth:`_admit`), an inbox
        holding several chunks joined. ``step`` is called directly (the block is bound), with the
        node's own keyword dict refilled every time: every needed port is set, and Python hands the
        callee its own copy of the keywords, so reusing the dict is safe. A node with one input
        that is its ``step``'s first parameter gets it positionally (the same binding, cheaper).
        One call per tick, the delivery inline, the demanded outputs looked up rather than what the
        block returned walked: each call or dict walk costs a tenth of the 1 µs per node-step the
        executor is allowed here (``flowtact bench executor``).
        """
        recorder, delivered = self.recorder, self._delivered
        for nd in nodes:
            given = None  # the one input, handed to ``step`` by position
            try:
                if flush:
                    out = nd.block.flush()
                elif nd.solo:  # the common filter: one input, ``step``'s first parameter
                    _, box, empty, spec = nd.inputs[0]
                    given = box.pop() if len(box) == 1 else _take(box, empty, spec)
                    if not (len(given.t) or given.end is not None):
                        continue
                    out = nd.call(given)
                else:
                    kw = nd.kw
                    live = nd.source
                    for port, box, empty, spec in nd.inputs:
                        c = box.pop() if len(box) == 1 else _take(box, empty, spec)
                        if port is not None:
                            kw[port] = c
                        if not live and (len(c.t) or c.end is not None):
                            live = True
                    if not live:
                        continue
                    out = nd.call(now, **kw) if nd.source else nd.call(**kw)
            except Exception as e:
                raise NodeError(nd.name, nd.block.name, now, e) from e
            for o in nd.outs:
                chunk = out.get(o.port)
                if chunk is None:
                    continue  # not produced this time
                if chunk is not given or o.kind is not nd.in_kind:
                    chunk = self._admit(nd.name, chunk, o, now)
                for box in o.now:
                    box.append(chunk)
                if o.later:
                    for box in o.delayed_into if at_end else o.later:
                        box.append(chunk)
                if o.tally is not None:
                    if not o.seen:
                        o.seen = True
                        delivered.append(o)
                    o.count += len(chunk.t)
                    if o.record is not None and recorder is not None:
                        recorder.write(o.record, chunk)

    def _admit(self, node: str, chunk: Chunk, o: OutPlan, now: float) -> Chunk:
        """Check a produced chunk against its stream and seal it read-only.

        The check is the common case of :func:`check_chunk` (1-D ``t``, one data row per time
        stamp, the declared sample shape and dtype); anything else goes to the full check, which
        names the bug. Sealing (:func:`~flowtact.runtime.sealing.sealed`) lets every consumer get
        the same object: none can change what another receives. A block that hands on the one
        input it was given, to a stream of the same kind, skips both (see :meth:`_step`); a chunk
        admitted again (a gate handing on one of several inputs) passes the check and is already
        sealed.
        """
        t, d = chunk.t, chunk.data
        shape = d.shape
        if (
            t.ndim != 1
            or not shape
            or shape[0] != len(t)
            or shape[1:] != o.tail
            or (d.dtype is not o.dtype and d.dtype != o.dtype)
        ):
            check_chunk(node, o.port, chunk, o.spec, now)
        return sealed(chunk, t, d)

    def run(self, duration_s: float | None) -> RunSummary:
        """Run until ``duration_s`` of graph time (None: until interrupted; realtime only)."""
        if duration_s is None and self.fast:
            raise ValueError("a --fast run needs a duration (--duration or the graph's duration_s)")
        clock: Clock = FastClock() if self.fast else RealtimeClock()
        opened: list[Block] = []
        stopped_by = "duration"
        now, k, lag = 0.0, 0, 0.0
        nodes, step, delay_ports, fast = self.nodes, self._step, self._delay_ports, self.fast
        for nd in nodes:
            nd.call = nd.block.step  # looked up per run, so a test may replace it
            nd.solo = takes_first(nd.call, nd.inputs)
        try:
            for block in self.blocks.values():
                block.open()
                opened.append(block)
            if self.warm_up:  # kernels load or compile now, not on the clock the factor is taken on
                warm_up_here(self.blocks, self.tick_s)
            clock.start()
            startup_s = time.perf_counter() - self._made
            n_ticks = math.ceil(duration_s / self.tick_s - 1e-9) if duration_s is not None else None
            try:
                while n_ticks is None or k < n_ticks:
                    k += 1
                    now = k * self.tick_s if n_ticks is None or k < n_ticks else float(duration_s)  # type: ignore[arg-type]
                    if not fast:
                        lag = max(lag, clock.wait_until(now))
                    step(nodes, now, False)
                    for box, later in delay_ports:  # what went through a delay port arrives next tick
                        if later:
                            box.extend(later)
                            later.clear()
                    if self.recorder is not None:
                        self.recorder.maybe_flush()  # a quiet spell must not hold data back
                    if self.progress is not None:
                        self.progress(now, duration_s)
            except KeyboardInterrupt:
                stopped_by = "interrupted"
                for _, later in delay_ports:  # the interrupted tick's delayed outputs never arrive
                    later.clear()
            running_s = clock.elapsed()
            self._flush_all(now)
            said = block_summaries(self.blocks)
        finally:
            for block in reversed(opened):
                block.close()
        counters = {n: dict(b.counters) for n, b in self.blocks.items() if b.counters}
        samples, events = tallies(self._delivered)
        return RunSummary(
            graph=self.plan.graph.name,
            duration_s=now,
            wall_s=time.perf_counter() - self._made,
            running_s=running_s,
            startup_s=startup_s,
            stopped_by=stopped_by,
            samples=samples,
            events=events,
            event_units={
                f"{n}.{p}": self.plan.specs[(n, p)].n_units or 1
                for n in self.plan.order
                for p in self.plan.demanded[n]
                if self.plan.specs[(n, p)].events
            },
            counters=counters,
            pruned=list(self.plan.pruned),
            ticks=k,
            counter_docs=explain_counters(self.plan, counters),
            realtime=None if self.fast else lag < LAG_WARN_S,
            max_lag_s=lag,
            block_summaries=said,
        )

    def _flush_all(self, now: float) -> None:
        """End of stream: feed what is pending, then flush each node in order."""
        for nd in self.nodes:
            if not nd.source:
                self._step((nd,), now, True)
            self._step((nd,), now, True, flush=True)


def _take(box: list[Chunk], empty: Chunk, spec: StreamSpec) -> Chunk:
    """What an inbox holding other than one chunk gives: its empty chunk, or its chunks joined."""
    if not box:
        return empty
    c = concat(box, spec).readonly()
    box.clear()
    return c


SUMMARY_MAX_CHARS = 240
"""A block's summary line is cut to this many characters: it is a line of the run summary, and a
worker sends it to the supervisor with its last message (a block's bug must not flood either)."""


def block_summaries(blocks: Mapping[str, Block]) -> dict[str, str]:
    """What each block says of its run (its :meth:`~flowtact.block.Block.summary`), per node, for
    the blocks that say something; asked after the final flush, before ``close``."""
    out: dict[str, str] = {}
    for node, block in blocks.items():
        try:
            text = block.summary()
        except Exception as e:
            raise NodeError(node, block.name, math.nan, e) from e
        if text:
            line = " ".join(str(text)[: 4 * SUMMARY_MAX_CHARS].split())  # one line, whatever it returned
            out[node] = line if len(line) <= SUMMARY_MAX_CHARS else line[: SUMMARY_MAX_CHARS - 1] + "…"
    return out


def explain_counters(
    plan: CompiledGraph, counters: Mapping[str, Mapping[str, int]]
) -> dict[str, dict[str, str]]:
    """What each counter in ``counters`` (node -> name -> count) means, from its node's block class."""
    out: dict[str, dict[str, str]] = {}
    for node, cs in counters.items():
        nd = plan.graph.nodes.get(node)
        docs = nd.cls.documented_counters() if nd is not None else {}
        if known := {k: docs[k] for k in cs if k in docs}:
            out[node] = known
    return out


@functools.cache
def _dtype(name: str) -> np.dtype:
    return np.dtype(name)


def check_chunk(node: str, port: str, chunk: Chunk, spec: StreamSpec, now: float) -> None:
    """Guard the stream contract: a block's output must match its declared spec."""
    n = chunk.t.shape[0]
    shape = chunk.data.shape
    if shape[0:1] != (n,) or shape[1:] != spec.shape or chunk.data.dtype != _dtype(spec.dtype):
        raise RuntimeError(
            f"node '{node}' produced {chunk.data.dtype}{list(chunk.data.shape)} with {n} timestamps on "
            f"'{port}' at t={now:.3f} s, but the stream is {spec.describe()} (a bug in the block)"
        )
