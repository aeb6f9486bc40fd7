"""A worker process: runs one process group's nodes, joined to the others by ZeroMQ streams.

The worker follows the same tick schedule as the in-process executor, so a ``--fast`` run gives
the same chunks, hence the same results, in both modes. Tick ``k`` covers graph time up to
``k * tick_s``; every chunk a node emits at tick ``k`` becomes available to its consumers at tick
``k`` (or ``k + 1`` through a delay port). A ``block`` stream carries one message per tick (an
empty one when nothing came out), so a consumer knows when it has all of tick ``k``; a ``latest``
stream carries only data and the consumer takes whatever is newest. ``END`` messages carry each
node's end-of-stream output (its flush). Nodes wait for remote input just before they step, so
chains that leave a process and come back within a tick do not deadlock.

The hot path: every node's step plan (input queues, output routes, the block's ``step`` itself)
is resolved once (:mod:`flowtact.runtime.worker_plan`); ``step`` is called directly on read-only
inputs (received messages are read-only views, local outputs are sealed as they are delivered);
a block stream is read by blocking ``recv`` calls, one message each, without catching
``zmq.Again`` on the way; control is read every :data:`CONTROL_NS`, not every tick; recorded
chunks are coalesced for :data:`RECORD_FLUSH_NS`; a source's data is stamped once its step has
made it, so latency is transport, not the source's own work. In ``--fast`` runs a worker without
sources that already holds ticks ``k+1..K`` on every input steps once at ``K`` when
:func:`~flowtact.runtime.worker_plan.ticks_mergeable` says no result can depend on it.

Lifecycle, driven by the supervisor over the control socket (msgpack dicts): hello -> plan ->
ready (bound endpoints) -> wire (connect) -> wired -> start -> stats -> done -> exit. A stop
names the tick every worker ends on (``stop`` with ``k``), so a loop through several processes
ends on the same tick everywhere and drains like the end of a timed run.

Liveness: a heartbeat thread reports the tick, the node being stepped and the steps done every
:data:`BEAT_S`, so the supervisor tells a worker stuck inside a block (or stopped) from one that
waits for its clock or its inputs. Before the start it reports its start-up phase instead
("building node 'sa1' (nlif)", "warming node 'sa1' (2/3), step 4/10", "opening node 'cam'"),
with counters that advance while it imports modules or numba runs compiler passes: each advance
restarts the supervisor's start-up window, so a long compile or warm-up is progress, not a stall. A worker the supervisor started dies with it (it checks its
parent, and on Linux ``PR_SET_PDEATHSIG``); one started by hand on another host exits after
:data:`ORPHAN_S` without a ping. So no process outlives a run.

Run as ``python -m flowtact.runtime.worker --connect ENDPOINT --process NAME`` (the supervisor
does this) or ``flowtact worker ENDPOINT --process NAME`` on another host.
"""

from __future__ import annotations

import argparse
import contextlib
import ctypes
import math
import os
import signal
import socket
import sys
import threading
import time
import traceback
from collections import deque
from typing import Any

import msgpack
import numpy as np
import zmq

from flowtact.block import Block, Source
from flowtact.catalog.blocks import load_block
from flowtact.chunk import Chunk, StreamSpec, concat
from flowtact.runtime.inproc import block_summaries, check_chunk
from flowtact.runtime.placement import spec_from_wire
from flowtact.runtime.stats import LatencyHistogram
from flowtact.runtime.warm_up import CompileWatch, settle_heap, warm_up
from flowtact.runtime.wire import END, recv_message, send_message
from flowtact.runtime.worker_plan import NO_ORIGINS, NodePlan, OutPort, merge_origins, take

__all__ = ["BEAT_S", "ORPHAN_S", "Worker", "main"]

