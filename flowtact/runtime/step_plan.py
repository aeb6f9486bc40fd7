"""Per-node step plans of the in-process executor: every lookup a tick needs, resolved once.

A tick then touches only lists and slots: each input port owns an inbox (a list its link fills),
each demanded output knows the links to its consumers (:mod:`flowtact.runtime.links`), its checked
dtype and sample shape, and whether it is recorded; no per-tick dicts keyed by (node, port), no
spec lookups.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from flowtact.block import Block, Source
from flowtact.chunk import Chunk, StreamSpec
from flowtact.running.compile import CompiledGraph
from flowtact.runtime.links import Link, link_kind

__all__ = ["OutPlan", "WiredNode", "build_plans", "takes_first", "tallies"]


@dataclass(slots=True, eq=False)
class OutPlan:
    """One demanded output: how to check what the block produced and where it goes."""

    port: str
    spec: StreamSpec
    dtype: np.dtype
    tail: tuple[int, ...]
    """The declared sample shape (``data.shape[1:]``)."""
    kind: tuple[np.dtype, tuple[int, ...]]
    """(dtype, tail), one shared object per distinct kind in the plan (inputs' streams included):
    what a chunk admitted to one stream is known to fit (compared by identity)."""
    links: tuple[Link, ...]
    """The links to its consumers' inboxes (a delay port's link holds it until the tick ends)."""
    record: str | None
    """Stream name given to the recorder, or None when not recorded."""
    tally: str | None
    """Name its samples (or events) are counted under in the run summary, or None."""
    events: bool
    count: int = 0
    seen: bool = False


@dataclass(slots=True, eq=False)
class WiredNode:
    """One active node wired for the engine: its block, its inboxes and its demanded outputs' links."""

    name: str
    block: Block
    source: bool
    inputs: tuple[tuple[str | None, list[Chunk], Chunk, StreamSpec], ...]
    """(port passed to ``step`` or None when only drained, inbox, its empty chunk, its spec)."""
    outs: tuple[OutPlan, ...] = ()
    """Its demanded outputs, by port name."""
    kw: dict[str, Chunk] = field(default_factory=dict)
    """The keywords ``step`` is called with, refilled every step."""
    call: Callable[..., dict[str, Chunk]] | None = None
    """The block's ``step``, looked up when a run starts."""
    solo: bool = False
    """``call`` takes the node's one input as its first parameter (see :func:`takes_first`)."""
    in_kind: tuple[np.dtype, tuple[int, ...]] | None = None
    """The :attr:`OutPlan.kind` of its first input's stream: a chunk it hands on from there
    unchanged to an output of this kind is already checked and sealed."""


def build_plans(
    plan: CompiledGraph, blocks: dict[str, Block], link: str = "local"
) -> tuple[list[WiredNode], list[Link]]:
    """Node plans in execution order, every edge a link of kind ``link``, and every link made."""
    nodes: dict[str, WiredNode] = {}
    boxes: dict[tuple[str, str], list[Chunk]] = {}
    kinds: dict[tuple[np.dtype, tuple[int, ...]], tuple[np.dtype, tuple[int, ...]]] = {}

    def kind_of(spec: StreamSpec) -> tuple[np.dtype, tuple[int, ...]]:
        kind = (np.dtype(spec.dtype), tuple(spec.shape))
        return kinds.setdefault(kind, kind)

    for n in plan.order:
        block = blocks[n]
        drained, passed = plan.needed[n], block.needed
        inputs = []
        for p in sorted(drained | passed):
            box: list[Chunk] = []
            boxes[(n, p)] = box
            spec = block.input_specs[p]
            inputs.append((p if p in passed else None, box, Chunk.empty(spec).readonly(), spec))
        in_kind = kind_of(inputs[0][3]) if inputs else None
        nodes[n] = WiredNode(n, block, isinstance(block, Source), tuple(inputs), in_kind=in_kind)
    make = link_kind(link)
    links: list[Link] = []
    routes: dict[tuple[str, str], list[Link]] = {}
    for e in plan.active_edges:
        inbox = boxes.get((e.dst, e.dst_port))
        if inbox is None:  # the consumer neither steps on nor drains this input
            continue
        delayed = plan.graph.nodes[e.dst].cls.inputs[e.dst_port].delay
        made = make(plan.specs[(e.src, e.src_port)], inbox, delayed=delayed)
        routes.setdefault((e.src, e.src_port), []).append(made)
        links.append(made)
    recorded = {(n, p): f"{n}.{p}" for n, p in plan.record if n in blocks}
    for n, nd in nodes.items():
        outs = []
        for p in sorted(plan.demanded[n]):
            spec = plan.specs[(n, p)]
            dst = routes.get((n, p), [])
            name = recorded.get((n, p))
            kind = kind_of(spec)
            outs.append(
                OutPlan(
                    port=p,
                    spec=spec,
                    dtype=kind[0],
                    tail=kind[1],
                    kind=kind,
                    links=tuple(dst),
                    record=name,
                    tally=name if name is not None else (f"{n}.{p}" if spec.events else None),
                    events=spec.events,
                )
            )
        nd.outs = tuple(outs)
    return list(nodes.values()), links


def tallies(delivered: list[OutPlan]) -> tuple[dict[str, int], dict[str, int]]:
    """Samples and events counted per stream, in the order the streams first delivered."""
    samples: dict[str, int] = {}
    events: dict[str, int] = {}
    for o in delivered:
        (events if o.events else samples)[o.tally] = o.count  # type: ignore[index]
    return samples, events


def takes_first(step: Callable[..., Any], inputs: tuple[tuple[str | None, Any, Any, Any], ...]) -> bool:
    """Whether ``step(chunk)`` binds exactly as ``step(port=chunk)`` does for a node whose only
    input is ``port``: true when ``port`` is ``step``'s first parameter and may be given by
    position (the other parameters then take their defaults either way)."""
    if len(inputs) != 1 or inputs[0][0] is None:
        return False
    try:
        first = next(iter(inspect.signature(step).parameters.values()), None)
    except (TypeError, ValueError):  # no signature to read: keep the keyword call
        return False
    return first is not None and first.name == inputs[0][0] and first.kind is first.POSITIONAL_OR_KEYWORD
