"""The runtime's one hook for the view: a :class:`~flowtact.runtime.engine.Sink` that tees.

It stands where the recorder stands (the engine in-process, the supervisor's recording pump
across processes): a stream the file records goes on to the recorder, a viewed one (a copy) into
the view's bounded buffers. The first call starts the view's server: by then every local worker is
forked (a fork needs the supervisor to run one thread, :func:`flowtact.runtime.forked.can_fork`).
"""

from __future__ import annotations

from collections.abc import Callable, Collection
from typing import Any

from flowtact.chunk import Chunk
from flowtact.view.buffers import ViewBuffers

__all__ = ["TeeSink"]


class TeeSink:
    """Writes ``recorded`` streams to ``inner`` (a recorder, or None) and viewed ones to ``buffers``."""

    def __init__(
        self,
        inner: Any,
        recorded: Collection[str],
        buffers: ViewBuffers,
        on_first: Callable[[], None] | None = None,
    ) -> None:
        self.inner = inner
        self.recorded = frozenset(recorded) if inner is not None else frozenset()
        self.buffers = buffers
        self._on_first = on_first

    def _first(self) -> None:
        on_first, self._on_first = self._on_first, None
        if on_first is not None:
            on_first()

    def write(self, stream: str, chunk: Chunk) -> None:
        """Hand ``chunk`` to the recorder (a recorded stream) and the view (a viewed one)."""
        if self._on_first is not None:
            self._first()
        if stream in self.recorded:
            self.inner.write(stream, chunk)
        self.buffers.append(stream, chunk)

    def maybe_flush(self) -> None:
        """The recorder's periodic flush (and, the first time, the view's start)."""
        if self._on_first is not None:
            self._first()
        if self.inner is not None:
            self.inner.maybe_flush()
