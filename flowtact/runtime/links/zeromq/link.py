"""The ZeroMQ link for the engine: each edge a PUSH/PULL socket pair, chunks framed by wire.py.

A chunk put on the link is sent through a real ZeroMQ socket (``inproc://`` within this process)
in the wire format and received at once into the consumer's inbox (or, through a delay port,
held until the tick ends). The engine's schedule needs nothing else: ``InprocExecutor(plan,
link="zmq")`` runs a graph over ZeroMQ framing and sockets, and its recordings are bit-identical
to the local link's (tests/runtime/test_engine_links.py). Its high-water mark is the default queue bound.
"""

from __future__ import annotations

import itertools

import zmq

from flowtact.chunk import Chunk, StreamSpec
from flowtact.graphfile.deployment import DEFAULT_QUEUE
from flowtact.runtime.links import Link, register_link
from flowtact.runtime.links.zeromq.streams import stream_socket
from flowtact.runtime.links.zeromq.wire import recv_message, send_message

__all__ = ["ZmqLink"]

_names = itertools.count()


@register_link("zmq")
class ZmqLink(Link):
    """An edge over a ZeroMQ socket pair in this process (see the module docstring)."""

    def __init__(self, spec: StreamSpec, inbox: list[Chunk], *, delayed: bool = False) -> None:
        super().__init__(spec, inbox, delayed=delayed)
        self.holds = delayed
        self.held: list[Chunk] = []
        self.ended = False
        ctx = zmq.Context.instance()
        endpoint = f"inproc://flowtact-link-{next(_names)}"
        self.pull = stream_socket(ctx, zmq.PULL, endpoint, DEFAULT_QUEUE)
        self.pull.bind(endpoint)
        self.push = stream_socket(ctx, zmq.PUSH, endpoint, DEFAULT_QUEUE)
        self.push.connect(endpoint)
        self.seq = 0

    def put(self, chunk: Chunk) -> None:
        send_message(self.push, 0, self.seq, 0, chunk)
        self.seq += 1
        got = recv_message(self.pull).chunk
        (self.held if self.holds and not self.ended else self.inbox).append(got)

    def tick_done(self) -> None:
        if self.held:
            self.inbox.extend(self.held)
            self.held.clear()

    def end(self) -> None:
        self.ended = True

    def drop(self) -> None:
        self.held.clear()

    def __del__(self) -> None:
        for sock in (getattr(self, "push", None), getattr(self, "pull", None)):
            if sock is not None:
                sock.close(linger=0)
