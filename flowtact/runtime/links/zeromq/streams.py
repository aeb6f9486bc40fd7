"""A stream's two ends across processes: sockets, high-water marks, bind and connect, policies.

A ``block`` stream is lossless: a full queue makes the sender wait (hearing its supervisor
meanwhile) and carries one message per tick, so the receiver knows when it has all of a tick. A
``latest`` stream carries only data: the sender drops what the queue cannot hold, the receiver
takes the newest ``queue`` messages and counts the older ones as dropped. The high-water mark of
both sockets is the stream's queue bound (:attr:`flowtact.graphfile.deployment.Flow.queue`).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from typing import Any

import numpy as np
import zmq

from flowtact.chunk import Chunk, StreamSpec
from flowtact.graphfile.deployment import Flow
from flowtact.runtime.links.zeromq.wire import Message, recv_message, send_message
from flowtact.runtime.protocol import InboundStream, OutboundStream
from flowtact.runtime.stats import LatencyHistogram

__all__ = [
    "LATEST_DRAIN_MS",
    "MERGE_MAX_BYTES",
    "POLL_MS",
    "RECORD_HWM",
    "ZmqInbound",
    "ZmqOutbound",
    "bind_address",
    "record_socket",
    "send_lossless",
    "stream_socket",
]

POLL_MS = 100
"""Longest wait on a socket before the worker hears its supervisor (control, heartbeat)."""
LATEST_DRAIN_MS = 1
"""A ``latest`` input whose receive queue was full is drained again after waiting this long for
what ZeroMQ still moves in from the kernel: what reaches the consumer is the newest, not the oldest."""
MERGE_MAX_BYTES = 1 << 20
"""--fast: one merged step takes at most about this much data per input. Merging saves per-message
costs; past a MiB it only builds arrays that leave the cache (frames merged 1 000 at a time ran
at 0.85x the rate of frames merged 64 at a time)."""
RECORD_HWM = 1000
"""Messages the recorder's socket queues before a worker's lossless send waits."""
_EVENTS, _POLLIN = int(zmq.EVENTS), int(zmq.POLLIN)
"""As plain ints: ``getsockopt(_EVENTS) & _POLLIN`` is an int ``&``, where ``get(zmq.EVENTS) &
zmq.POLLIN`` builds enum members for the operands too. pyzmq still makes one for the option it
reads, so an events check is never free: the tick path does without it (see ``fetch``)."""
INF = math.inf

Accept = Callable[["ZmqInbound", Message, float], None]
"""What the worker does with a received message (``accept(stream, message, tick)``)."""
Service = Callable[[], None]
"""What the worker does while it waits on a socket: hear its supervisor."""


def stream_socket(ctx: zmq.Context, kind: int, endpoint: str, hwm: int, keys: Any = None) -> zmq.Socket:
    """A PUSH or PULL socket with high-water mark ``hwm``; CURVE on tcp:// when there are ``keys``."""
    s = ctx.socket(kind)
    s.setsockopt(zmq.SNDHWM if kind == zmq.PUSH else zmq.RCVHWM, hwm)
    s.setsockopt(zmq.LINGER, 0)
    if endpoint.startswith("tcp://") and keys is not None:
        from flowtact.runtime.links.zeromq.security import secure_client, secure_server

        (secure_client if kind == zmq.PUSH else secure_server)(s, keys)
    return s


def record_socket(ctx: zmq.Context, endpoint: str, keys: Any = None) -> zmq.Socket:
    """A worker's socket to the supervisor's recorder (connected; lingers to hand over its last data)."""
    s = stream_socket(ctx, zmq.PUSH, endpoint, RECORD_HWM, keys)
    s.setsockopt(zmq.LINGER, 500)
    s.connect(endpoint)
    return s


def bind_address(rundir: str, stream: InboundStream, group: str, host: str | None, listen: str) -> str:
    """Where group ``group`` (on ``host``, None: this one) binds ``stream``: an ipc:// path in the
    run folder when producer and consumer share this host, else tcp:// on a port the OS picks."""
    if stream.same_host and host is None:
        return f"ipc://{rundir}/s{stream.id}-{group}"
    return f"tcp://{host or listen}:0"


def send_lossless(sock: zmq.Socket, service: Service, *args: Any, **kw: Any) -> None:
    """Send, waiting while the consumer's queue is full, and still hear the supervisor meanwhile."""
    while not send_message(sock, *args, nowait=True, **kw):
        sock.poll(POLL_MS, zmq.POLLOUT)
        service()


