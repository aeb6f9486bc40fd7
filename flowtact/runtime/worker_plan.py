"""What a worker's plan settles before the clock starts, apart from its wiring (worker_setup.py).

Whether a ``--fast`` worker may step once over every tick its inputs hold (:func:`ticks_mergeable`,
decided by placement for every worker of the graph), and the shared empty chunk that closes a tick
on a lossless stream (:func:`frozen_empty`).
"""

from __future__ import annotations

from typing import Any

from flowtact.block import Source
from flowtact.chunk import Chunk, StreamSpec

__all__ = ["frozen_empty", "ticks_mergeable"]


def frozen_empty(spec: StreamSpec) -> Chunk:
    """A zero-sample chunk of ``spec`` whose arrays cannot be written: shared, never copied."""
    c = Chunk.empty(spec)
    c.t.flags.writeable = False
    c.data.flags.writeable = False
    return c


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