ORPHAN_S = 10.0
"""A worker started by hand (another host) that has not heard its supervisor this long exits."""
BEAT_S = 0.1
"""How often the heartbeat thread reports progress (tick, node being stepped, steps done)."""
HEARTBEAT_S = 0.25
"""How often the main thread sends its statistics (rates, latencies, drops, CPU)."""
LATENCY_WARMUP_S = 1.0
"""Latencies count for data that left its source this long after the start: loading JIT-compiled
kernels and first allocations are start-up, not transport."""
POLL_MS = 100
"""Longest wait on a socket before the worker hears its supervisor (control, heartbeat)."""
_EVENTS, _POLLIN = int(zmq.EVENTS), int(zmq.POLLIN)
"""As plain ints: ``getsockopt(_EVENTS) & _POLLIN`` is an int ``&``, where ``get(zmq.EVENTS) &
zmq.POLLIN`` builds enum members for the operands too. pyzmq still makes one for the option it
reads, so an events check is never free: the tick path does without it (see ``_fetch``)."""
LATEST_DRAIN_MS = 1
"""A ``latest`` input whose receive queue was full is drained again after waiting this long for
what ZeroMQ still moves in from the kernel: what reaches the consumer is the newest, not the oldest."""
MERGE_MAX_S = 0.1
"""A worker behind the wall clock merges at most this much graph time into one tick."""
STOP_MERGE_MAX_S = 1.0
"""... and this much once a stop is asked: a run far behind real time (an overloaded machine) then
drains its backlog to the stop tick in a tenth of the ticks, within ``stop_grace_s``."""
MERGE_MAX_BYTES = 1 << 20
"""--fast: one merged step takes at most about this much data per input. Merging saves per-message
costs; past a MiB it only builds arrays that leave the cache (frames merged 1 000 at a time ran
at 0.85x the rate of frames merged 64 at a time)."""
COALESCE_TICKS = 32
COALESCE_S = 0.0005
"""--fast: a merging worker whose inputs hold fewer than COALESCE_TICKS ticks (or a merge's worth of
bytes) waits COALESCE_S once before stepping, so that one step and one message downstream cover a
batch. On 2 cores a consumer that keeps pace with its producer wakes for every message, and those
wake-ups take the CPU the producer needs: bench/graphs/fast.yaml moved 42-53 k samples/s without
the wait and 62 k with it (raw pyzmq: 62 k), frames 460-590 MB/s against 630-720 (3 runs each)."""
CONTROL_NS = 5_000_000
"""The control socket (stop, abort, pings) is read this often (ns) from the tick loop, not every tick."""
RECORD_FLUSH_NS = 50_000_000
"""Recorded chunks are coalesced and sent to the recorder this often (ns), or sooner when many."""
RECORD_MAX_CHUNKS = 256
"""... or once this many chunks of one stream wait (a fast run's memory stays bounded)."""
INF = math.inf
FOREVER = 2**62


class _Stop(Exception):
    """The supervisor asked this worker to abort at once."""


