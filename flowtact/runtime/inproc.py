"""The in-process executor: the engine with local links, every active node in one loop, deterministic.

The tick schedule is :class:`~flowtact.runtime.engine.Engine`'s; this module adds what a run needs
around it (opening and closing blocks, warming up, the clock, progress) and the run's summary
(a :class:`~flowtact.runtime.summary.RunSummary`, what every executor returns).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping

from flowtact.block import Block
from flowtact.running.compile import CompiledGraph
from flowtact.runtime.clock import LAG_WARN_S, Clock, FastClock, RealtimeClock, tick_for
from flowtact.runtime.engine import Engine, NodeError, Sink, check_chunk
from flowtact.runtime.executors import RunOptions
from flowtact.runtime.summary import RunSummary
from flowtact.runtime.warm_up import warm_up_here

__all__ = [
    "InprocExecutor",
    "NodeError",
    "RunSummary",
    "Sink",
    "block_summaries",
    "check_chunk",
    "explain_counters",
]


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
        link: str = "local",
    ) -> None:
        """``link``: the kind of link joining the nodes (:func:`~flowtact.runtime.links.link_kind`)."""
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
        self.engine = Engine(plan, self.blocks, recorder=recorder, link=link)
        self._made = time.perf_counter()  # start-up counts from here: the blocks were just made

    @classmethod
    def for_run(cls, plan: CompiledGraph, options: RunOptions) -> InprocExecutor:
        """The executor ``flowtact run --inproc`` makes: warmed up as a worker is, so kernel
        loading is start-up, apart from the running time."""
        o = options
        return cls(plan, fast=o.fast, tick_s=o.tick_s, recorder=o.recorder, progress=o.progress, warm_up=True)

    def run(self, duration_s: float | None) -> RunSummary:
        """Run until ``duration_s`` of graph time (None: until interrupted; realtime only)."""
        if duration_s is None and self.fast:
            raise ValueError("a --fast run needs a duration (--duration or the graph's duration_s)")
        clock: Clock = FastClock() if self.fast else RealtimeClock()
        opened: list[Block] = []
        stopped_by = "duration"
        now, k, lag = 0.0, 0, 0.0
        engine, fast = self.engine, self.fast
        engine.bind_steps()
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
                    engine.tick(now)
                    if self.recorder is not None:
                        self.recorder.maybe_flush()  # a quiet spell must not hold data back
                    if self.progress is not None:
                        self.progress(now, duration_s)
            except KeyboardInterrupt:
                stopped_by = "interrupted"
                engine.interrupt()  # the interrupted tick's delayed outputs never arrive
            running_s = clock.elapsed()
            engine.finish(now)
            said = block_summaries(self.blocks)
        finally:
            for block in reversed(opened):
                block.close()
        counters = {n: dict(b.counters) for n, b in self.blocks.items() if b.counters}
        samples, events = engine.tallies()
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
