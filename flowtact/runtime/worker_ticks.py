"""A worker's tick loop: which tick to run next (the clock, catch-up, ``--fast`` merging, a stop),
each run by the engine, and the end of stream.

Part of :class:`flowtact.runtime.worker.Worker` (which holds the state these methods share). The
schedule of a tick is :class:`~flowtact.runtime.engine.Engine`'s, the one the in-process executor
runs, over local links and ZeroMQ links (:mod:`flowtact.runtime.links.zeromq.stream_links`); this
loop chooses ``k`` and hears the supervisor, and :meth:`WorkerTicks._accept` takes a stream's
messages in (statistics, latency, END).
"""

from __future__ import annotations

import math
import time
from typing import Any

from flowtact.errors import NodeError, NodeFailure
from flowtact.runtime.inproc import block_summaries
from flowtact.runtime.links.zeromq.stream_links import FOREVER
from flowtact.runtime.links.zeromq.streams import POLL_MS, ZmqInbound
from flowtact.runtime.links.zeromq.wire import END
from flowtact.runtime.protocol import Done
from flowtact.runtime.worker_control import HEARTBEAT_S

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


class WorkerTicks:
    """The tick loop of a :class:`~flowtact.runtime.worker.Worker`."""

    def _tick_time(self, k: int) -> float:
        if self.n_ticks is not None and k >= self.n_ticks:
            return float(self.duration_s)  # type: ignore[arg-type]
        return k * self.tick_s

    def _run(self, *, resume: bool) -> None:
        self.engine.bind_steps()
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
        """Tick ``k`` at graph time ``now``: the engine's tick (what is due taken from the streams
        before each node, outputs sent with ``k``, every lossless stream closing the tick)."""
        self.watch.k = k
        try:
            self.engine.tick(now)
        except NodeError as e:
            raise NodeFailure(e.node, e.block, e.now, e.cause) from e.cause
        self.watch.tick_done()

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
        """The engine's end of stream (:meth:`~flowtact.runtime.engine.Engine.finish`), one tick
        after the last: each node steps once more on everything that reached it (its streams read
        to their END), then flushes, and its streams to other processes say END at once (a loop
        that leaves this process and comes back would otherwise wait for its own END). Then the
        recording is sent whole, and the supervisor told."""
        self.watch.k = self.k + 1
        try:
            self.engine.finish(self.now)
        except NodeError as e:
            raise NodeFailure(e.node, e.block, e.now, e.cause) from e.cause
        if self.rec is not None:
            self.records.end(self.k + 1)
        counters = {n: b.counters for n, b in self.blocks.items() if b.counters}
        self._send(Done(self._stats(), counters, block_summaries(self.blocks)))
