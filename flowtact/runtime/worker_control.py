"""A worker's control loop: its messages to and from the supervisor, the recording pump, statistics.

Part of :class:`flowtact.runtime.worker.Worker` (which holds the state these methods share): the
control socket is read every :data:`CONTROL_NS` from the tick loop, recorded chunks are coalesced
for :data:`RECORD_FLUSH_NS`, statistics go out every :data:`HEARTBEAT_S`.
"""

from __future__ import annotations

import os
import time
from typing import TypeVar

import zmq

from flowtact.errors import WorkerStop
from flowtact.runtime.links.zeromq.streams import (
    POLL_MS,
)
from flowtact.runtime.protocol import (
    Abort,
    Exit,
    InboundStats,
    Message,
    PathStats,
    Stats,
    Stop,
    decode,
    encode,
)

__all__ = [
    "CONTROL_NS",
    "HEARTBEAT_S",
    "ORPHAN_S",
    "RECORD_FLUSH_NS",
    "RECORD_MAX_CHUNKS",
    "WorkerControl",
]

ORPHAN_S = 10.0
"""A worker started by hand (another host) that has not heard its supervisor this long exits."""
HEARTBEAT_S = 0.25
"""How often the main thread sends its statistics (rates, latencies, drops, CPU)."""
_EVENTS, _POLLIN = int(zmq.EVENTS), int(zmq.POLLIN)
"""As plain ints: ``getsockopt(_EVENTS) & _POLLIN`` is an int ``&``, where ``get(zmq.EVENTS) &
zmq.POLLIN`` builds enum members for the operands too. pyzmq still makes one for the option it
reads, so an events check is never free (the control socket is read every :data:`CONTROL_NS`)."""
CONTROL_NS = 5_000_000
"""The control socket (stop, abort, pings) is read this often (ns) from the tick loop, not every tick."""
RECORD_FLUSH_NS = 50_000_000
"""Recorded chunks are coalesced and sent to the recorder this often (ns), or sooner when many."""
RECORD_MAX_CHUNKS = 256
"""... or once this many chunks of one stream wait (a fast run's memory stays bounded)."""


M = TypeVar("M", bound=Message)


class WorkerControl:
    """The control loop, recording pump and statistics of a :class:`~flowtact.runtime.worker.Worker`."""

    def _send(self, msg: Message) -> None:
        self.ctl.send(encode(msg))

    def _recv_ctl(self, timeout_ms: int) -> Message | None:
        if not self.ctl.poll(timeout_ms):
            return None
        msg = decode(self.ctl.recv())
        self.last_ping = time.monotonic()
        return msg

    def _expect(self, kind: type[M]) -> M:
        """Wait for a control message of class ``kind`` for as long as the supervisor lives (it keeps time)."""
        while True:
            msg = self._recv_ctl(POLL_MS)
            if msg is None:
                self._check_orphan()
                continue
            if isinstance(msg, kind):
                return msg
            self._control(msg)

    def _check_orphan(self) -> None:
        if self.parent is not None:
            if os.getppid() != self.parent:
                raise WorkerStop("the supervisor is gone")
        elif time.monotonic() - self.last_ping > ORPHAN_S:
            raise WorkerStop("the supervisor is gone")

    def _service(self) -> None:
        """Handle pending control messages (pings, stop, abort) without blocking; send statistics."""
        while self.ctl.getsockopt(_EVENTS) & _POLLIN:
            self._control(decode(self.ctl.recv()))
            self.last_ping = time.monotonic()
        self._check_orphan()
        now_ns = time.monotonic_ns()
        self.next_service = now_ns + CONTROL_NS
        self.records.maybe_flush()
        now = now_ns / 1e9
        if now >= self.next_beat:
            self.next_beat = now + HEARTBEAT_S
            self._send(self._stats())

    def _salvage_records(self) -> None:
        """On an abort or a failure, hand the recorder what was coalesced but not yet sent, without
        waiting (:meth:`~flowtact.runtime.worker_records.RecordSink.salvage`)."""
        records = getattr(self, "records", None)
        if self.rec is not None and records is not None:
            records.salvage()

    def _phase(self, text: str) -> None:
        """Enter a start-up phase: the heartbeat reports it, and the supervisor counts it as progress."""
        self.phase = text
        self.marks += 1

    def _control(self, msg: Message) -> None:
        """A message that is not the one awaited: a stop names the last tick, abort and exit end now
        (pings only prove the supervisor alive)."""
        if isinstance(msg, Stop):
            self.stop_k = min(self.stop_k, msg.k)
        elif isinstance(msg, (Abort, Exit)):
            raise WorkerStop

    def _stats(self) -> Stats:
        """What :class:`~flowtact.runtime.protocol.Stats` reports now (sent at once: the
        histograms are the live ones)."""
        return Stats(
            k=self.k,
            now=self.now,
            cpu_s=time.process_time(),
            wall_ns=time.monotonic_ns(),
            lag_s=self.lag_s,
            max_lag_s=self.max_lag_s,
            merged_ticks=self.merged_ticks,
            node_ns={nd.name: nd.state.ns for nd in self.engine.nodes},
            counts={o.tally: o.count for nd in self.engine.nodes for o in nd.outs},
            inbound={
                ib.id: InboundStats(ib.messages, ib.samples, ib.dropped, ib.gaps, ib.hist)
                for ib in self.inbound.values()
            },
            sent_dropped={ob.id: ob.dropped for ob in self.outbound if ob.dropped},
            paths={
                d.name: PathStats(d.hist, d.violations, d.worst_ns)
                for ds in self.deadlines.values()
                for d in ds
            },
        )
