"""Split a compiled plan into process groups, and each group's part into a plain worker plan.

Placement: a node runs in the group its ``process:`` names; a node without one runs with the
producer of its first input (so a chain follows its source), and a source without one in the
group ``main``. Streams that cross groups become ZeroMQ edges with the flow (policy and queue
bound) of their graph edges. A worker plan is a typed :class:`~flowtact.runtime.protocol.WorkerPlan`
(encoded in one place, :mod:`flowtact.runtime.protocol`): blocks are re-created from their
registry name, parameters and seed, so blocks are the same objects in every mode.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from flowtact.block import Source
from flowtact.errors import GraphFileError
from flowtact.graphfile.deployment import Flow, ProcessDef
from flowtact.graphfile.located import GraphProblem
from flowtact.running.compile import CompiledGraph
from flowtact.runtime.protocol import (
    DeadlinePlan,
    InboundStream,
    LocalEdge,
    NodeBuild,
    OutboundStream,
    RecordedStream,
    WorkerPlan,
)
from flowtact.runtime.worker_plan import ticks_mergeable

__all__ = ["DEFAULT_GROUP", "MAX_LOCAL_PROCESSES", "Placement", "default_groups", "place"]

DEFAULT_GROUP = "main"
MAX_LOCAL_PROCESSES = 64
"""Process groups one host runs at most: each is a Python interpreter with numpy, numba and ZeroMQ
(≈ 60–100 MB and ≈ 1 s of CPU to start), and one supervisor serves them all."""


@dataclass
class Placement:
    """Which group runs each node, the cross-group streams, and every group's worker plan."""

    plan: CompiledGraph
    group_of: dict[str, str]
    groups: dict[str, list[str]]
    processes: dict[str, ProcessDef]
    stream_ids: dict[tuple[str, str], int]
    #: (stream id, consumer group) -> its flow (policy, queue) for every stream that crosses groups
    crossings: dict[tuple[int, str], Flow] = field(default_factory=dict)

    def stream_name(self, sid: int) -> str:
        return self._names[sid]

    def __post_init__(self) -> None:
        self._names = {sid: f"{n}.{p}" for (n, p), sid in self.stream_ids.items()}

    def consumers(self, sid: int) -> list[str]:
        """Groups that receive stream ``sid`` over the network."""
        return sorted({g for (s, g) in self.crossings if s == sid})

    def worker_plan(self, group: str, *, fast: bool, tick_s: float, duration_s: float | None) -> WorkerPlan:
        """Everything worker ``group`` needs."""
        plan, graph = self.plan, self.plan.graph
        mine = self.groups[group]
        src_index = {
            n: i for i, n in enumerate(n for n in plan.order if issubclass(graph.nodes[n].cls, Source))
        }
        host = self.processes[group].host
        nodes = tuple(
            NodeBuild(
                name=n,
                block=graph.nodes[n].block,
                params=graph.nodes[n].config.to_dict(),
                seed=plan.seeds[n],
                inputs=dict(plan.input_specs(n)),
                demanded=tuple(sorted(plan.demanded[n])),
                needed=tuple(sorted(plan.needed[n])),
                src_idx=src_index.get(n),
            )
            for n in mine
        )
        edges: list[LocalEdge] = []
        inbound: dict[int, tuple[str, str, list[tuple[str, str, bool]]]] = {}
        for e in plan.active_edges:
            if e.dst not in mine:
                continue
            delayed = graph.nodes[e.dst].cls.inputs[e.dst_port].delay
            if e.src in mine:
                edges.append(LocalEdge(e.src, e.src_port, e.dst, e.dst_port, delayed))
                continue
            sid = self.stream_ids[(e.src, e.src_port)]
            inbound.setdefault(sid, (e.src, e.src_port, []))[2].append((e.dst, e.dst_port, delayed))
        return WorkerPlan(
            process=group,
            graph=graph.name,
            allow_modules=tuple(graph.allow_modules),
            fast=fast,
            merge_ticks=fast and ticks_mergeable(plan),
            tick_s=tick_s,
            duration_s=duration_s,
            nodes=nodes,
            edges=tuple(edges),
            inbound=tuple(
                InboundStream(
                    id=sid,
                    stream=f"{src}.{port}",
                    spec=plan.specs[(src, port)],
                    flow=self.crossings[(sid, group)],
                    dsts=tuple(dsts),
                    same_host=self.processes[self.group_of[src]].host == host,
                )
                for sid, (src, port, dsts) in inbound.items()
            ),
            outbound=tuple(
                OutboundStream(id=sid, node=n, port=p, group=g, flow=self.crossings[(sid, g)])
                for (n, p), sid in self.stream_ids.items()
                if n in mine
                for g in self.consumers(sid)
            ),
            record=tuple(RecordedStream(n, p, self.stream_ids[(n, p)]) for n, p in plan.record if n in mine),
            deadlines=tuple(
                DeadlinePlan(d.name, src_index[d.src], d.dst, d.budget_s)
                for d in graph.deployment.deadlines
                if d.dst in mine and d.src in src_index
            ),
        )


