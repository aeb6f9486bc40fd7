"""The typed boundary between the supervisor and its workers, and its one codec.

What crosses processes on the control socket is a message: an :class:`Op` and its fields. A
worker's part of the plan is a :class:`WorkerPlan` of frozen dataclasses (the nodes it builds, its
local edges, the streams it receives and sends, what it records, its deadlines); a stream's
:class:`~flowtact.graphfile.deployment.Flow` (policy and queue bound) travels in it as one value from the
graph's edge to the socket. :func:`encode` and :func:`decode` are the only places that turn these
into msgpack bytes and back (never pickle).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import msgpack
import numpy as np

from flowtact.chunk import StreamSpec
from flowtact.graphfile.deployment import Flow

__all__ = [
    "DeadlinePlan",
    "InboundStream",
    "LocalEdge",
    "NodeBuild",
    "Op",
    "OutboundStream",
    "RecordedStream",
    "WorkerPlan",
    "decode",
    "encode",
    "spec_from_wire",
    "spec_to_wire",
]


class Op(StrEnum):
    """What a control message says. The lifecycle: hello -> plan -> ready (bound endpoints) ->
    wire (connect) -> wired -> start -> stats... -> done -> exit; ``beat`` from the heartbeat
    thread, ``ping`` from the supervisor, ``stop`` (at tick ``k``), ``abort`` and ``error`` at any time."""

    HELLO = "hello"
    PLAN = "plan"
    READY = "ready"
    WIRE = "wire"
    WIRED = "wired"
    START = "start"
    STATS = "stats"
    BEAT = "beat"
    PING = "ping"
    STOP = "stop"
    DONE = "done"
    ERROR = "error"
    ABORT = "abort"
    EXIT = "exit"


@dataclass(frozen=True)
class NodeBuild:
    """How a worker re-creates one node: its block by registry name, parameters and seed, bound
    to its input streams, with its demanded outputs and needed inputs."""

    name: str
    block: str
    params: dict[str, Any]
    seed: int
    inputs: dict[str, StreamSpec]
    demanded: tuple[str, ...]
    needed: tuple[str, ...]
    src_idx: int | None
    """Its index among the graph's sources (latency origins, deadlines), or None."""


@dataclass(frozen=True)
class LocalEdge:
    """An edge between two nodes of the same worker."""

    src: str
    src_port: str
    dst: str
    dst_port: str
    delayed: bool


@dataclass(frozen=True)
class InboundStream:
    """A stream a worker receives from another process, and the inputs it feeds."""

    id: int
    stream: str
    spec: StreamSpec
    flow: Flow
    dsts: tuple[tuple[str, str, bool], ...]
    """(node, port, through a delay port) of each input it feeds."""
    same_host: bool
    """Its producer runs on this host: an ipc:// address, latencies on one clock."""


@dataclass(frozen=True)
class OutboundStream:
    """A demanded output a worker sends to one consumer process."""

    id: int
    node: str
    port: str
    group: str
    flow: Flow


@dataclass(frozen=True)
class RecordedStream:
    node: str
    port: str
    id: int


@dataclass(frozen=True)
class DeadlinePlan:
    name: str
    src_idx: int
    dst: str
    budget_s: float


@dataclass(frozen=True)
class WorkerPlan:
    """Everything one worker (one process group) needs to run its part of the graph."""

    process: str
    graph: str
    allow_modules: tuple[str, ...]
    """The user's --allow-module, for ``module:Class`` blocks."""
    fast: bool
    merge_ticks: bool
    tick_s: float
    duration_s: float | None
    nodes: tuple[NodeBuild, ...]
    edges: tuple[LocalEdge, ...]
    inbound: tuple[InboundStream, ...]
    outbound: tuple[OutboundStream, ...]
    record: tuple[RecordedStream, ...]
    deadlines: tuple[DeadlinePlan, ...]


# -- the codec ------------------------------------------------------------------------------
def spec_to_wire(spec: StreamSpec) -> dict[str, Any]:
    """A stream spec as plain data."""
    return {
        "dtype": spec.dtype,
        "shape": list(spec.shape),
        "units": spec.units,
        "rate_hz": spec.rate_hz,
        "events": spec.events,
        "n_units": spec.n_units,
        "labels": list(spec.labels) if spec.labels is not None else None,
        "categories": list(spec.categories) if spec.categories is not None else None,
    }


