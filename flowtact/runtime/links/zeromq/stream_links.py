"""The engine's links across processes: a stream from another worker into a consumer's inbox, and
a demanded output to another worker.

A worker (:mod:`flowtact.runtime.worker`) runs the engine with these between processes and
``local`` links between its own nodes. Ticks are counted alike in every process, so a message
carries its tick:

- :class:`InboundLink` ("take what is due"): before its consumer is gathered at tick ``k``, it
  receives from the stream's socket until the stream has reached ``k`` (``k - 1`` through a delay
  port), hearing the supervisor while it waits (:meth:`ZmqInbound.fetch`), and moves the chunks
  due by ``k`` into the inbox; messages received ahead (``--fast`` merging drains them) wait in its
  queue. Once the run ends (``end``), it takes the stream to its END.
- :class:`OutboundLink`: ``put`` sends the chunk with the tick; a ``block`` (lossless) stream
  sends an empty watermark at the end of every tick it carried nothing, so its consumer knows it
  has the whole tick; ``done`` (after the producer's flush) sends END.

The sockets, high-water marks and policies are :mod:`flowtact.runtime.links.zeromq.streams`'.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Protocol

from flowtact.chunk import Chunk, StreamSpec
from flowtact.runtime.links import Link
from flowtact.runtime.links.zeromq.streams import Accept, Service, ZmqInbound, ZmqOutbound, send_lossless
from flowtact.runtime.links.zeromq.wire import END

__all__ = ["FOREVER", "InboundLink", "OutboundLink", "TickSource"]

INF = math.inf
FOREVER = 2**62
"""A tick no stream reaches: fetching up to it takes a stream to its END."""


class TickSource(Protocol):
    """Where a worker's links read the tick being run and the origins of what the last step made."""

    k: int
    origins: dict[int, int]


class Pending(Protocol):
    """The consumer's latency origins of what came and was not stepped on yet."""

    pending: dict[int, int]


class InboundLink(Link):
    """One input fed by a stream from another process (see the module docstring); it has no
    ``put``: its producer is in that process."""

    pulls = True

    def __init__(
        self,
        spec: StreamSpec,
        inbox: list[Chunk],
        *,
        delayed: bool = False,
        stream: ZmqInbound,
        into: Pending,
        accept: Accept,
        service: Service,
    ) -> None:
        super().__init__(spec, inbox, delayed=delayed)
        self.stream = stream
        self.into = into
        self.accept = accept
        self.service = service
        self.ending = False
        self.queue: deque[tuple[float, Chunk, dict[int, int]]] = deque()
        """(due from tick, chunk, origins) in arrival order: what the stream's ``accept`` received."""

    def pull(self, k: int) -> None:
        """Receive up to tick ``k`` (or to the END once the run ends) and move what is due into the inbox."""
        stream = self.stream
        if not stream.ended:
            upto = k - 1 if self.delayed else (FOREVER if self.ending else k)
            stream.fetch(upto, self.accept, self.service)
        q = self.queue
        if not q:
            return
        avail = INF if self.ending else k
        inbox, pending = self.inbox, self.into.pending
        while q and q[0][0] <= avail:
            _, c, origins = q.popleft()
            inbox.append(c)
            if origins and c.t.shape[0]:  # a watermark alone carries no data whose latency counts
                for s, ns in origins.items():
                    old = pending.get(s)
                    if old is None or ns < old:
                        pending[s] = ns

    def end(self) -> None:
        self.ending = True


class OutboundLink(Link):
    """A demanded output sent to another process (see the module docstring)."""

    def __init__(self, spec: StreamSpec, stream: ZmqOutbound, ticks: TickSource, service: Service) -> None:
        super().__init__(spec, [])  # its consumer's inbox is in another process
        self.stream = stream
        self.ticks = ticks
        self.service = service
        self.holds = stream.flow.policy == "block"  # closes every tick (tick_done)

    def put(self, chunk: Chunk) -> None:
        self.stream.send(self.ticks.k, chunk, self.ticks.origins, self.service)

    def tick_done(self) -> None:
        ob, k = self.stream, self.ticks.k
        if ob.sent_tick < k:  # a block stream carries every tick, empty or not
            ob.send(k, ob.empty, {}, self.service)  # type: ignore[arg-type]

    def done(self) -> None:
        ob = self.stream
        send_lossless(ob.sock, self.service, ob.id, ob.seq, self.ticks.k, ob.empty, flags=END)  # type: ignore[arg-type]