class ZmqInbound:
    """A stream arriving from another process: its socket, what was received, its statistics."""

    def __init__(self, d: InboundStream) -> None:
        self.id = d.id
        self.name = d.stream
        self.spec: StreamSpec = d.spec
        self.flow: Flow = d.flow
        self.dsts = d.dsts
        self.same_host = d.same_host
        self.sock: zmq.Socket | None = None
        self.targets: list[tuple[deque[Any], bool]] = []  # input queues it feeds (queue, delayed)
        self.upto = 0  # highest tick received
        self.ended = False
        self.messages = self.samples = self.dropped = self.gaps = 0
        self.next_seq = 0
        self.hist = LatencyHistogram()
        self.sample_bytes = np.dtype(self.spec.dtype).itemsize * self.spec.size

    def bind(self, ctx: zmq.Context, endpoint: str, keys: Any = None) -> str:
        """Bind its PULL socket at ``endpoint`` (a tcp:// port 0: one the OS picks); the address bound."""
        self.sock = sock = stream_socket(ctx, zmq.PULL, endpoint, self.flow.queue, keys)
        sock.setsockopt(zmq.RCVTIMEO, POLL_MS)  # fetch's blocking recv hears control meanwhile
        if endpoint.startswith("tcp://") and endpoint.endswith(":0"):
            sock.bind_to_random_port(endpoint.rsplit(":", 1)[0])
        else:
            sock.bind(endpoint)
        return sock.last_endpoint.decode()

    def merge_cap(self) -> int:
        """Ticks of this stream one merged step may take: about MERGE_MAX_BYTES of data."""
        per_tick = self.sample_bytes * self.samples / max(self.messages, 1)
        return max(1, int(MERGE_MAX_BYTES // max(per_tick, 1.0)))

    def fetch(self, tick: int, accept: Accept, service: Service) -> None:
        """Receive what the stream holds for ticks up to ``tick`` (block) or what is there (latest).

        A block stream waits as raw pyzmq does, in a blocking ``recv`` (its socket's receive
        timeout is :data:`POLL_MS`, so ``zmq.Again`` is raised only by a stream idle that long, to
        hear the supervisor), one message per ``recv`` until the tick is here. A message already
        queued is one ``recv`` that returns at once; asking the socket whether more are queued
        (``getsockopt(EVENTS)``, as :meth:`drain` does for ``--fast`` merging: pyzmq builds an enum
        member for every option it reads) costs several times that, every tick, and in real time
        there is rarely more.
        """
        if self.ended:
            return
        if self.flow.policy == "latest":
            self.fetch_latest(accept)
            return
        sock = self.sock
        while self.upto < tick and not self.ended:
            try:
                m = recv_message(sock)  # type: ignore[arg-type]
            except zmq.Again:
                service()
                continue
            accept(self, m, m.tick)

    def fetch_latest(self, accept: Accept) -> None:
        """Take the newest ``queue`` messages of a ``latest`` stream; count the older ones as dropped.

        ZeroMQ moves messages from the kernel into the receive queue only as the queue empties, so
        a full queue holds the *oldest* backlog. While a drain fills the queue, wait
        :data:`LATEST_DRAIN_MS` and drain again: the backlog is read through to its newest end.
        """
        queue = self.flow.queue
        got: deque[Any] = deque(maxlen=queue)
        received = 0
        sock = self.sock
        while True:
            batch = 0
            while sock.getsockopt(_EVENTS) & _POLLIN:  # type: ignore[union-attr]
                got.append(recv_message(sock, zmq.NOBLOCK))  # type: ignore[arg-type]
                batch += 1
            received += batch
            if batch < queue or not sock.poll(LATEST_DRAIN_MS):  # type: ignore[union-attr]
                break
        self.dropped += received - len(got)
        for m in got:
            accept(self, m, -INF)

    def drain(self, accept: Accept) -> None:
        """Accept what a block stream holds (at most its queue bound), without waiting."""
        sock = self.sock
        budget = self.flow.queue
        while budget and not self.ended and sock.getsockopt(_EVENTS) & _POLLIN:  # type: ignore[union-attr]
            m = recv_message(sock, zmq.NOBLOCK)  # type: ignore[arg-type]
            accept(self, m, m.tick)
            budget -= 1


class ZmqOutbound:
    """A stream leaving for another process."""

    def __init__(self, d: OutboundStream) -> None:
        self.id = d.id
        self.node = d.node
        self.port = d.port
        self.group = d.group
        self.flow: Flow = d.flow
        self.sock: zmq.Socket | None = None
        self.seq = 0
        self.sent_tick = 0
        self.dropped = 0
        self.empty: Chunk | None = None  # the empty chunk that closes a tick with nothing in it

    def connect(self, ctx: zmq.Context, endpoint: str, keys: Any = None) -> None:
        """Connect its PUSH socket to the consumer's bound ``endpoint``."""
        self.sock = stream_socket(ctx, zmq.PUSH, endpoint, self.flow.queue, keys)
        self.sock.connect(endpoint)

    def send(self, k: int, chunk: Chunk, origins: dict[int, int], service: Service) -> None:
        """Send a chunk of tick ``k``; ``latest`` streams skip empty chunks and drop what the queue
        cannot hold, ``block`` streams wait for room (:func:`send_lossless`)."""
        if (
            not chunk.t.shape[0]
            and chunk.end is None
            and (self.flow.policy == "latest" or self.sent_tick == k)
        ):
            return
        if send_message(self.sock, self.id, self.seq, k, chunk, origins, nowait=True):  # type: ignore[arg-type]
            self.seq += 1
        elif self.flow.policy == "block":  # the consumer's queue is full: wait for room
            send_lossless(self.sock, service, self.id, self.seq, k, chunk, origins)  # type: ignore[arg-type]
            self.seq += 1
        else:
            self.dropped += 1
        self.sent_tick = k
