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
from flowtact.runtime.links.zeromq.streams import (
    ZmqInbound,
    ZmqOutbound,
    record_socket,
)
from flowtact.runtime.protocol import DeadlinePlan, WorkerPlan
from flowtact.runtime.stats import LatencyHistogram
from flowtact.runtime.warm_up import settle_heap, warm_up
from flowtact.runtime.worker_plan import OutPort, WorkerNode

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
        self.remote_inputs: dict[str, list[tuple[ZmqInbound, bool]]] = {n: [] for n in self.order}
        for ib in self.inbound.values():
            for dst, _port, delayed in ib.dsts:
                if (ib, delayed) not in self.remote_inputs[dst]:
                    self.remote_inputs[dst].append((ib, delayed))
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
        self.next_record = 0
        self.warm_ns = 0  # data that left its source before this is start-up, not transport
        self.ends_seen = 0  # END markers received (of any input)

    def _plan_nodes(self, plan: WorkerPlan) -> None:
        """Resolve once what every node's step reads and where each output goes (see worker_plan)."""
        self.plans = [WorkerNode(n, self.blocks[n], self.needed[n], self.src_idx.get(n)) for n in self.order]
        by_name = {nd.name: nd for nd in self.plans}
        for nd in self.plans:
            for port in sorted(self.demanded[nd.name]):
                nd.outputs[port] = OutPort(nd.name, port, self.out_specs[nd.name][port])
            nd.deadlines = self.deadlines.get(nd.name, [])
            nd.remote = self.remote_inputs[nd.name]
        queue = {(nd.name, ip.name): ip.queue for nd in self.plans for ip in nd.inputs}
        for src, sport, dst, dport, delayed in (
            (e.src, e.src_port, e.dst, e.dst_port, e.delayed) for e in plan.edges
        ):
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
