"""A worker's tick loop: the tick schedule over its local queues and ZeroMQ streams, and the end of stream.

Part of :class:`flowtact.runtime.worker.Worker` (which holds the state these methods share); the
schedule is the one :mod:`flowtact.runtime.worker` describes.
"""

from __future__ import annotations

import math
import time
from typing import Any

import zmq

from flowtact.chunk import Chunk
from flowtact.errors import NodeFailure
from flowtact.runtime.inproc import block_summaries, check_chunk
from flowtact.runtime.links.zeromq.streams import (
    POLL_MS,
    ZmqInbound,
    ZmqOutbound,
    send_lossless,
)
from flowtact.runtime.links.zeromq.wire import END
from flowtact.runtime.protocol import Done
from flowtact.runtime.worker_control import HEARTBEAT_S, RECORD_MAX_CHUNKS
from flowtact.runtime.worker_plan import NO_ORIGINS, WorkerNode, merge_origins, take

__all__ = ["COALESCE_S", "COALESCE_TICKS", "FOREVER", "MERGE_MAX_S", "STOP_MERGE_MAX_S", "WorkerTicks"]

MERGE_MAX_S = 0.1
"""A worker behind the wall clock merges at most this much graph time into one tick."""
STOP_MERGE_MAX_S = 1.0
"""... and this much once a stop is asked: a run far behind real time (an overloaded machine) then
drains its backlog to the stop tick in a tenth of the ticks, within ``stop_grace_s``."""
COALESCE_TICKS = 32
COALESCE_S = 0.0005
"""--fast: a merging worker whose inputs hold fewer than COALESCE_TICKS ticks (or a merge's worth of
bytes) waits COALESCE_S once before stepping, so that one step and one message downstream cover a
batch. On 2 cores a consumer that keeps pace with its producer wakes for every message, and those
wake-ups take the CPU the producer needs: bench/graphs/fast.yaml moved 42-53 k samples/s without
the wait and 62 k with it (raw pyzmq: 62 k), frames 460-590 MB/s against 630-720 (3 runs each)."""
INF = math.inf
FOREVER = 2**62


