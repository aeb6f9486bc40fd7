"""A worker's start-up: build its nodes from the typed plan, warm up, bind and connect its streams, open blocks.

Part of :class:`flowtact.runtime.worker.Worker` (which holds the state these methods share).
"""

from __future__ import annotations

import math
import traceback

import zmq

from flowtact.block import Block, Source
from flowtact.catalog.blocks import load_block
from flowtact.chunk import StreamSpec
from flowtact.errors import NodeFailure
from flowtact.runtime.engine import Engine
from flowtact.runtime.links import Link
from flowtact.runtime.links.local import LocalLink
from flowtact.runtime.links.zeromq.stream_links import InboundLink, OutboundLink
from flowtact.runtime.links.zeromq.streams import ZmqInbound, ZmqOutbound, record_socket
from flowtact.runtime.protocol import DeadlinePlan, WorkerPlan
from flowtact.runtime.stats import LatencyHistogram
from flowtact.runtime.step_plan import wire_inputs, wire_outputs
from flowtact.runtime.warm_up import settle_heap, warm_up
from flowtact.runtime.worker_plan import frozen_empty
from flowtact.runtime.worker_records import RecordBuffer, RecordSink
from flowtact.runtime.worker_watch import NodeWatch, StepWatch

__all__ = ["Deadline", "WorkerSetup"]


class Deadline:
    """A declared deadline ending at one of this worker's nodes: its latencies and misses."""

    def __init__(self, d: DeadlinePlan) -> None:
        self.name = d.name
        self.src = d.src_idx
        self.dst = d.dst
        self.budget_ns = int(d.budget_s * 1e9)
        self.hist = LatencyHistogram()
        self.violations = 0
        self.worst_ns = 0


