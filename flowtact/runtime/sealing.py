"""Outputs made read-only once, as they leave their block, so all consumers can share them.

The old way built two read-only views per input per step (for every consumer, every tick). Now a
produced chunk is sealed once: arrays only the delivery still refers to are flagged read-only in
place (no copy, no new object); an array the block also keeps (a buffer it may write into on the
next step) is left writable for it and the consumers get a read-only view of it instead.
"""

from __future__ import annotations

from sys import getrefcount

import numpy as np

from flowtact.chunk import Chunk

__all__ = ["sealed"]

_CHUNK_REFS = 5
"""References to a produced chunk nobody but the delivery holds, as counted inside :func:`sealed`
called from ``InprocExecutor._admit``: the block's output dict, the delivery loop's variable,
``_admit``'s parameter, this function's parameter and getrefcount's own argument."""
_ARRAY_REFS = 4
"""The same for one of its arrays: the chunk's field, ``_admit``'s local, the parameter and the
argument. More references than these mean the block (or something else) keeps the object.
tests/runtime/test_inproc_sealing.py pins both: fewer would seal a kept buffer, more only costs a view."""


def sealed(chunk: Chunk, t: np.ndarray, d: np.ndarray) -> Chunk:
    """``chunk`` with read-only arrays, for the executor's ``_admit`` (which holds ``t = chunk.t``,
    ``d = chunk.data``, called from a loop over the node's demanded outputs).

    Arrays nobody else refers to are flagged in place and the chunk itself is returned; otherwise
    a chunk of read-only views (:meth:`Chunk.readonly`; the chunk itself when its arrays already
    are), so a block that keeps and rewrites its output buffer goes on working and its consumers
    still cannot write.
    """
    if getrefcount(chunk) > _CHUNK_REFS or getrefcount(t) > _ARRAY_REFS or getrefcount(d) > _ARRAY_REFS:
        return chunk.readonly()
    # flagged without asking first: reading ``flags.writeable`` costs half as much as setting it
    # (setflags itself costs half the ``flags.writeable = False`` assignment)
    t.setflags(write=False)
    d.setflags(write=False)
    return chunk
