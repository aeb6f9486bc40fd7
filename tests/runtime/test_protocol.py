"""The process boundary is typed and encoded in one place: a worker plan and control messages
survive the codec whole, and an edge's flow (policy, queue) reaches the worker plan as one value."""

from __future__ import annotations

import textwrap

import msgpack
import pytest
from runs import TEST_BLOCKS

from flowtact.graphfile.deployment import Flow
from flowtact.graphfile.graph import load_graph
from flowtact.running.compile import compile_graph
from flowtact.runtime.placement import place
from flowtact.runtime.protocol import Op, WorkerPlan, decode, encode

GRAPH = """
nodes:
  src: {block: "toyblocks:Ramp", process: a, params: {channels: 3, noise: 0.5}}
  a:   {block: "toyblocks:Loop", process: b}
  b:   {block: "toyblocks:Scale", process: b}
  sum: {block: "toyblocks:Add", process: c}
edges:
  - {from: src.y, to: a.x, policy: latest, queue: 7}
  - a.y -> b.x
  - b.y -> a.fb
  - src.y -> sum.a
  - {from: b.y, to: sum.b, queue: 5}
record: [b.y, sum.y]
deadlines:
  - {from: src, to: sum, budget: 5ms}
"""


def _placed(fast: bool):
    plan = compile_graph(load_graph("g.yaml", text=textwrap.dedent(GRAPH), allow_modules=TEST_BLOCKS))
    return plan, place(plan, fast=fast)


def test_every_worker_plan_survives_the_codec_whole():
    _, placement = _placed(fast=False)
    for group in placement.groups:
        wp = placement.worker_plan(group, fast=False, tick_s=0.01, duration_s=2.0)
        got = decode(encode(Op.PLAN, plan=wp, bind={3: "ipc:///x"}))
        assert got["op"] is Op.PLAN and isinstance(got["plan"], WorkerPlan)
        assert got["plan"] == wp  # every field, nested dataclasses and stream specs included
        assert got["bind"] == {3: "ipc:///x"}
    b = placement.worker_plan("b", fast=False, tick_s=0.01, duration_s=2.0)
    assert {(e.src, e.dst, e.delayed) for e in b.edges} == {("a", "b", False), ("b", "a", True)}
    assert b.inbound[0].spec.units == "N" and b.inbound[0].spec.shape == (3,)
    c = placement.worker_plan("c", fast=False, tick_s=0.01, duration_s=2.0)
    assert c.deadlines[0].budget_s == pytest.approx(0.005) and c.record[0].node == "sum"


def test_an_edges_flow_reaches_both_ends_of_its_stream_as_one_value():
    plan, placement = _placed(fast=False)
    edge = next(e for e in plan.graph.edges if (e.src, e.dst) == ("src", "a"))
    assert edge.flow == Flow("latest", 7)
    b = placement.worker_plan("b", fast=False, tick_s=0.01, duration_s=2.0)
    a = placement.worker_plan("a", fast=False, tick_s=0.01, duration_s=2.0)
    assert [s.flow for s in b.inbound] == [Flow("latest", 7)]
    assert {(s.group, s.flow) for s in a.outbound} == {("b", Flow("latest", 7)), ("c", Flow("block", 64))}
    c = placement.worker_plan("c", fast=False, tick_s=0.01, duration_s=2.0)
    assert {s.stream: s.flow for s in c.inbound} == {"src.y": Flow("block", 64), "b.y": Flow("block", 5)}
    _, fast = _placed(fast=True)  # --fast: every crossing lossless, its queue kept
    assert [s.flow for s in fast.worker_plan("b", fast=True, tick_s=0.01, duration_s=2.0).inbound] == [
        Flow("block", 7)
    ]


def test_control_messages_carry_an_op_and_an_unknown_one_is_refused():
    got = decode(encode(Op.STOP, k=12))
    assert got == {"op": Op.STOP, "k": 12} and got["op"] is Op.STOP
    assert msgpack.unpackb(encode(Op.BEAT, steps=3)) == {
        "steps": 3,
        "op": "beat",
    }  # plain msgpack on the wire
    with pytest.raises(ValueError, match="'launch' is not a valid Op"):
        decode(msgpack.packb({"op": "launch"}))


def test_the_flow_in_a_worker_plan_is_the_high_water_mark_of_both_socket_ends(tmp_path):
    import zmq

    from flowtact.runtime.links.zeromq.streams import ZmqInbound, ZmqOutbound, bind_address

    _, placement = _placed(fast=False)
    b, a = (placement.worker_plan(g, fast=False, tick_s=0.01, duration_s=2.0) for g in ("b", "a"))
    inbound = ZmqInbound(decode(encode(Op.PLAN, plan=b))["plan"].inbound[0])
    outbound = ZmqOutbound(
        next(s for s in decode(encode(Op.PLAN, plan=a))["plan"].outbound if s.group == "b")
    )
    ctx = zmq.Context()
    try:
        where = bind_address(str(tmp_path), b.inbound[0], "b", None, "127.0.0.1")
        assert where == f"ipc://{tmp_path}/s{b.inbound[0].id}-b"  # same host: ipc in the run folder
        bound = inbound.bind(ctx, where)
        outbound.connect(ctx, bound)
        assert inbound.sock.getsockopt(zmq.RCVHWM) == outbound.sock.getsockopt(zmq.SNDHWM) == 7
    finally:
        for s in (inbound.sock, outbound.sock):
            if s is not None:
                s.close(linger=0)
        ctx.term()
