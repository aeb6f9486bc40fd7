"""Each node's own random seed, derived from the graph's ``seed``: independent per node, stable
across edits. Here, below both the graph file (a shard's seed) and the compiler (every node's)."""

from __future__ import annotations

import zlib

import numpy as np

__all__ = ["node_seed"]


def node_seed(graph_seed: int, node: str) -> int:
    """The seed of a node's own random stream: independent per node, stable across edits."""
    ss = np.random.SeedSequence(graph_seed, spawn_key=(zlib.crc32(node.encode()),))
    return int(ss.generate_state(1, np.uint64)[0])
