"""What a worker measures of each node-step of its engine: the engine's one watch.

The worker runs :class:`~flowtact.runtime.engine.Engine` (the schedule the in-process executor
runs); :class:`StepWatch` is the engine's :class:`~flowtact.runtime.engine.Watch` in a worker:

- ``enter``: before a node is gathered, its inbound links take what is due from their streams
  (:class:`~flowtact.runtime.links.zeromq.stream_links.InboundLink.pull`);
- ``timed``: the block's ``step`` wrapped, so the heartbeat sees the node being stepped (a step
  that never returns is named), and the worker counts its CPU time, steps and ``warmed``, checks
  the node's deadlines and knows the latency origins of what the step made: the oldest origin per
  source behind the data it stepped on (a source stamps its own, once its step has made it, so
  latency is transport, not its own work). Those origins go with its outputs to other processes
  (:class:`~flowtact.runtime.links.zeromq.stream_links.OutboundLink`) and to its local consumers.

An observer rather than a second loop, so the schedule is written once; in process there is no
watch, and the engine's hot loop pays one ``is None`` check per node-step for it.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from flowtact.chunk import Chunk
from flowtact.runtime.links import Link
from flowtact.runtime.step_plan import WiredNode

__all__ = ["NO_ORIGINS", "NodeWatch", "StepWatch", "merge_origins"]

NO_ORIGINS: dict[int, int] = {}
"""The origins of a step that stepped on no data (shared: never written)."""


def merge_origins(into: dict[int, int], more: dict[int, int]) -> None:
    """Keep, per source, the oldest origin time of ``into`` and ``more``."""
    for s, ns in more.items():
        old = into.get(s)
        if old is None or ns < old:
            into[s] = ns


class NodeWatch:
    """What a worker keeps of one node (:attr:`WiredNode.state`): its CPU time, whether it has
    stepped on data, its deadlines, its remote inputs, and the origins of what came for it."""

    __slots__ = ("deadlines", "held", "local", "name", "ns", "pending", "pulls", "src_idx", "warmed")

    def __init__(self, name: str, src_idx: int | None, deadlines: list[Any]) -> None:
        self.name = name
        self.src_idx = src_idx
        self.deadlines = deadlines
        self.ns = 0  # time spent in this node's steps
        self.warmed = False  # past its first data-carrying step
        self.pulls: tuple[Link, ...] = ()  # its inputs' links from other processes
        self.local: list[tuple[str, list[tuple[NodeWatch, bool]]]] = []
        """(its output port, the local consumers it feeds (their watch, through a delay port))."""
        self.pending: dict[int, int] = {}  # origins of what came and was not stepped on yet
        self.held: dict[int, int] = {}  # ... through a delay port: pending once the tick ends

    def feeds(self, port: str, consumer: NodeWatch, delayed: bool) -> None:
        """Its output ``port`` feeds ``consumer`` in this process."""
        for p, targets in self.local:
            if p == port:
                targets.append((consumer, delayed))
                return
        self.local.append((port, [(consumer, delayed)]))


class StepWatch:
    """The engine's watch in a worker (see the module docstring); ``k`` is the tick being run,
    ``origins`` those of what the last step made (read by the outbound links)."""

    def __init__(self, worker: Any) -> None:
        self.worker = worker
        self.k = 0
        self.origins: dict[int, int] = NO_ORIGINS
        self.delayed: list[NodeWatch] = []  # nodes fed through a delay port in this process

    def enter(self, nd: WiredNode, flush: bool) -> None:
        if flush:
            self.origins = NO_ORIGINS  # a flush's outputs carry no origins
            return
        k = self.k
        for link in nd.state.pulls:
            link.pull(k)

    def tick_done(self) -> None:
        """The tick ended: origins that came through a delay port are pending now (as their chunks)."""
        for st in self.delayed:
            if st.held:
                merge_origins(st.pending, st.held)
                st.held = {}

    def timed(self, nd: WiredNode, step: Callable[..., dict[str, Chunk]]) -> Callable[..., dict[str, Chunk]]:
        st: NodeWatch = nd.state
        w, name, source = self.worker, nd.name, nd.source
        perf, mono = time.perf_counter_ns, time.monotonic_ns

        def call(*args: Any, **kw: Any) -> dict[str, Chunk]:
            w.busy, w.busy_first = name, not st.warmed
            t0 = perf()
            out = step(*args, **kw)
            st.ns += perf() - t0
            w.busy = None
            w.steps += 1
            if not st.warmed and (source or _carries_samples(args, kw)):
                st.warmed = True
            origins = st.pending
            if origins:
                st.pending = {}
            else:
                origins = NO_ORIGINS
            if st.deadlines:
                self._deadlines(st, origins)
            if source:  # stamped once the source has made its data: its own step is not transport
                origins = {st.src_idx: mono()} if st.src_idx is not None else NO_ORIGINS
            self.origins = origins
            if origins:
                for port, targets in st.local:
                    c = out.get(port)
                    if c is not None and c.t.shape[0]:
                        for consumer, delayed in targets:
                            merge_origins(consumer.held if delayed else consumer.pending, origins)
            return out

        return call

    def _deadlines(self, st: NodeWatch, origins: dict[int, int]) -> None:
        t = time.monotonic_ns()
        warm_ns = self.worker.warm_ns
        for d in st.deadlines:
            if origins.get(d.src, 0) >= warm_ns:
                lat = t - origins[d.src]
                d.hist.add(lat)
                if lat > d.budget_ns:
                    d.violations += 1
                    d.worst_ns = max(d.worst_ns, lat)


def _carries_samples(args: tuple[Any, ...], kw: dict[str, Any]) -> bool:
    """Did a step get samples on any input (the positional one, or its keywords)?"""
    return any(isinstance(c, Chunk) and c.t.shape[0] for c in (*args, *kw.values()))