class WorkerTicks:
    """The tick loop of a :class:`~flowtact.runtime.worker.Worker`."""

    def _tick_time(self, k: int) -> float:
        if self.n_ticks is not None and k >= self.n_ticks:
            return float(self.duration_s)  # type: ignore[arg-type]
        return k * self.tick_s

    def _run(self, *, resume: bool) -> None:
        sources = bool(self.sources)
        clocked = sources or bool(self.block_inputs)  # k follows the graph clock (else: arrivals)
        if resume and self.sources and not self.fast:  # skip what the clock already passed
            self.k = max(self.k, int((time.monotonic_ns() - self.t0_ns) / 1e9 / self.tick_s))
            for n in self.sources:
                self.blocks[n](self.k * self.tick_s)
        fed = 0 if sources else len(self.block_inputs)  # ends once every block input is consumed
        only_latest = not sources and not self.block_inputs  # ends once every input has ended
        self.next_beat = time.monotonic() + HEARTBEAT_S
        while True:
            if self.n_ticks is not None and self.k >= self.n_ticks:
                break
            if clocked and self.k >= self.stop_k:  # stopped: every worker ends on this tick
                break
            if fed and self.ends_seen >= fed and all(self._consumed(ib) for ib in self.block_inputs):
                break
            if only_latest and (not self.latest_inputs or not self._wait_latest()):
                break
            self.k += 1
            if self.merge and self.block_inputs:
                self._merge_ahead()
            if sources and not self.fast:
                self._catch_up()
            self.now = self._tick_time(self.k)
            if sources and not self.fast:
                self._wait_clock(self.now)
            if time.monotonic_ns() >= self.next_service:
                self._service()
            self._tick(self.k, self.now)

    def _catch_up(self) -> None:
        """Behind the wall clock by more than a tick: take every due tick in this one.

        Blocks are chunking-invariant, so one late tick covering several gives the same outputs
        as several; ticking through them one by one would never catch up with a loop whose
        round trip through the processes is as long as its tick. The skipped ticks are closed on
        every lossless stream first (an empty message), as if they had carried nothing: consumers,
        and loops back into this worker, move on to the merged tick.
        """
        behind = int((time.monotonic_ns() - self.t0_ns) / 1e9 / self.tick_s) - self.k
        if behind <= 1:
            return
        self.lag_s = behind * self.tick_s
        self.max_lag_s = max(self.max_lag_s, self.lag_s)
        merge_s = MERGE_MAX_S if self.stop_k == FOREVER else STOP_MERGE_MAX_S
        step = max(1, int(merge_s / self.tick_s))  # bounded chunks: a slow consumer stays bounded
        k = min(self.k + min(behind, step), self.stop_k, self.n_ticks or FOREVER)
        self.merged_ticks += k - self.k
        self.k = k
        for ob in self.lossless_out:
            if ob.sent_tick < k - 1:
                ob.send(k - 1, ob.empty, {}, self._service)  # type: ignore[arg-type]

    def _merge_ahead(self) -> None:
        """--fast: take every tick all block inputs already hold in this one (see ticks_mergeable).

        What is queued is read without waiting; when every input holds ticks up to ``K`` beyond
        this tick, one step covers them all: one message downstream instead of ``K - k`` — at most
        about :data:`MERGE_MAX_BYTES` of each input at a time. With little queued, the worker first
        waits :data:`COALESCE_S` for more (:data:`COALESCE_TICKS`).
        """
        for ib in self.block_inputs:
            if not ib.ended:
                self._drain(ib)
        live = [ib for ib in self.block_inputs if not self._consumed(ib)]
        if not live:
            return
        cap = min(ib.merge_cap() for ib in live)
        more = not any(ib.ended for ib in live)  # an ended stream holds all it will
        if more and min(ib.upto for ib in live) - self.k < min(cap, COALESCE_TICKS):
            time.sleep(COALESCE_S)  # little queued: let the producers get ahead (see COALESCE_TICKS)
            for ib in live:
                if not ib.ended:
                    self._drain(ib)
            live = [ib for ib in live if not self._consumed(ib)]
        upto = min((ib.upto for ib in live), default=self.k)
        if upto > self.k:
            self.k = min(
                upto, self.k - 1 + cap, self.stop_k, self.n_ticks if self.n_ticks is not None else FOREVER
            )

    def _consumed(self, ib: ZmqInbound) -> bool:
        """Has block stream ``ib`` ended, and have the ticks it carried all been stepped?

        A drain may read a stream's END ahead of the ticks queued before it: those still run.
        """
        return ib.ended and ib.upto <= self.k

    def _drain(self, ib: ZmqInbound) -> None:
        """Accept what block stream ``ib`` holds (at most its queue bound), without waiting."""
        ib.drain(self._accept)

    def _wait_clock(self, now: float) -> None:
        target = self.t0_ns + int(now * 1e9)
        while True:
            remaining = (target - time.monotonic_ns()) / 1e9
            if remaining <= 0:
                self.lag_s = -remaining  # how far this tick runs behind real time
                self.max_lag_s = max(self.max_lag_s, self.lag_s)
                return
            if remaining > 0.06:
                self.ctl.poll(50)
                self._service()
            else:
                time.sleep(remaining)

    def _wait_latest(self) -> bool:
        """A worker fed only by ``latest`` streams waits for any of them; False once all ended."""
        poller = self._latest_poller
        while not all(ib.ended for ib in self.latest_inputs):
            if poller.poll(POLL_MS):
                return True
            self._service()
        return False

    def _tick(self, k: int, now: float) -> None:
        for nd in self.plans:
            for ib, delayed in nd.remote:
                ib.fetch(k - 1 if delayed else k, self._accept, self._service)
            self._step(nd, k, now, k)
        for ob in self.lossless_out:  # a block stream carries every tick, empty or not
            if ob.sent_tick < k:
                ob.send(k, ob.empty, {}, self._service)  # type: ignore[arg-type]

    def _step(self, nd: WorkerNode, k: int, now: float, avail: float) -> None:
        """Step node ``nd`` on what reached it up to tick ``avail`` (a source: every tick).

        ``step`` is called directly (``WorkerNode.call``) with every needed input, an empty chunk
        where nothing came; a node other than a source steps only when something came (data or a
        watermark). A node whose one input is ``step``'s first parameter gets it by position.
        """
        if nd.solo:
            c, origins = take(nd.inputs[0], avail)
            if c is None:
                return
            samples = c.t.shape[0] > 0
            if not samples and c.end is None:
                return
        else:
            ins, origins, came, samples = self._gather(nd, avail)
            if not came and not nd.source:
                return
        self.busy, self.busy_first = nd.name, not nd.warmed
        t0 = time.perf_counter_ns()
        try:
            if nd.solo:
                out = nd.call(c)
            elif nd.source:
                out = nd.call(now, **ins)
            else:
                out = nd.call(**ins)
        except Exception as e:
            raise NodeFailure(nd.name, nd.block, now, e) from e
        nd.ns += time.perf_counter_ns() - t0
        self.busy = None
        self.steps += 1
        if not nd.warmed and (nd.source or samples):
            nd.warmed = True
        if nd.deadlines:
            self._deadlines(nd, origins)
        if nd.source:  # stamped once the source has made its data: its own step is not transport
            origins = {nd.src_idx: time.monotonic_ns()} if nd.src_idx is not None else NO_ORIGINS
        self._deliver(nd, out, k, origins)

    @staticmethod
    def _gather(nd: WorkerNode, avail: float) -> tuple[dict[str, Chunk], dict[int, int], bool, bool]:
        """Node ``nd``'s inputs up to tick ``avail`` (see :func:`~flowtact.runtime.worker_plan.take`),
        the oldest origin per source behind their data, whether anything came (data or a
        watermark) and whether samples came."""
        ins: dict[str, Chunk] = {}
        origins = NO_ORIGINS
        came = samples = False
        for ip in nd.inputs:
            c, o = take(ip, avail)
            if c is None:
                ins[ip.name] = ip.empty
                continue
            ins[ip.name] = c
            if c.t.shape[0]:
                came = samples = True
            elif c.end is not None:
                came = True
            if o:
                if origins:
                    origins = dict(origins)  # never write a chunk's own (shared) origins
                    merge_origins(origins, o)
                else:
                    origins = o
        return ins, origins, came, samples

    def _deadlines(self, nd: WorkerNode, origins: dict[int, int]) -> None:
        t = time.monotonic_ns()
        for d in nd.deadlines:
            if origins.get(d.src, 0) >= self.warm_ns:
                lat = t - origins[d.src]
                d.hist.add(lat)
                if lat > d.budget_ns:
                    d.violations += 1
                    d.worst_ns = max(d.worst_ns, lat)

    def _deliver(self, nd: WorkerNode, out: dict[str, Chunk], k: int, origins: dict[int, int]) -> None:
        """Hand each demanded output to its local consumers (sealed read-only), its remote streams
        and the recorder, once it has passed the common case of :func:`check_chunk` (the full
        check names a bug)."""
        outputs = nd.outputs
        for port, chunk in out.items():
            o = outputs.get(port)
            if o is None:  # not demanded
                continue
            t, d = chunk.t, chunk.data
            shape = d.shape
            if (
                t.ndim != 1
                or not shape
                or shape[0] != t.shape[0]
                or shape[1:] != o.tail
                or (d.dtype is not o.dtype and d.dtype != o.dtype)
            ):
                check_chunk(nd.name, port, chunk, o.spec, self.now)
            n = shape[0]
            if n:
                o.samples += n
            if o.local:
                if t.flags.writeable or d.flags.writeable:
                    chunk = chunk.readonly()
                for q, delayed in o.local:
                    q.append((k + 1 if delayed else k, chunk, origins))
            for ob in o.outbound:
                ob.send(k, chunk, origins, self._service)
            if o.record is not None and (n or chunk.end is not None):
                o.keep_record(chunk)
                if len(o.rec_buf) >= RECORD_MAX_CHUNKS:
                    self._flush_records()

    def _send_lossless(self, sock: zmq.Socket, *args: Any, **kw: Any) -> None:
        """Send, waiting while the consumer's queue is full, and still hear the supervisor meanwhile."""
        send_lossless(sock, self._service, *args, **kw)

    def _accept(self, ib: ZmqInbound, m: Any, tick: float) -> None:
        if m.seq != ib.next_seq and not m.flags & END:
            ib.gaps += 1
        ib.next_seq = m.seq + 1
        if m.flags & END:
            ib.ended = True
            self.ends_seen += 1
            tick = INF
        elif m.tick > ib.upto:
            ib.upto = m.tick
        n = len(m.chunk.t)
        if n:
            ib.messages += 1
            ib.samples += n
            if ib.same_host and m.origins:
                origin = min(m.origins.values())
                if origin >= self.warm_ns:
                    ib.hist.add(time.monotonic_ns() - origin)
        for q, delayed in ib.targets:
            q.append((tick + 1 if delayed and tick != INF else tick, m.chunk, m.origins))

    def _finish(self) -> None:
        """Flush every node in order, feeding it what its producers flushed, then say done.

        As in the in-process executor: each node steps once more on everything that reached it,
        then flushes; consumers later in the order receive both. A remote consumer receives them
        as ordinary messages, then an ``END`` marker, sent as soon as the node has flushed: a loop
        that leaves this process and comes back would otherwise wait for its own END.
        """
        k = self.k + 1
        ends: dict[str, list[ZmqOutbound]] = {}
        for ob in self.outbound:
            ends.setdefault(ob.node, []).append(ob)
        for nd in self.plans:
            n, block = nd.name, nd.block
            if not nd.source:
                for ib, delayed in nd.remote:
                    ib.fetch(self.k if delayed else FOREVER, self._accept, self._service)
                self._step(nd, k, self.now, INF)
            try:
                out = block.flush()
            except Exception as e:
                raise NodeFailure(n, block, self.now, e) from e
            self._deliver(nd, out, k, {})
            for ob in ends.get(n, ()):
                self._send_lossless(ob.sock, ob.id, ob.seq, k, ob.empty, flags=END)  # type: ignore[arg-type]
        if self.rec is not None:
            self._flush_records()
            self._send_lossless(self.rec, -1, 0, k, Chunk.empty(), flags=END)
        counters = {n: b.counters for n, b in self.blocks.items() if b.counters}
        self._send(Done(self._stats(), counters, block_summaries(self.blocks)))
