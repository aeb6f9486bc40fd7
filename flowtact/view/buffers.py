"""The view's bounded buffers: what the graph side appends to, and the server thread takes from.

The graph side (the engine in-process, the supervisor's recording pump across processes) only
appends a copy of each chunk under a short lock and never waits for a browser: a stream holds at
most ``max_samples`` samples (events) between two frames, dropping the oldest beyond that, and an
image stream only its latest frame. The server thread swaps the pending chunks out once a frame.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from flowtact.chunk import Chunk, StreamSpec
from flowtact.view.kinds import Kind, view_kind

__all__ = ["MAX_PENDING", "Pending", "StreamBuffer", "ViewBuffers"]

MAX_PENDING = 20_000
"""Samples (or events) a stream holds between two frames; the oldest beyond are dropped (stale)."""


@dataclass(frozen=True)
class Pending:
    """What a stream gathered since the last frame: times, data, and how much was dropped."""

    t: np.ndarray
    data: np.ndarray
    end: float | None
    dropped: int


class StreamBuffer:
    """One viewed stream's bounded buffer (drop-oldest)."""

    def __init__(self, spec: StreamSpec, max_samples: int = MAX_PENDING) -> None:
        self.spec = spec
        self.kind: Kind = view_kind(spec)
        self.max_samples = 1 if self.kind == "image" else max_samples
        self._lock = threading.Lock()
        self._chunks: deque[tuple[np.ndarray, np.ndarray]] = deque()
        self._n = 0
        self._dropped = 0
        self._end: float | None = None
        self.appended = 0
        """Samples (events) appended since the run began (dropped ones too)."""

    def append(self, chunk: Chunk) -> None:
        """Keep a copy of ``chunk`` (its latest sample only, for an image stream)."""
        n = len(chunk)
        end = chunk.end if chunk.end is not None else (float(chunk.t[-1]) if n else None)
        if n > self.max_samples:  # only the newest fit: copy no more than those
            t, data = chunk.t[-self.max_samples :], chunk.data[-self.max_samples :]
        else:
            t, data = chunk.t, chunk.data
        t, data = np.array(t, np.float64), np.array(data)
        with self._lock:
            self.appended += n
            self._dropped += n - len(t)
            if end is not None:
                self._end = end if self._end is None else max(self._end, end)
            if not len(t):
                return
            self._chunks.append((t, data))
            self._n += len(t)
            while self._n > self.max_samples:
                old_t, old_d = self._chunks[0]
                extra = self._n - self.max_samples
                if len(old_t) <= extra:
                    self._chunks.popleft()
                    self._n -= len(old_t)
                    self._dropped += len(old_t)
                else:
                    self._chunks[0] = (old_t[extra:], old_d[extra:])
                    self._n -= extra
                    self._dropped += extra

    def take(self) -> Pending | None:
        """Everything gathered since the last take (None when nothing came, not even time)."""
        with self._lock:
            chunks, self._chunks = self._chunks, deque()
            dropped, end = self._dropped, self._end
            self._n = self._dropped = 0
            self._end = None
        if not chunks and end is None:
            return None
        if not chunks:
            shape = self.spec.shape
            return Pending(np.empty(0), np.empty((0, *shape), self.spec.dtype), end, dropped)
        if len(chunks) == 1:
            t, data = chunks[0]
        else:
            t = np.concatenate([c[0] for c in chunks])
            data = np.concatenate([c[1] for c in chunks])
        return Pending(t, data, end, dropped)


class ViewBuffers:
    """The buffers of every viewed stream, by name (``node.port``)."""

    def __init__(self, specs: Mapping[str, StreamSpec], max_samples: int = MAX_PENDING) -> None:
        self.streams = {name: StreamBuffer(spec, max_samples) for name, spec in specs.items()}

    def append(self, name: str, chunk: Chunk) -> None:
        """Append a chunk of stream ``name`` (a stream not viewed is ignored)."""
        buf = self.streams.get(name)
        if buf is not None:
            buf.append(chunk)

    def take(self) -> dict[str, Pending]:
        """Each stream's pending data (streams with nothing new left out)."""
        out = {}
        for name, buf in self.streams.items():
            p = buf.take()
            if p is not None:
                out[name] = p
        return out
