"""A worker's recorder: the engine's :class:`~flowtact.runtime.engine.Sink` in a worker process.

Recorded chunks are kept per stream and coalesced: the worker's control loop sends them to the
supervisor's recorder every :data:`~flowtact.runtime.worker_control.RECORD_FLUSH_NS` (one message
per stream), or sooner once :data:`~flowtact.runtime.worker_control.RECORD_MAX_CHUNKS` of one
stream wait, so a fast run's memory stays bounded.
"""

from __future__ import annotations

import time
from typing import Any

from flowtact.chunk import Chunk, StreamSpec, concat
from flowtact.runtime.links.zeromq.streams import Service, send_lossless
from flowtact.runtime.links.zeromq.wire import END, send_message
from flowtact.runtime.worker_control import RECORD_FLUSH_NS, RECORD_MAX_CHUNKS

__all__ = ["RecordBuffer", "RecordSink"]


class RecordBuffer:
    """One recorded stream's chunks not sent yet."""

    __slots__ = ("chunks", "id", "spec")

    def __init__(self, sid: int, spec: StreamSpec) -> None:
        self.id = sid
        self.spec = spec
        self.chunks: list[Chunk] = []

    def keep(self, chunk: Chunk) -> None:
        """Keep a chunk for the recorder. One without samples only moves the stream's end (an event
        stream's watermark, every tick): it is folded into the last chunk kept, so the buffer grows
        with data, not with ticks, and joining it (``concat``) gives the same chunk."""
        buf = self.chunks
        if len(chunk) or not buf:
            buf.append(chunk)
        elif chunk.end is not None:
            last = buf[-1]
            end = chunk.end if last.end is None else max(last.end, chunk.end)
            buf[-1] = Chunk(last.t, last.data, end)

    def take(self) -> Chunk:
        """The chunks kept, joined; the buffer is emptied."""
        chunk = concat(self.chunks, self.spec)
        self.chunks = []
        return chunk


class RecordSink:
    """Coalesces a worker's recorded streams and sends them on its record socket (``worker.rec``,
    at the worker's tick ``worker.k``), hearing the supervisor (``service``) while the recorder's
    queue is full."""

    def __init__(self, worker: Any, streams: dict[str, RecordBuffer], service: Service) -> None:
        self.worker = worker
        self.streams = streams
        self.service = service
        self.next_flush = 0

    def write(self, stream: str, chunk: Chunk) -> None:
        if chunk.t.shape[0] or chunk.end is not None:
            buf = self.streams[stream]
            buf.keep(chunk)
            if len(buf.chunks) >= RECORD_MAX_CHUNKS:
                self.flush()

    def maybe_flush(self) -> None:
        """Send what waits once :data:`RECORD_FLUSH_NS` has passed since the last send."""
        if time.monotonic_ns() >= self.next_flush:
            self.flush()

    def flush(self) -> None:
        """Send every recorded stream's coalesced chunks to the recorder (one message each)."""
        self.next_flush = time.monotonic_ns() + RECORD_FLUSH_NS
        w = self.worker
        for buf in self.streams.values():
            if buf.chunks:
                send_lossless(w.rec, self.service, buf.id, 0, w.k, buf.take())

    def end(self, k: int) -> None:
        """Send what waits, then END: the worker's recording is complete."""
        self.flush()
        w = self.worker
        send_lossless(w.rec, self.service, -1, 0, k, Chunk.empty(), flags=END)

    def salvage(self) -> None:
        """On an abort or a failure, hand the recorder what was coalesced but not yet sent, without
        waiting: the recording keeps everything that came before (the supervisor drains it)."""
        w = self.worker
        for buf in self.streams.values():
            if buf.chunks:
                send_message(w.rec, buf.id, 0, w.k, buf.take(), nowait=True)
