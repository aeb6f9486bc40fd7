"""Per-node step plans of the in-process executor: every lookup a tick needs, resolved once.

A tick then touches only lists and slots: each input port owns an inbox (a list its link fills),
each demanded output knows the links to its consumers (:mod:`flowtact.runtime.links`), its checked
dtype and sample shape, and whether it is recorded; no per-tick dicts keyed by (node, port), no
spec lookups.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from flowtact.block import Block, Source
from flowtact.chunk import Chunk, StreamSpec
from flowtact.running.compile import CompiledGraph
from flowtact.runtime.links import Link, link_kind

__all__ = ["OutPlan", "WiredNode", "build_plans", "takes_first", "tallies", "wire_inputs", "wire_outputs"]


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
    state: Any = None
    """What an engine's watcher keeps per node (a worker's timings, origins and remote links,
    :mod:`flowtact.runtime.worker_watch`); None in process."""


def wire_inputs(
    order: list[str], blocks: dict[str, Block], drained: Mapping[str, Iterable[str]]
) -> tuple[dict[str, WiredNode], dict[tuple[str, str], list[Chunk]]]:
    """Each node of ``order`` wired with an inbox per input it steps on (its block's ``needed``) or
    only drains (``drained[node]``: the inputs fed by an edge); the inboxes by (node, port)."""
    nodes: dict[str, WiredNode] = {}
    boxes: dict[tuple[str, str], list[Chunk]] = {}
    for n in order:
        block = blocks[n]
        passed = block.needed
        inputs = []
        for p in sorted(set(drained[n]) | passed):
            box: list[Chunk] = []
            boxes[(n, p)] = box
            spec = block.input_specs[p]
            inputs.append((p if p in passed else None, box, Chunk.empty(spec).readonly(), spec))
        nodes[n] = WiredNode(n, block, isinstance(block, Source), tuple(inputs))
    return nodes, boxes


def wire_outputs(
    nodes: dict[str, WiredNode],
    demanded: Mapping[str, Iterable[str]],
    spec_of: Callable[[str, str], StreamSpec],
    routes: Mapping[tuple[str, str], list[Link]],
    recorded: Mapping[tuple[str, str], str],
    *,
    count_all: bool = False,
) -> None:
    """Give each node its demanded outputs (and its first input's kind, :attr:`WiredNode.in_kind`): the links ``routes`` holds for them, the name it is
    recorded under (``recorded``), and the name it is counted under (a recorded or an event stream;
    every output with ``count_all``)."""
    kinds: dict[tuple[np.dtype, tuple[int, ...]], tuple[np.dtype, tuple[int, ...]]] = {}
    for nd in nodes.values():  # the inputs' kinds first: an output of the same kind is the same object
        for _, _, _, spec in nd.inputs[:1]:
            nd.in_kind = _kind_of(spec, kinds)
    for n, nd in nodes.items():
        outs = []
        for p in sorted(demanded[n]):
            spec = spec_of(n, p)
            name = recorded.get((n, p))
            kind = _kind_of(spec, kinds)
            counted = count_all or name is not None or spec.events
            outs.append(
                OutPlan(
                    port=p,
                    spec=spec,
                    dtype=kind[0],
                    tail=kind[1],
                    kind=kind,
                    links=tuple(routes.get((n, p), ())),
                    record=name,
                    tally=f"{n}.{p}" if counted else None,
                    events=spec.events,
                )
            )
        nd.outs = tuple(outs)


def _kind_of(
    spec: StreamSpec, kinds: dict[tuple[np.dtype, tuple[int, ...]], tuple[np.dtype, tuple[int, ...]]]
) -> tuple[np.dtype, tuple[int, ...]]:
    kind = (np.dtype(spec.dtype), tuple(spec.shape))
    return kinds.setdefault(kind, kind)


def build_plans(
    plan: CompiledGraph, blocks: dict[str, Block], link: str = "local"
) -> tuple[list[WiredNode], list[Link]]:
    """Node plans in execution order, every edge a link of kind ``link``, and every link made."""
    nodes, boxes = wire_inputs(list(plan.order), blocks, plan.needed)
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
    wire_outputs(nodes, plan.demanded, lambda n, p: plan.specs[(n, p)], routes, recorded)
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
