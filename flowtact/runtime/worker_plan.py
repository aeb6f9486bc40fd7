"""Per-node step plans of a worker, prepared once before the clock starts.

The worker's tick loop steps every node of its process group once per tick; everything a step
needs (the block, its input queues and empty chunks, where each output goes: local queues, remote
streams, the recorder, its sample counter) is resolved here once, so a tick does no dict lookups
keyed by node or port and builds no per-tick tables.
"""

from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np

from flowtact.block import Block, Source
from flowtact.chunk import Chunk, StreamSpec, concat
from flowtact.runtime.step_plan import takes_first

__all__ = ["NO_ORIGINS", "InPort", "OutPort", "Queued", "WorkerNode", "frozen_empty", "merge_origins", "take"]

Queued = deque[tuple[float, Chunk, dict[int, int]]]
"""A node input's queue: (available from tick, chunk, origins) in arrival order."""


def frozen_empty(spec: StreamSpec) -> Chunk:
    """A zero-sample chunk of ``spec`` whose arrays cannot be written: shared, never copied."""
    c = Chunk.empty(spec)
    c.t.flags.writeable = False
    c.data.flags.writeable = False
    return c


class InPort:
    """One needed input of a node: its queue and the empty chunk it gets when nothing came."""

    __slots__ = ("empty", "name", "queue", "spec")

    def __init__(self, name: str, spec: StreamSpec) -> None:
        self.name = name
        self.spec = spec
        self.queue: Queued = deque()
        self.empty = frozen_empty(spec)


class OutPort:
    """One demanded output of a node: where its chunks go and how many samples it carried."""

    __slots__ = (
        "dtype",
        "empty",
        "key",
        "local",
        "name",
        "outbound",
        "rec_buf",
        "record",
        "samples",
        "spec",
        "tail",
    )

    def __init__(self, node: str, name: str, spec: StreamSpec) -> None:
        self.name = name
        self.key = f"{node}.{name}"
        self.spec = spec
        self.dtype = np.dtype(spec.dtype)
        self.tail = tuple(spec.shape)  # the declared sample shape: a chunk's data.shape[1:]
        self.empty = frozen_empty(spec)
        self.local: list[tuple[Queued, bool]] = []  # consumers in this process (queue, delayed)
        self.outbound: list[Any] = []  # streams to other processes (worker._Outbound)
        self.record: int | None = None  # the recorded stream's id
        self.rec_buf: list[Chunk] = []  # recorded chunks not sent yet (coalesced)
        self.samples = 0

    def keep_record(self, chunk: Chunk) -> None:
        """Keep a chunk for the recorder. One without samples only moves the stream's end (an event
        stream's watermark, every tick): it is folded into the last chunk kept, so the buffer grows
        with data, not with ticks, and joining it (``concat``) gives the same chunk."""
        buf = self.rec_buf
        if len(chunk) or not buf:
            buf.append(chunk)
        elif chunk.end is not None:
            last = buf[-1]
            end = chunk.end if last.end is None else max(last.end, chunk.end)
            buf[-1] = Chunk(last.t, last.data, end)


class WorkerNode:
    """One node of a worker: everything its step needs (block, input queues, output routes), resolved once.

    ``call`` is the block's ``step``, called directly: the worker hands it every needed input,
    read-only (received arrays are, local outputs are sealed as they are delivered), as
    ``Block.__call__`` would. ``solo``: the node's one input is ``step``'s first parameter, so it
    is passed by position (:func:`~flowtact.runtime.step_plan.takes_first`).
    """

    __slots__ = (
        "block",
        "call",
        "deadlines",
        "inputs",
        "name",
        "ns",
        "outputs",
        "remote",
        "solo",
        "source",
        "src_idx",
        "warmed",
    )

    def __init__(self, name: str, block: Block, needed: list[str], src_idx: int | None) -> None:
        self.name = name
        self.block = block
        self.source = isinstance(block, Source)
        self.src_idx = src_idx
        self.inputs = [InPort(p, block.input_specs[p]) for p in needed]
        self.call = block.step
        self.solo = not self.source and takes_first(self.call, [(p,) for p in needed])
        self.outputs: dict[str, OutPort] = {}
        self.remote: list[tuple[Any, bool]] = []  # streams from other processes (worker._Inbound, delayed)
        self.deadlines: list[Any] = []
        self.ns = 0  # wall time spent in this node's steps
        self.warmed = False  # past its first data-carrying step


NO_ORIGINS: dict[int, int] = {}
"""The origins of a chunk without data (shared: never written)."""


def take(ip: InPort, avail: float) -> tuple[Chunk | None, dict[int, int]]:
    """What input ``ip`` holds for ticks up to ``avail``, joined (None: nothing), and the oldest
    origin per source behind its data: a watermark alone carries no data whose latency counts.

    One queued chunk, the common case, is returned as it came, with its origins (shared with its
    other consumers: read them, never write them); several are joined into a read-only chunk.
    """
    q = ip.queue
    if not q or q[0][0] > avail:
        return None, NO_ORIGINS
    _, c, origins = q.popleft()
    if not q or q[0][0] > avail:
        return c, (origins if c.t.shape[0] else NO_ORIGINS)
    parts = [c]
    merged = dict(origins) if c.t.shape[0] else {}
    while q and q[0][0] <= avail:
        _, c, o = q.popleft()
        parts.append(c)
        if c.t.shape[0]:
            merge_origins(merged, o)
    return concat(parts, ip.spec).readonly(), merged


def merge_origins(into: dict[int, int], more: dict[int, int]) -> None:
    """Keep, per source, the oldest origin time of ``into`` and ``more``."""
    for s, ns in more.items():
        old = into.get(s)
        if old is None or ns < old:
            into[s] = ns


def ticks_mergeable(plan: Any) -> bool:
    """May a ``--fast`` worker without sources step once over every tick its inputs already hold?

    Only when the result cannot depend on it: every node has at most one input edge (no fan-in,
    so no node sees two streams chunked differently), no source has inputs, no edge is delayed
    (no loops), and every fed block is known to be chunking-invariant: registered (the
    conformance suite proves it) or a ``module:Class`` block whose class says
    ``chunking_invariant = True``. One step over ticks ``k+1..K`` then gives the same output as
    ``K-k`` steps, and a ``--fast`` run stays bit-identical to ``--inproc``.
    """
    graph = plan.graph
    fed: set[str] = set()
    for e in plan.active_edges:
        node = graph.nodes[e.dst]
        cls = node.cls
        if e.dst in fed or issubclass(cls, Source) or cls.inputs[e.dst_port].delay:
            return False
        if ":" in node.block and not getattr(cls, "chunking_invariant", False):
            return False
        fed.add(e.dst)
    return True