def spec_from_wire(d: dict[str, Any]) -> StreamSpec:
    """Inverse of :func:`spec_to_wire`."""
    return StreamSpec(
        dtype=d["dtype"],
        shape=tuple(d["shape"]),
        units=d["units"],
        rate_hz=d["rate_hz"],
        events=d["events"],
        n_units=d["n_units"],
        labels=tuple(d["labels"]) if d["labels"] is not None else None,
        categories=tuple(d["categories"]) if d.get("categories") is not None else None,
    )


def _flow(d: list[Any]) -> Flow:
    return Flow(str(d[0]), int(d[1]))


def _plan_to_wire(p: WorkerPlan) -> dict[str, Any]:
    return {
        "process": p.process,
        "graph": p.graph,
        "allow_modules": list(p.allow_modules),
        "fast": p.fast,
        "merge_ticks": p.merge_ticks,
        "tick_s": p.tick_s,
        "duration_s": p.duration_s,
        "nodes": [
            [
                n.name,
                n.block,
                n.params,
                n.seed,
                {k: spec_to_wire(s) for k, s in n.inputs.items()},
                list(n.demanded),
                list(n.needed),
                n.src_idx,
            ]
            for n in p.nodes
        ],
        "edges": [[e.src, e.src_port, e.dst, e.dst_port, e.delayed] for e in p.edges],
        "inbound": [
            [
                s.id,
                s.stream,
                spec_to_wire(s.spec),
                [s.flow.policy, s.flow.queue],
                [list(d) for d in s.dsts],
                s.same_host,
            ]
            for s in p.inbound
        ],
        "outbound": [[s.id, s.node, s.port, s.group, [s.flow.policy, s.flow.queue]] for s in p.outbound],
        "record": [[r.node, r.port, r.id] for r in p.record],
        "deadlines": [[d.name, d.src_idx, d.dst, d.budget_s] for d in p.deadlines],
    }


def _plan_from_wire(d: dict[str, Any]) -> WorkerPlan:
    return WorkerPlan(
        process=d["process"],
        graph=d["graph"],
        allow_modules=tuple(d["allow_modules"]),
        fast=d["fast"],
        merge_ticks=d["merge_ticks"],
        tick_s=d["tick_s"],
        duration_s=d["duration_s"],
        nodes=tuple(
            NodeBuild(
                name,
                block,
                params,
                seed,
                {k: spec_from_wire(s) for k, s in inputs.items()},
                tuple(demanded),
                tuple(needed),
                src_idx,
            )
            for name, block, params, seed, inputs, demanded, needed, src_idx in d["nodes"]
        ),
        edges=tuple(LocalEdge(*e) for e in d["edges"]),
        inbound=tuple(
            InboundStream(sid, stream, spec_from_wire(spec), _flow(flow), tuple(tuple(x) for x in dsts), same)  # type: ignore[misc]
            for sid, stream, spec, flow, dsts, same in d["inbound"]
        ),
        outbound=tuple(OutboundStream(sid, n, p, g, _flow(flow)) for sid, n, p, g, flow in d["outbound"]),
        record=tuple(RecordedStream(*r) for r in d["record"]),
        deadlines=tuple(DeadlinePlan(*x) for x in d["deadlines"]),
    )


def _plain(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, WorkerPlan):
        return _plan_to_wire(obj)
    raise TypeError(f"cannot send {type(obj).__name__}")


def encode(op: Op, **fields: Any) -> bytes:
    """A control message as msgpack bytes: ``op`` and its fields (a :class:`WorkerPlan` included)."""
    fields["op"] = op.value
    return msgpack.packb(fields, default=_plain)


def decode(raw: bytes) -> dict[str, Any]:
    """Inverse of :func:`encode`: the fields, ``"op"`` an :class:`Op`, a plan a :class:`WorkerPlan`.
    An unknown op raises ``ValueError`` (a peer speaking another version)."""
    msg = msgpack.unpackb(raw, strict_map_key=False)
    msg["op"] = Op(msg["op"])
    if msg["op"] is Op.PLAN:
        msg["plan"] = _plan_from_wire(msg["plan"])
    return msg
