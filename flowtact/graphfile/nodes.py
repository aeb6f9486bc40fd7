"""A graph's nodes and edges as loaded (:class:`NodeDef`, :class:`Edge`): plain records that the
graph file (:mod:`flowtact.graphfile.graph`), its shard expansion (:mod:`flowtact.graphfile.shards`)
and the compiler all read, so none of them imports another for them."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from flowtact.block import Block
from flowtact.graphfile.deployment import DEFAULT_QUEUE, Flow
from flowtact.graphfile.located import Loc

__all__ = ["Edge", "NodeDef"]


@dataclass
class NodeDef:
    """One node: its block class, validated config, placement and where it was written."""

    name: str
    block: str
    cls: type[Block]
    params: dict[str, Any]
    config: Any
    loc: Loc
    process: str | list[str] | None = None
    """Its process group; a sharded node may list one per shard."""
    seed: int | None = None
    param_locs: dict[str, Loc] = field(default_factory=dict)
    shards: int | None = None
    """``shards: K`` as written (flowtact.graphfile.shards splits the node when the graph is loaded)."""

    def make(self) -> Block:
        """A fresh block instance for this node."""
        return self.cls(self.config, node=self.name)


@dataclass(frozen=True)
class Edge:
    """``src_node.src_port -> dst_node.dst_port``."""

    src: str
    src_port: str
    dst: str
    dst_port: str
    loc: Loc
    policy: str = "block"
    """Across processes: ``block`` (lossless, back-pressure) or ``latest`` (drop the oldest)."""
    queue: int = DEFAULT_QUEUE
    """Bound of the edge's queue, in messages, when it crosses processes."""

    @property
    def flow(self) -> Flow:
        """Its policy and queue bound as one value: what a stream crossing processes carries to its socket."""
        return Flow(self.policy, self.queue)

    def __str__(self) -> str:
        return f"{self.src}.{self.src_port} -> {self.dst}.{self.dst_port}"