class WorkerSetup:
    """Start-up of a :class:`~flowtact.runtime.worker.Worker`: from its plan to opened blocks and wired streams."""

    def _build(self, plan: WorkerPlan) -> None:
        self.fast = plan.fast
        self.tick_s = plan.tick_s
        self.duration_s = plan.duration_s
        self.n_ticks = (
            math.ceil(self.duration_s / self.tick_s - 1e-9) if self.duration_s is not None else None
        )
        self.order: list[str] = []
        self.blocks: dict[str, Block] = {}
        self.src_idx: dict[str, int] = {}
        self.needed: dict[str, list[str]] = {}
        self.demanded: dict[str, frozenset[str]] = {}
        self.out_specs: dict[str, dict[str, StreamSpec]] = {}
        for nd in plan.nodes:
            self.busy = nd.name
            self._phase(f"building node '{nd.name}' ({nd.block})")
            allow = plan.allow_modules if self.allow_modules is None else self.allow_modules
            cls = load_block(nd.block, allow)
            block = cls(cls.config_cls.build(nd.params, owner=nd.name), node=nd.name)
            specs = block.bind(dict(nd.inputs), seed=nd.seed, demanded=frozenset(nd.demanded))
            name = nd.name
            self.order.append(name)
            self.blocks[name] = block
            self.needed[name] = list(nd.needed)
            self.demanded[name] = frozenset(nd.demanded)
            self.out_specs[name] = specs
            if nd.src_idx is not None:
                self.src_idx[name] = nd.src_idx
        self.busy = None
        self.max_lag_s = 0.0
        self.merged_ticks = 0  # real-time ticks taken together to catch up with the clock
        self.sources = [n for n in self.order if isinstance(self.blocks[n], Source)]
        self.inbound = {d.id: ZmqInbound(d) for d in plan.inbound}
        self.outbound = [ZmqOutbound(d) for d in plan.outbound]
        self.recorded = {(r.node, r.port): r.id for r in plan.record}
        self.deadlines = {}
        for d in plan.deadlines:
            self.deadlines.setdefault(d.dst, []).append(Deadline(d))
        self._plan_nodes(plan)
        self.block_inputs = [ib for ib in self.inbound.values() if ib.flow.policy == "block"]
        self.latest_inputs = [ib for ib in self.inbound.values() if ib.flow.policy == "latest"]
        # --fast, no sources here, a graph where merging cannot change a result (ticks_mergeable)
        self.merge = plan.merge_ticks and not self.sources and not self.latest_inputs
        self.now = 0.0
        self.next_beat = 0.0
        self.next_service = 0
        self.warm_ns = 0  # data that left its source before this is start-up, not transport
        self.ends_seen = 0  # END markers received (of any input)

    def _plan_nodes(self, plan: WorkerPlan) -> None:
        """Wire the engine this worker runs: its nodes joined by local links, and by ZeroMQ links
        to and from the other processes (:mod:`~flowtact.runtime.links.zeromq.stream_links`); its
        watch (:class:`~flowtact.runtime.worker_watch.StepWatch`) and its recorder (a
        :class:`~flowtact.runtime.worker_records.RecordSink`)."""
        self.watch = watch = StepWatch(self)
        nodes, boxes = wire_inputs(self.order, self.blocks, self.needed)
        states = {n: NodeWatch(n, self.src_idx.get(n), self.deadlines.get(n, [])) for n in self.order}
        for n, nd in nodes.items():
            nd.state = states[n]
        links: list[Link] = []
        routes: dict[tuple[str, str], list[Link]] = {}
        for e in plan.edges:
            if e.src_port not in self.demanded[e.src]:  # an output nobody demands is never delivered
                continue
            local = LocalLink(
                self.out_specs[e.src][e.src_port], boxes[(e.dst, e.dst_port)], delayed=e.delayed
            )
            routes.setdefault((e.src, e.src_port), []).append(local)
            links.append(local)
            states[e.src].feeds(e.src_port, states[e.dst], e.delayed)
            if e.delayed and states[e.dst] not in watch.delayed:
                watch.delayed.append(states[e.dst])
        for ib in self.inbound.values():
            for dst, dport, delayed in ib.dsts:
                inbound = InboundLink(
                    ib.spec,
                    boxes[(dst, dport)],
                    delayed=delayed,
                    stream=ib,
                    into=states[dst],
                    accept=self._accept,
                    service=self._service,
                )
                ib.targets.append((inbound.queue, delayed))
                states[dst].pulls += (inbound,)
                links.append(inbound)
        for ob in self.outbound:
            spec = self.out_specs[ob.node][ob.port]
            ob.empty = frozen_empty(spec)
            outbound = OutboundLink(spec, ob, watch, self._service)
            routes.setdefault((ob.node, ob.port), []).append(outbound)
            links.append(outbound)
        names = {(n, p): f"{n}.{p}" for n, p in self.recorded}
        self.records = RecordSink(
            self,
            {names[(n, p)]: RecordBuffer(sid, self.out_specs[n][p]) for (n, p), sid in self.recorded.items()},
            self._service,
        )
        wire_outputs(nodes, self.demanded, lambda n, p: self.out_specs[n][p], routes, names, count_all=True)
        self.engine = Engine(
            None,
            self.blocks,
            recorder=self.records if self.recorded else None,
            wired=(list(nodes.values()), links),
            watch=watch,
        )
        self.lossless_out = [ob for ob in self.outbound if ob.flow.policy == "block"]

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

    def _bind(self, bind: dict[int, str]) -> dict[int, str]:
        """Bind every incoming stream where the supervisor says; the addresses bound, by stream id."""
        return {ib.id: ib.bind(self.ctx, bind[ib.id], self.keys) for ib in self.inbound.values()}

    def _connect(self, connect: dict[int, dict[str, str]], record: str | None) -> None:
        self._latest_poller = zmq.Poller()
        for ib in self.latest_inputs:
            self._latest_poller.register(ib.sock, zmq.POLLIN)
        for ob in self.outbound:
            ob.connect(self.ctx, connect[ob.id][ob.group], self.keys)
        if record is not None and self.recorded:
            self.rec = record_socket(self.ctx, record, self.keys)

    def _open(self) -> None:
        self.opened: list[Block] = []
        for n in self.order:
            self.busy, self.busy_first = n, True
            self._phase(f"opening node '{n}'")
            try:
                self.blocks[n].open()
            except Exception as e:
                raise NodeFailure(n, self.blocks[n], 0.0, e) from e
            self.opened.append(self.blocks[n])
        self.busy = None

    def _close_blocks(self) -> None:
        for block in reversed(getattr(self, "opened", [])):
            try:
                block.close()
            except Exception:  # noqa: BLE001 — a block's close may raise anything; it must not hide the run's outcome
                traceback.print_exc()