def default_groups(plan: CompiledGraph) -> dict[str, str]:
    """Each active node's process group by the runtime's rule: its declared ``process``, else its
    first producer's group, else the default group."""
    graph = plan.graph
    first_input: dict[str, str] = {}
    for e in plan.active_edges:
        first_input.setdefault(e.dst, e.src)
    group_of: dict[str, str] = {}
    for n in plan.order:  # topological: a node's producers are placed before it
        declared = graph.nodes[n].process
        if declared:
            group_of[n] = declared
        elif n in first_input and first_input[n] in group_of:
            group_of[n] = group_of[first_input[n]]
        else:
            group_of[n] = DEFAULT_GROUP
    return group_of


def place(plan: CompiledGraph, *, fast: bool) -> Placement:
    """Group the plan's active nodes into processes and find the streams that cross groups.

    In ``fast`` mode every edge is ``block`` (lossless), whatever the graph says, so that a
    virtual-clock run is deterministic.
    """
    graph = plan.graph
    group_of = default_groups(plan)
    groups: dict[str, list[str]] = {}
    for n in plan.order:
        groups.setdefault(group_of[n], []).append(n)
    processes = {g: graph.deployment.process(g) for g in groups}
    local = [g for g in groups if processes[g].host is None]
    if len(local) > MAX_LOCAL_PROCESSES:
        first = graph.nodes[groups[local[MAX_LOCAL_PROCESSES]][0]]
        raise GraphFileError(
            [
                GraphProblem(
                    first.loc,
                    f"the graph places {len(local)} process groups on this host; flowtact runs at most "
                    f"{MAX_LOCAL_PROCESSES} (each is a Python process of its own)",
                    "put several nodes in one group with `process: NAME`, or give groups a `host:`",
                )
            ]
        )
    stream_ids = {
        (n, p): i for i, (n, p) in enumerate((n, p) for n in plan.order for p in sorted(plan.demanded[n]))
    }
    crossings: dict[tuple[int, str], Flow] = {}
    errors = []
    for e in plan.active_edges:
        g_src, g_dst = group_of[e.src], group_of[e.dst]
        if g_src == g_dst:
            continue
        key = (stream_ids[(e.src, e.src_port)], g_dst)
        flow = Flow("block", e.queue) if fast else e.flow
        if key in crossings and crossings[key] != flow:
            errors.append(
                GraphProblem(
                    e.loc,
                    f"{e}: the edges from '{e.src}.{e.src_port}' into process '{g_dst}' disagree on policy/queue",
                    "a stream enters a process once: give its edges into that process the same policy and queue",
                )
            )
        crossings[key] = flow
    if errors:
        raise GraphFileError(errors)
    return Placement(plan, group_of, groups, processes, stream_ids, crossings)
