"""Each run's seed: derived from the graph's seed and the row's key, never from order or worker.

The same row of the same graph gets the same seed whichever executor, worker count or resume
runs it, so a sweep's table is reproducible run by run.
"""

from __future__ import annotations

import hashlib

import numpy as np

__all__ = ["key_digest", "row_seed"]


def key_digest(key: str) -> str:
    """A short stable hash of a row key (16 hex digits of its SHA-256)."""
    return hashlib.sha256(key.encode()).hexdigest()[:16]


def row_seed(graph_seed: int, key: str) -> int:
    """The graph seed a row runs with: a SeedSequence over the graph seed and a hash of the key."""
    words = tuple(int.from_bytes(hashlib.sha256(key.encode()).digest()[i : i + 4], "little") for i in (0, 4))
    return int(np.random.SeedSequence(graph_seed, spawn_key=words).generate_state(1)[0])
