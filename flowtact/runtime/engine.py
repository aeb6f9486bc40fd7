"""The engine: the tick schedule, written once, over links.

Each tick, sources are stepped with the graph time ``now`` and every other node, in topological
order, receives what its upstream produced during the tick (or, through a delay port, during the
previous tick): its inbox holds what its links made due, joined when several chunks came. A node
other than a source steps only when something came (data or a watermark). Each demanded output is
checked against its stream, sealed read-only and put on its links; recorded streams go to the
recorder. At the end every link is ended and every node is flushed in order, so held-back samples
(a centred filter's tail) reach the sinks.

What joins two nodes is a link (:mod:`flowtact.runtime.links`): the in-process executor runs the
engine with ``local`` links; a worker process (:mod:`flowtact.runtime.worker`) runs it with local
links between its own nodes and ZeroMQ links to and from the others
(:mod:`flowtact.runtime.links.zeromq.stream_links`); another kind is one module registering one class.

An optional :class:`Watch` sees every node-step: a worker's takes what its remote links hold due
before the node is gathered, and times the step, tracks latency origins and deadlines
(:mod:`flowtact.runtime.worker_watch`). In process there is none: the hot loop pays one ``is
None`` check per node-step for it.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterable
from typing import Protocol

import numpy as np

from flowtact.block import Block
from flowtact.chunk import Chunk, StreamSpec, concat
from flowtact.errors import NodeError
from flowtact.running.compile import CompiledGraph
from flowtact.runtime.links import Link
from flowtact.runtime.sealing import sealed
from flowtact.runtime.step_plan import OutPlan, WiredNode, build_plans, takes_first, tallies

__all__ = ["Engine", "NodeError", "Sink", "Watch", "check_chunk"]


class Sink(Protocol):
    """What the engine writes recorded streams to (a :class:`flowtact.recording.hdf5.Recorder`)."""

    def write(self, stream: str, chunk: Chunk) -> None: ...

    def maybe_flush(self) -> None: ...


class Watch(Protocol):
    """What sees every node-step of an engine (a worker's :class:`~flowtact.runtime.worker_watch.StepWatch`)."""

    def enter(self, nd: WiredNode, flush: bool) -> None:
        """Node ``nd`` is next (to step, or to flush): take what its pulling links hold due."""

    def timed(self, nd: WiredNode, step: Callable[..., dict[str, Chunk]]) -> Callable[..., dict[str, Chunk]]:
        """``step`` wrapped: what the engine calls for ``nd`` (timed, its outputs' origins known)."""
        ...


class Engine:
    """The tick schedule of a plan's nodes, joined by links of one kind (``local`` by default)."""

    def __init__(
        self,
        plan: CompiledGraph | None,
        blocks: dict[str, Block],
        *,
        recorder: Sink | None = None,
        link: str = "local",
        wired: tuple[list[WiredNode], list[Link]] | None = None,
        watch: Watch | None = None,
    ) -> None:
        """The nodes of ``plan`` joined by links of kind ``link``, or nodes already ``wired`` with
        their links (a worker's: local and ZeroMQ links, :meth:`flowtact.runtime.worker_setup.WorkerSetup._plan_nodes`)."""
        self.recorder = recorder
        self.watch = watch
        if wired is None:
            if plan is None:
                raise ValueError("an engine needs a plan or nodes already wired")
            wired = build_plans(plan, blocks, link)
        self.nodes, self.links = wired
        self._holding = [ln for ln in self.links if ln.holds]  # act once the tick ends
        self._delivered: list[OutPlan] = []  # outputs counted in the summary, by first delivery

    def bind_steps(self) -> None:
        """Look up every block's ``step`` (per run, so a test may replace it); with a watch, the
        engine calls its wrapper of ``step`` (:meth:`Watch.timed`)."""
        watch = self.watch
        for nd in self.nodes:
            step = nd.block.step
            nd.solo = takes_first(step, nd.inputs)
            nd.call = step if watch is None else watch.timed(nd, step)

    def tick(self, now: float) -> None:
        """One tick at graph time ``now``: every node in order, then what links held becomes due."""
        self.step(self.nodes, now)
        for link in self._holding:
            link.tick_done()

    def interrupt(self) -> None:
        """The run was interrupted: what links hold for the next tick never arrives."""
        for link in self._holding:
            link.drop()

    def finish(self, now: float) -> None:
        """End of stream: every link ends, then each node steps on what is pending and flushes, in
        order, and its output links are told it is done (a loop leaving the process and coming
        back would otherwise wait for its own end)."""
        for link in self.links:
            link.end()
        for nd in self.nodes:
            if not nd.source:
                self.step((nd,), now)
            self.step((nd,), now, flush=True)
            for o in nd.outs:
                for link in o.links:
                    link.done()

    def tallies(self) -> tuple[dict[str, int], dict[str, int]]:
        """Samples and events per delivered stream, in the order they first delivered."""
        return tallies(self._delivered)

    def step(self, nodes: Iterable[WiredNode], now: float, flush: bool = False) -> None:  # noqa: C901 — the hot loop, inline on purpose (see the docstring)
        """Step each node in ``nodes`` on its inboxes (a non-source only when something came), or
        ``flush`` it, and put each demanded output, admitted (:meth:`_admit`), on its links and
        hand it to the recorder.

        Inputs reach ``step`` as they left their producer (read-only, see :meth:`_admit`), an inbox
        holding several chunks joined. ``step`` is called directly (the block is bound), with the
        node's own keyword dict refilled every time: every needed port is set, and Python hands the
        callee its own copy of the keywords, so reusing the dict is safe. A node with one input
        that is its ``step``'s first parameter gets it positionally (the same binding, cheaper).
        One call per tick, the delivery inline, the demanded outputs looked up rather than what the
        block returned walked: each call or dict walk costs a tenth of the 1 µs per node-step the
        executor is allowed here (``flowtact bench executor``).
        """
        recorder, delivered, watch = self.recorder, self._delivered, self.watch
        for nd in nodes:
            if watch is not None:
                watch.enter(nd, flush)
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
                    chunk = _admit(nd.name, chunk, o, now)
                for link in o.links:
                    link.put(chunk)
                if o.tally is not None:
                    if not o.seen:
                        o.seen = True
                        delivered.append(o)
                    o.count += len(chunk.t)
                    if o.record is not None and recorder is not None:
                        recorder.write(o.record, chunk)


def _admit(node: str, chunk: Chunk, o: OutPlan, now: float) -> Chunk:
    """Check a produced chunk against its stream and seal it read-only.

    The check is the common case of :func:`check_chunk` (1-D ``t``, one data row per time
    stamp, the declared sample shape and dtype); anything else goes to the full check, which
    names the bug. Sealing (:func:`~flowtact.runtime.sealing.sealed`) lets every consumer get
    the same object: none can change what another receives. A block that hands on the one
    input it was given, to a stream of the same kind, skips both (see :meth:`Engine.step`); a
    chunk admitted again (a gate handing on one of several inputs) passes the check and is
    already sealed.
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


def _take(box: list[Chunk], empty: Chunk, spec: StreamSpec) -> Chunk:
    """What an inbox holding other than one chunk gives: its empty chunk, or its chunks joined."""
    if not box:
        return empty
    c = concat(box, spec).readonly()
    box.clear()
    return c


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