class _Inbound:
    """A stream arriving from another process: its socket, what was received, its statistics."""

    def __init__(self, d: dict[str, Any]) -> None:
        self.id: int = d["id"]
        self.name: str = d["stream"]
        self.spec: StreamSpec = spec_from_wire(d["spec"])
        self.policy: str = d["policy"]
        self.queue: int = d["queue"]
        self.dsts: list[tuple[str, str, bool]] = [tuple(x) for x in d["dsts"]]  # type: ignore[misc]
        self.same_host: bool = d["same_host"]
        self.sock: zmq.Socket | None = None
        self.targets: list[tuple[deque[Any], bool]] = []  # input queues it feeds (queue, delayed)
        self.upto = 0  # highest tick received
        self.ended = False
        self.messages = self.samples = self.dropped = self.gaps = 0
        self.next_seq = 0
        self.hist = LatencyHistogram()
        self.sample_bytes = np.dtype(self.spec.dtype).itemsize * self.spec.size

    def merge_cap(self) -> int:
        """Ticks of this stream one merged step may take: about MERGE_MAX_BYTES of data."""
        per_tick = self.sample_bytes * self.samples / max(self.messages, 1)
        return max(1, int(MERGE_MAX_BYTES // max(per_tick, 1.0)))


class _Outbound:
    """A stream leaving for another process."""

    def __init__(self, d: dict[str, Any]) -> None:
        self.id: int = d["id"]
        self.node: str = d["node"]
        self.port: str = d["port"]
        self.group: str = d["group"]
        self.policy: str = d["policy"]
        self.queue: int = d["queue"]
        self.sock: zmq.Socket | None = None
        self.seq = 0
        self.sent_tick = 0
        self.dropped = 0
        self.empty: Chunk | None = None  # the empty chunk that closes a tick with nothing in it


class _Deadline:
    def __init__(self, d: dict[str, Any]) -> None:
        self.name: str = d["name"]
        self.src: int = d["src_idx"]
        self.dst: str = d["dst"]
        self.budget_ns = int(d["budget_s"] * 1e9)
        self.hist = LatencyHistogram()
        self.violations = 0
        self.worst_ns = 0


class Worker:
    """One process group of a running graph."""

    def __init__(
        self,
        control: str,
        process: str,
        *,
        keys_dir: str | None = None,
        child: bool = False,
        allow_modules: tuple[str, ...] | None = None,
    ) -> None:
        self.process = process
        self.allow_modules = allow_modules
        """Modules whose ``module:Class`` blocks this worker may import: None (a child of the local
        supervisor) takes the user's list from the plan; a worker on another host has its own."""
        self.ctx = zmq.Context()
        self.keys = None
        self.ctl = self.ctx.socket(zmq.DEALER)
        self.ctl.setsockopt(zmq.LINGER, 2000)
        self.auth = None
        if control.startswith("tcp://") or keys_dir:  # a graph across hosts: CURVE on every tcp socket
            from flowtact.runtime.security import Authenticator, load_keys

            self.keys = load_keys(keys_dir)
            self.auth = Authenticator(self.ctx, self.keys).start()
        if control.startswith("tcp://"):
            from flowtact.runtime.security import HandshakeWatch, secure_client

            secure_client(self.ctl, self.keys)
            watch = HandshakeWatch(self.ctl)
            self.ctl.connect(control)
            try:
                watch.wait(10.0, endpoint=control)
            finally:
                watch.close()
        else:
            self.ctl.connect(control)
        self.last_ping = time.monotonic()
        self.parent = os.getppid() if child else None
        self.stop_k = FOREVER
        self.rec: zmq.Socket | None = None
        # progress, read by the heartbeat thread (plain attribute writes: cheap on the hot path)
        self.k = 0
        self.steps = 0
        self.busy: str | None = None  # the node being built, opened or stepped
        self.busy_first = True  # ... for the first time: kernels may be compiling
        self.lag_s = 0.0
        self.compiles = CompileWatch()  # numba compilations: announced while warming, a stall after
        self.phase = "starting"  # what the start-up is doing now (reported by the heartbeat)
        self.marks = 0  # start-up phases entered so far: each one is progress
        self.heart = _Heartbeat(self, control)

    # -- control ----------------------------------------------------------------------------
    def _send(self, op: str, **kw: Any) -> None:
        kw["op"] = op
        self.ctl.send(msgpack.packb(kw, default=_plain))

    def _recv_ctl(self, timeout_ms: int) -> dict[str, Any] | None:
        if not self.ctl.poll(timeout_ms):
            return None
        msg = msgpack.unpackb(self.ctl.recv(), strict_map_key=False)
        self.last_ping = time.monotonic()
        return msg

    def _expect(self, op: str) -> dict[str, Any]:
        """Wait for control message ``op`` for as long as the supervisor lives (it keeps time)."""
        while True:
            msg = self._recv_ctl(POLL_MS)
            if msg is None:
                self._check_orphan()
                continue
            if msg["op"] == op:
                return msg
            if msg["op"] in ("abort", "exit"):
                raise _Stop
            if msg["op"] == "stop":
                self.stop_k = min(self.stop_k, int(msg["k"]))

    def _check_orphan(self) -> None:
        if self.parent is not None:
            if os.getppid() != self.parent:
                raise _Stop("the supervisor is gone")
        elif time.monotonic() - self.last_ping > ORPHAN_S:
            raise _Stop("the supervisor is gone")

    def _service(self) -> None:
        """Handle pending control messages (pings, stop, abort) without blocking; send statistics."""
        while self.ctl.getsockopt(_EVENTS) & _POLLIN:
            self._control(msgpack.unpackb(self.ctl.recv(), strict_map_key=False))
            self.last_ping = time.monotonic()
        self._check_orphan()
        now_ns = time.monotonic_ns()
        self.next_service = now_ns + CONTROL_NS
        if now_ns >= self.next_record:
            self._flush_records()
        now = now_ns / 1e9
        if now >= self.next_beat:
            self.next_beat = now + HEARTBEAT_S
            self._send("stats", **self._stats())

    def _flush_records(self) -> None:
        """Send every recorded stream's coalesced chunks to the recorder (one message each)."""
        self.next_record = time.monotonic_ns() + RECORD_FLUSH_NS
        for o in self.recorded_ports:
            if o.rec_buf:
                chunk = concat(o.rec_buf, o.spec)
                o.rec_buf = []
                self._send_lossless(self.rec, o.record, 0, self.k, chunk)  # type: ignore[arg-type]

    def _salvage_records(self) -> None:
        """On an abort or a failure, hand the recorder what was coalesced but not yet sent, without
        waiting: the recording keeps everything that came before (the supervisor drains it)."""
        if self.rec is None:
            return
        for o in getattr(self, "recorded_ports", ()):
            if o.rec_buf:
                chunk = concat(o.rec_buf, o.spec)
                o.rec_buf = []
                send_message(self.rec, o.record, 0, self.k, chunk, nowait=True)  # type: ignore[arg-type]

    # -- set-up -----------------------------------------------------------------------------
    def _phase(self, text: str) -> None:
        """Enter a start-up phase: the heartbeat reports it, and the supervisor counts it as progress."""
        self.phase = text
        self.marks += 1

    def serve(self) -> int:
        """Run the whole lifecycle; returns the process exit status."""
        self._send("hello", process=self.process, pid=os.getpid(), host=socket.gethostname())
        self.heart.start()
        try:
            self._phase("waiting for the plan")
            msg = self._expect("plan")
            self._build(msg["plan"])
            self._warm_up()
            self._phase("binding its inputs")
            self._bind(msg["bind"])
            self._send(
                "ready",
                endpoints={i.id: i.sock.last_endpoint.decode() for i in self.inbound.values()},
                compiled=self.warm_report.total_compiled,
                compile_s=self.compiles.seconds,
            )
            self._phase("waiting for the other processes")
            wire = self._expect("wire")
            self._phase("connecting its outputs")
            self._connect(wire["connect"], wire["record"])
            try:
                self._open()  # devices, cameras, weights: before the clock starts, not on its time
                self._send("wired")
                self._phase("waiting for the start")
                start = self._expect("start")
                self.t0_ns = start["t0_ns"] or time.monotonic_ns()
                self.warm_ns = self.t0_ns + int(_latency_from_s() * 1e9)
                self.k = int(start.get("k0", 0))
                self._run(resume=bool(start.get("resume")))
                self._finish()  # steps and flushes the blocks once more: before they are closed
            finally:
                self._close_blocks()
            self._expect("exit")
            return 0
        except _Stop:
            self._salvage_records()
            return 0
        except _NodeFailure as f:
            self._salvage_records()
            self._send("error", **f.report)
            return 1
        except Exception as e:  # noqa: BLE001 — any framework failure is reported to the supervisor, not lost
            self._salvage_records()
            self._send(
                "error",
                node=None,
                block=None,
                now=None,
                message=f"{type(e).__name__}: {e}",
                traceback=traceback.format_exc(),
            )
            return 1
        finally:
            self.heart.halt()
            if self.auth is not None:
                self.auth.stop()
            self.ctx.destroy()  # each socket's own linger: the control socket's last words get out

    def _build(self, plan: dict[str, Any]) -> None:
        self.fast: bool = plan["fast"]
        self.tick_s: float = plan["tick_s"]
        self.duration_s: float | None = plan["duration_s"]
        self.n_ticks = (
            math.ceil(self.duration_s / self.tick_s - 1e-9) if self.duration_s is not None else None
        )
        self.order: list[str] = []
        self.blocks: dict[str, Block] = {}
        self.src_idx: dict[str, int] = {}
        self.needed: dict[str, list[str]] = {}
        self.demanded: dict[str, frozenset[str]] = {}
        self.out_specs: dict[str, dict[str, StreamSpec]] = {}
        for nd in plan["nodes"]:
            self.busy = nd["name"]
            self._phase(f"building node '{nd['name']}' ({nd['block']})")
            allow = plan["allow_modules"] if self.allow_modules is None else self.allow_modules
            cls = load_block(nd["block"], allow)
            block = cls(cls.config_cls.build(nd["params"], owner=nd["name"]), node=nd["name"])
            specs = block.bind(
                {p: spec_from_wire(s) for p, s in nd["inputs"].items()},
                seed=nd["seed"],
                demanded=frozenset(nd["demanded"]),
            )
            name = nd["name"]
            self.order.append(name)
            self.blocks[name] = block
            self.needed[name] = nd["needed"]
            self.demanded[name] = frozenset(nd["demanded"])
            self.out_specs[name] = specs
            if nd["src_idx"] is not None:
                self.src_idx[name] = nd["src_idx"]
        self.busy = None
        self.max_lag_s = 0.0
        self.merged_ticks = 0  # real-time ticks taken together to catch up with the clock
        self.sources = [n for n in self.order if isinstance(self.blocks[n], Source)]
        self.inbound = {d["id"]: _Inbound(d) for d in plan["inbound"]}
        self.remote_inputs: dict[str, list[tuple[_Inbound, bool]]] = {n: [] for n in self.order}
        for ib in self.inbound.values():
            for dst, _port, delayed in ib.dsts:
                if (ib, delayed) not in self.remote_inputs[dst]:
                    self.remote_inputs[dst].append((ib, delayed))
        self.outbound = [_Outbound(d) for d in plan["outbound"]]
        self.recorded = {(n, p): sid for n, p, sid in plan["record"]}
        self.deadlines = {}
        for d in plan["deadlines"]:
            self.deadlines.setdefault(d["dst"], []).append(_Deadline(d))
        self._plan_nodes(plan)
        self.block_inputs = [ib for ib in self.inbound.values() if ib.policy == "block"]
        self.latest_inputs = [ib for ib in self.inbound.values() if ib.policy == "latest"]
        # --fast, no sources here, a graph where merging cannot change a result (ticks_mergeable)
        self.merge = bool(plan.get("merge_ticks")) and not self.sources and not self.latest_inputs
        self.now = 0.0
        self.next_beat = 0.0
        self.next_service = 0
        self.next_record = 0
        self.warm_ns = 0  # data that left its source before this is start-up, not transport
        self.ends_seen = 0  # END markers received (of any input)

    def _plan_nodes(self, plan: dict[str, Any]) -> None:
        """Resolve once what every node's step reads and where each output goes (see worker_plan)."""
        self.plans = [NodePlan(n, self.blocks[n], self.needed[n], self.src_idx.get(n)) for n in self.order]
        by_name = {nd.name: nd for nd in self.plans}
        for nd in self.plans:
            for port in sorted(self.demanded[nd.name]):
                nd.outputs[port] = OutPort(nd.name, port, self.out_specs[nd.name][port])
            nd.deadlines = self.deadlines.get(nd.name, [])
            nd.remote = self.remote_inputs[nd.name]
        queue = {(nd.name, ip.name): ip.queue for nd in self.plans for ip in nd.inputs}
        for src, sport, dst, dport, delayed in plan["edges"]:
            if sport in by_name[src].outputs:  # an output nobody demands is never delivered
                by_name[src].outputs[sport].local.append((queue[(dst, dport)], delayed))
        for ib in self.inbound.values():
            ib.targets = [(queue[(dst, dport)], delayed) for dst, dport, delayed in ib.dsts]
        for ob in self.outbound:
            ob.empty = by_name[ob.node].outputs[ob.port].empty
            by_name[ob.node].outputs[ob.port].outbound.append(ob)
        for (n, p), sid in self.recorded.items():
            by_name[n].outputs[p].record = sid
        self.recorded_ports = [o for nd in self.plans for o in nd.outputs.values() if o.record is not None]
        self.lossless_out = [ob for ob in self.outbound if ob.policy == "block"]

    def _warm_up(self) -> None:
        """Load or compile every kernel the run will call, before the worker says ready (warm_up.py)."""

        order = {n: i for i, n in enumerate(self.blocks, 1)}

        def naming(n: str) -> None:
            self.busy, self.busy_first = n, True

        def stepping(n: str, step: int, steps: int) -> None:
            self._phase(f"warming node '{n}' ({order[n]}/{len(order)}), step {step}/{steps}")

        self.warm_report = warm_up(
            self.blocks, self.tick_s, watch=self.compiles, on_node=naming, on_step=stepping
        )
        self.busy = None
        settle_heap()

    def _socket(self, kind: int, endpoint: str, hwm: int) -> zmq.Socket:
        s = self.ctx.socket(kind)
        s.setsockopt(zmq.SNDHWM if kind == zmq.PUSH else zmq.RCVHWM, hwm)
        s.setsockopt(zmq.LINGER, 0)
        if endpoint.startswith("tcp://") and self.keys is not None:
            from flowtact.runtime.security import secure_client, secure_server

            (secure_client if kind == zmq.PUSH else secure_server)(s, self.keys)
        return s

    def _bind(self, bind: dict[int, str]) -> None:
        for ib in self.inbound.values():
            endpoint = bind[ib.id]
            ib.sock = self._socket(zmq.PULL, endpoint, ib.queue)
            ib.sock.setsockopt(zmq.RCVTIMEO, POLL_MS)  # _fetch's blocking recv hears control meanwhile
            if endpoint.startswith("tcp://") and endpoint.endswith(":0"):
                ib.sock.bind_to_random_port(endpoint.rsplit(":", 1)[0])
            else:
                ib.sock.bind(endpoint)

    def _connect(self, connect: dict[int, dict[str, str]], record: str | None) -> None:
        self._latest_poller = zmq.Poller()
        for ib in self.latest_inputs:
            self._latest_poller.register(ib.sock, zmq.POLLIN)
        for ob in self.outbound:
            ob.sock = self._socket(zmq.PUSH, connect[ob.id][ob.group], ob.queue)
            ob.sock.connect(connect[ob.id][ob.group])
        if record is not None and self.recorded:
            self.rec = self._socket(zmq.PUSH, record, 1000)
            self.rec.setsockopt(zmq.LINGER, 500)
            self.rec.connect(record)

    def _open(self) -> None:
        self.opened: list[Block] = []
        for n in self.order:
            self.busy, self.busy_first = n, True
            self._phase(f"opening node '{n}'")
            try:
                self.blocks[n].open()
            except Exception as e:
                raise _NodeFailure(n, self.blocks[n], 0.0, e) from e
            self.opened.append(self.blocks[n])
        self.busy = None

    def _close_blocks(self) -> None:
        for block in reversed(getattr(self, "opened", [])):
            try:
                block.close()
            except Exception:  # noqa: BLE001 — a block's close may raise anything; it must not hide the run's outcome
                traceback.print_exc()

    # -- the tick loop ----------------------------------------------------------------------
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
                self._send_out(ob, k - 1, ob.empty, {})

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

    def _consumed(self, ib: _Inbound) -> bool:
        """Has block stream ``ib`` ended, and have the ticks it carried all been stepped?

        A drain may read a stream's END ahead of the ticks queued before it: those still run.
        """
        return ib.ended and ib.upto <= self.k

    def _drain(self, ib: _Inbound) -> None:
        """Accept what block stream ``ib`` holds (at most its queue bound), without waiting."""
        sock = ib.sock
        budget = ib.queue
        while budget and not ib.ended and sock.getsockopt(_EVENTS) & _POLLIN:  # type: ignore[union-attr]
            m = recv_message(sock, zmq.NOBLOCK)  # type: ignore[arg-type]
            self._accept(ib, m, m.tick)
            budget -= 1

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

    def _control(self, msg: dict[str, Any]) -> None:
        if msg["op"] == "stop":
            self.stop_k = min(self.stop_k, int(msg["k"]))
        elif msg["op"] in ("abort", "exit"):
            raise _Stop

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
                self._fetch(ib, k - 1 if delayed else k)
            self._step(nd, k, now, k)
        for ob in self.lossless_out:  # a block stream carries every tick, empty or not
            if ob.sent_tick < k:
                self._send_out(ob, k, ob.empty, {})

    def _step(self, nd: NodePlan, k: int, now: float, avail: float) -> None:
        """Step node ``nd`` on what reached it up to tick ``avail`` (a source: every tick).

        ``step`` is called directly (``NodePlan.call``) with every needed input, an empty chunk
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
            raise _NodeFailure(nd.name, nd.block, now, e) from e
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
    def _gather(nd: NodePlan, avail: float) -> tuple[dict[str, Chunk], dict[int, int], bool, bool]:
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

    def _deadlines(self, nd: NodePlan, origins: dict[int, int]) -> None:
        t = time.monotonic_ns()
        for d in nd.deadlines:
            if origins.get(d.src, 0) >= self.warm_ns:
                lat = t - origins[d.src]
                d.hist.add(lat)
                if lat > d.budget_ns:
                    d.violations += 1
                    d.worst_ns = max(d.worst_ns, lat)

    def _deliver(self, nd: NodePlan, out: dict[str, Chunk], k: int, origins: dict[int, int]) -> None:
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
                self._send_out(ob, k, chunk, origins)
            if o.record is not None and (n or chunk.end is not None):
                o.keep_record(chunk)
                if len(o.rec_buf) >= RECORD_MAX_CHUNKS:
                    self._flush_records()

    def _send_lossless(self, sock: zmq.Socket, *args: Any, **kw: Any) -> None:
        """Send, waiting while the consumer's queue is full, and still hear the supervisor meanwhile."""
        while not send_message(sock, *args, nowait=True, **kw):
            sock.poll(POLL_MS, zmq.POLLOUT)
            self._service()

    def _send_out(self, ob: _Outbound, k: int, chunk: Chunk, origins: dict[int, int]) -> None:
        """Send a chunk; ``latest`` streams skip empty chunks and drop what the queue cannot hold."""
        if not chunk.t.shape[0] and chunk.end is None and (ob.policy == "latest" or ob.sent_tick == k):
            return
        if send_message(ob.sock, ob.id, ob.seq, k, chunk, origins, nowait=True):  # type: ignore[arg-type]
            ob.seq += 1
        elif ob.policy == "block":  # the consumer's queue is full: wait for room
            self._send_lossless(ob.sock, ob.id, ob.seq, k, chunk, origins)  # type: ignore[arg-type]
            ob.seq += 1
        else:
            ob.dropped += 1
        ob.sent_tick = k

    def _fetch(self, ib: _Inbound, tick: int) -> None:
        """Receive what stream ``ib`` holds for ticks up to ``tick`` (block) or what is there (latest).

        A block stream waits as raw pyzmq does, in a blocking ``recv`` (its socket's receive
        timeout is :data:`POLL_MS`, so ``zmq.Again`` is raised only by a stream idle that long, to
        hear the supervisor), one message per ``recv`` until the tick is here. A message already
        queued is one ``recv`` that returns at once; asking the socket whether more are queued
        (``getsockopt(EVENTS)``, as ``_drain`` does for ``--fast`` merging: pyzmq builds an enum
        member for every option it reads) costs several times that, every tick, and in real time
        there is rarely more.
        """
        if ib.ended:
            return
        if ib.policy == "latest":
            self._fetch_latest(ib)
            return
        sock = ib.sock
        while ib.upto < tick and not ib.ended:
            try:
                m = recv_message(sock)  # type: ignore[arg-type]
            except zmq.Again:
                self._service()
                continue
            self._accept(ib, m, m.tick)

    def _fetch_latest(self, ib: _Inbound) -> None:
        """Take the newest ``queue`` messages of a ``latest`` stream; count the older ones as dropped.

        ZeroMQ moves messages from the kernel into the receive queue only as the queue empties, so
        a full queue holds the *oldest* backlog. While a drain fills the queue, wait
        :data:`LATEST_DRAIN_MS` and drain again: the backlog is read through to its newest end.
        """
        got: deque[Any] = deque(maxlen=ib.queue)
        received = 0
        sock = ib.sock
        while True:
            batch = 0
            while sock.getsockopt(_EVENTS) & _POLLIN:  # type: ignore[union-attr]
                got.append(recv_message(sock, zmq.NOBLOCK))  # type: ignore[arg-type]
                batch += 1
            received += batch
            if batch < ib.queue or not sock.poll(LATEST_DRAIN_MS):  # type: ignore[union-attr]
                break
        ib.dropped += received - len(got)
        for m in got:
            self._accept(ib, m, -INF)

    def _accept(self, ib: _Inbound, m: Any, tick: float) -> None:
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

    # -- end of stream ----------------------------------------------------------------------
    def _finish(self) -> None:
        """Flush every node in order, feeding it what its producers flushed, then say done.

        As in the in-process executor: each node steps once more on everything that reached it,
        then flushes; consumers later in the order receive both. A remote consumer receives them
        as ordinary messages, then an ``END`` marker, sent as soon as the node has flushed: a loop
        that leaves this process and comes back would otherwise wait for its own END.
        """
        k = self.k + 1
        ends: dict[str, list[_Outbound]] = {}
        for ob in self.outbound:
            ends.setdefault(ob.node, []).append(ob)
        for nd in self.plans:
            n, block = nd.name, nd.block
            if not nd.source:
                for ib, delayed in nd.remote:
                    self._fetch(ib, self.k if delayed else FOREVER)
                self._step(nd, k, self.now, INF)
            try:
                out = block.flush()
            except Exception as e:
                raise _NodeFailure(n, block, self.now, e) from e
            self._deliver(nd, out, k, {})
            for ob in ends.get(n, ()):
                self._send_lossless(ob.sock, ob.id, ob.seq, k, ob.empty, flags=END)  # type: ignore[arg-type]
        if self.rec is not None:
            self._flush_records()
            self._send_lossless(self.rec, -1, 0, k, Chunk.empty(), flags=END)
        counters = {n: b.counters for n, b in self.blocks.items() if b.counters}
        self._send("done", **self._stats(), counters=counters, summaries=block_summaries(self.blocks))

    # -- statistics -------------------------------------------------------------------------
    def _stats(self) -> dict[str, Any]:
        return {
            "k": self.k,
            "now": self.now,
            "cpu_s": time.process_time(),
            "wall_ns": time.monotonic_ns(),
            "lag_s": self.lag_s,
            "max_lag_s": self.max_lag_s,
            "merged_ticks": self.merged_ticks,
            "node_ns": {nd.name: nd.ns for nd in self.plans},
            "counts": {o.key: o.samples for nd in self.plans for o in nd.outputs.values()},
            "inbound": {
                ib.id: {
                    "messages": ib.messages,
                    "samples": ib.samples,
                    "dropped": ib.dropped,
                    "gaps": ib.gaps,
                    "lat": ib.hist.to_wire(),
                }
                for ib in self.inbound.values()
            },
            "sent_dropped": {ob.id: ob.dropped for ob in self.outbound if ob.dropped},
            "paths": {
                d.name: {"lat": d.hist.to_wire(), "violations": d.violations, "worst_ns": d.worst_ns}
                for ds in self.deadlines.values()
                for d in ds
            },
        }


class _Heartbeat:
    """Sends the worker's progress every :data:`BEAT_S` from a thread and a socket of its own.

    The main thread only writes plain attributes (``k``, ``busy``, ``steps``, ``lag_s``); a worker
    stuck inside a block keeps beating with the same step count, a stopped one falls silent.
    """

    def __init__(self, worker: Worker, control: str) -> None:
        self.worker, self.control = worker, control
        self.stopped = threading.Event()
        self.thread = threading.Thread(target=self._run, name="flowtact-heartbeat", daemon=True)

    def start(self) -> None:
        self.thread.start()

    def halt(self) -> None:
        """Stop beating and close the socket (before the context is destroyed)."""
        self.stopped.set()
        if self.thread.is_alive():
            self.thread.join(timeout=5.0)

    def _run(self) -> None:
        w = self.worker
        sock = w.ctx.socket(zmq.DEALER)
        sock.setsockopt(zmq.LINGER, 0)
        sock.setsockopt(zmq.SNDHWM, 8)
        if self.control.startswith("tcp://"):
            from flowtact.runtime.security import secure_client

            secure_client(sock, w.keys)
        sock.connect(self.control)
        pid = os.getpid()
        try:
            while not self.stopped.wait(BEAT_S):
                beat = {
                    "op": "beat",
                    "process": w.process,
                    "pid": pid,
                    "k": w.k,
                    "steps": w.steps,
                    "node": w.busy,
                    "first": w.busy_first,
                    "lag_s": w.lag_s,
                    "compiling": w.compiles.current,
                    "compiled": w.compiles.count,
                    "phase": w.phase,
                    # start-up progress: phases entered, modules imported, compiler passes run
                    "progress": (w.marks, len(sys.modules), w.compiles.passes),
                    "sent_ns": time.monotonic_ns(),  # rates from the sender's clock, not arrivals
                }
                with contextlib.suppress(zmq.Again):
                    sock.send(msgpack.packb(beat), zmq.NOBLOCK)
        finally:
            sock.close(linger=0)


class _NodeFailure(Exception):
    def __init__(self, node: str, block: Block, now: float, cause: BaseException) -> None:
        super().__init__(str(cause))
        self.report = {
            "node": node,
            "block": block.name,
            "now": now,
            "message": f"{type(cause).__name__}: {cause}",
            "traceback": traceback.format_exc(),
        }


def _latency_from_s() -> float:
    """:data:`LATENCY_WARMUP_S`, or ``$FLOWTACT_LATENCY_FROM_S`` (the start-up bench counts from 0)."""
    with contextlib.suppress(KeyError, ValueError):
        return max(float(os.environ["FLOWTACT_LATENCY_FROM_S"]), 0.0)
    return LATENCY_WARMUP_S


def _plain(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f"cannot send {type(obj).__name__}")


def _die_with_parent() -> None:
    """Linux: this process gets SIGKILL when the process that started it dies."""
    try:
        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
        if os.getppid() == 1:  # the parent died before prctl
            os._exit(1)
    except OSError:
        pass


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``python -m flowtact.runtime.worker``."""
    p = argparse.ArgumentParser(prog="flowtact worker", description="run one process group of a graph")
    p.add_argument("connect", help="the supervisor's control endpoint (ipc://... or tcp://host:port)")
    p.add_argument("--process", required=True, help="the process group to run")
    p.add_argument("--keys", help="CURVE keys folder for tcp (default: $FLOWTACT_KEYS)")
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    from flowtact.cli import add_allow_module

    add_allow_module(p)
    args = p.parse_args(argv)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the supervisor coordinates a Ctrl-C
    if args.child and sys.platform.startswith("linux"):
        _die_with_parent()
    from flowtact.errors import SecurityError

    try:
        allow = None if args.child else tuple(args.allow_modules)  # on another host: this host's own word
        worker = Worker(args.connect, args.process, keys_dir=args.keys, child=args.child, allow_modules=allow)
    except SecurityError as e:
        print(f"flowtact worker: {e}", file=sys.stderr)
        return 1

    return worker.serve()


if __name__ == "__main__":
    sys.exit(main())
