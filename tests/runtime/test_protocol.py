"""The process boundary is typed and encoded in one place: a worker plan and every control message
survive the codec whole, a malformed or foreign message is refused with one line naming its op and
field (and never brings the supervisor down), and an edge's flow (policy, queue) reaches the
worker plan as one value."""

from __future__ import annotations

import copy
import dataclasses
import textwrap

import msgpack
import pytest
from runs import TEST_BLOCKS

from flowtact.errors import ProcessFailure, ProtocolError
from flowtact.graphfile.deployment import Flow
from flowtact.graphfile.graph import load_graph
from flowtact.running.compile import compile_graph
from flowtact.runtime.placement import place
from flowtact.runtime.protocol import (
    MESSAGES,
    Abort,
    Beat,
    Done,
    ErrorReport,
    Exit,
    Hello,
    InboundStats,
    Message,
    Op,
    PathStats,
    Ping,
    Plan,
    Ready,
    Start,
    Stats,
    Stop,
    Wire,
    Wired,
    WorkerPlan,
    decode,
    encode,
)
from flowtact.runtime.stats import LatencyHistogram

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
        got = decode(encode(Plan(wp, {3: "ipc:///x"})))
        assert isinstance(got, Plan) and isinstance(got.plan, WorkerPlan)
        assert got.plan == wp  # every field, nested dataclasses and stream specs included
        assert got.bind == {3: "ipc:///x"}
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


def _histogram(*ns: int) -> LatencyHistogram:
    h = LatencyHistogram()
    for x in ns:
        h.add(x)
    return h


def _one_of_each() -> list[Message]:
    """A message of every op, every field set to something other than its default."""
    _, placement = _placed(fast=False)
    stats = Stats(
        k=7,
        now=0.07,
        cpu_s=1.5,
        wall_ns=123_456_789,
        lag_s=0.001,
        max_lag_s=0.002,
        merged_ticks=3,
        node_ns={"a": 1000, "b": 2000},
        counts={"a.y": 70},
        inbound={4: InboundStats(7, 70, 1, 2, _histogram(1_000, 50_000))},
        sent_dropped={5: 3},
        paths={"src->sum": PathStats(_histogram(2_000_000), 1, 6_000_000)},
    )
    return [
        Hello("b", 4242, "rig-1"),
        Plan(placement.worker_plan("b", fast=False, tick_s=0.01, duration_s=2.0), {4: "ipc:///run/s4-b"}),
        Ready(
            {4: "ipc:///run/s4-b"},
            compiled=2,
            compile_s=3.5,
            setup={"build": 0.1, "warm_up": 0.2, "bind": 0.0},
        ),
        Wire({5: {"c": "ipc:///run/s5-c", "d": "tcp://10.0.0.2:5555"}}, "ipc:///run/rec"),
        Wired(),
        Start(1_000_000_000, k0=12, resume=True),
        stats,
        Beat("b", 4242, 7, 99, "a", True, 0.5, "nlif_step", 2, "warming node 'a'", (3, 812, 40), 5_000),
        Ping(),
        Stop(30),
        Done(stats, {"a": {"nonfinite": 2}}, {"a": "2 frames dropped"}),
        ErrorReport("ValueError: bad", node="a", block="toyblocks:Loop", now=0.25, traceback="Traceback ..."),
        Abort(),
        Exit(),
    ]


def _same(a: object, b: object) -> bool:
    """Equal, histograms by their contents (a histogram compares by identity)."""
    if isinstance(a, LatencyHistogram):
        return isinstance(b, LatencyHistogram) and a.to_wire() == b.to_wire()
    if dataclasses.is_dataclass(a):
        return type(a) is type(b) and all(
            _same(getattr(a, f.name), getattr(b, f.name)) for f in dataclasses.fields(a)
        )
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    return type(a) is type(b) and a == b


def test_every_control_message_survives_the_codec_whole_as_its_own_class():
    messages = _one_of_each()
    assert {m.op for m in messages} == set(Op) == set(MESSAGES)  # one class per op, each tried here
    for m in messages:
        got = decode(encode(m))
        assert type(got) is type(m) and _same(got, m), m.op
        assert dataclasses.is_dataclass(got) and not hasattr(got, "__dict__")  # slots
        for f in dataclasses.fields(got)[:1]:
            with pytest.raises(dataclasses.FrozenInstanceError):
                setattr(got, f.name, None)
    done = decode(encode(messages[10]))
    assert done.stats.inbound[4].lat.summary()["n"] == 2  # type: ignore[attr-defined]
    assert done.stats.paths["src->sum"].worst_ns == 6_000_000  # type: ignore[attr-defined]


def test_the_wire_stays_plain_msgpack_with_the_op_beside_the_fields():
    assert msgpack.unpackb(encode(Stop(12))) == {"k": 12, "op": "stop"}
    assert msgpack.unpackb(encode(Ping())) == {"op": "ping"}
    assert decode(msgpack.packb({"op": "start", "t0_ns": 5})) == Start(5, k0=0, resume=False)  # defaults


GOOD_STATS = msgpack.unpackb(encode(_one_of_each()[6]), strict_map_key=False)


def _with(base: dict, path: tuple, value: object) -> bytes:
    """``base`` (a decoded message) with the value at ``path`` replaced (``...``: removed)."""
    doc = copy.deepcopy(base)
    here = doc
    for key in path[:-1]:
        here = here[key]
    if value is ...:
        del here[path[-1]]
    else:
        here[path[-1]] = value
    return msgpack.packb(doc)


@pytest.mark.parametrize(
    ("raw", "message"),
    [
        (b"\xc1\x00", r"^control message: not msgpack \(.+\)$"),
        (b"", r"^control message: not msgpack"),
        (msgpack.packb([1, 2]), r"^control message: not a map of fields but list \[1, 2\]$"),
        (msgpack.packb({"op": "launch"}), r"^control message: unknown op 'launch'$"),
        (msgpack.packb({"k": 3}), r"^control message: unknown op None$"),
        (msgpack.packb({"op": 7}), r"^control message: unknown op 7$"),
        (msgpack.packb({"op": "stop"}), r"^control message 'stop': field 'k' is missing$"),
        (
            msgpack.packb({"op": "stop", "k": "3"}),
            r"^control message 'stop': field 'k' should be int, got str '3'$",
        ),
        (msgpack.packb({"op": "stop", "k": True}), r"field 'k' should be int, got bool True$"),
        (msgpack.packb({"op": "stop", "k": 3, "at": 1}), r"^control message 'stop': unknown field 'at'$"),
        (
            msgpack.packb({"op": "hello", "process": "a", "pid": 1.5, "host": "h"}),
            r"'hello': field 'pid' should be int",
        ),
        (
            msgpack.packb({"op": "ready", "endpoints": {"4": "ipc:///x"}}),
            r"^control message 'ready': field 'endpoints\['4'\]' should be int, got str '4'$",
        ),
        (
            msgpack.packb({"op": "ready", "endpoints": [1]}),
            r"'ready': field 'endpoints' should be a map, got list",
        ),
        (
            _with(GOOD_STATS, ("inbound", 4, "gaps"), ...),
            r"^control message 'stats': field 'inbound\[4\]\.gaps' is missing$",
        ),
        (
            _with(GOOD_STATS, ("paths", "src->sum", "lat"), [1, 2]),
            r"^control message 'stats': field 'paths\['src->sum'\]\.lat': not a latency histogram",
        ),
        (
            _with(GOOD_STATS, ("node_ns", "a"), None),
            r"'stats': field 'node_ns\['a'\]' should be int, got NoneType None$",
        ),
        (
            msgpack.packb(
                {
                    "op": "beat",
                    **dict.fromkeys(("process", "phase", "node", "compiling"), "x"),
                    **dict.fromkeys(("pid", "k", "steps", "compiled", "sent_ns"), 1),
                    "first": True,
                    "lag_s": 0.0,
                    "progress": [1, 2],
                }
            ),
            r"^control message 'beat': field 'progress' should have 3 items, got 2$",
        ),
        (
            msgpack.packb({"op": "done", "stats": {"k": "x"}}),
            r"^control message 'done': field 'stats\.k' should be int, got str 'x'$",
        ),
        (
            msgpack.packb({"op": "plan", "plan": {"process": "b"}}),
            r"^control message 'plan': field 'plan\.graph' is missing$",
        ),
    ],
)
def test_a_malformed_message_is_refused_in_one_line_naming_op_and_field(raw, message):
    with pytest.raises(ProtocolError, match=message) as caught:
        decode(raw)
    assert "\n" not in str(caught.value) and caught.value.__cause__ is None


def test_a_malformed_worker_plan_is_refused_at_its_nested_field():
    _, placement = _placed(fast=False)
    doc = msgpack.unpackb(
        encode(Plan(placement.worker_plan("b", fast=False, tick_s=0.01, duration_s=2.0))),
        strict_map_key=False,
    )
    doc["plan"]["inbound"][0]["spec"]["shape"] = [3, "x"]
    with pytest.raises(
        ProtocolError,
        match=r"^control message 'plan': field 'plan\.inbound\[0\]\.spec\.shape\[1\]' should be int, got str 'x'$",
    ):
        decode(msgpack.packb(doc))


def _supervisor_poll(frames: list[bytes], known: bool, wplans=None) -> tuple[list[str], BaseException | None]:
    """Send ``frames`` from a peer to a supervisor's control socket and let it poll once: what it
    warned, and what it raised."""
    import zmq

    from flowtact.runtime.supervisor import ProcessExecutor
    from flowtact.runtime.supervisor_procs import Proc

    ctx = zmq.Context()
    ctl, peer = ctx.socket(zmq.ROUTER), ctx.socket(zmq.DEALER)
    try:
        port = ctl.bind_to_random_port("tcp://127.0.0.1")
        peer.setsockopt(zmq.IDENTITY, b"peer")
        peer.connect(f"tcp://127.0.0.1:{port}")
        sup = ProcessExecutor.__new__(ProcessExecutor)  # only what the pump's control path reads
        said: list[str] = []
        sup.warn, sup.strangers = said.append, 0
        sup.ctl, sup.ctl_tcp = ctl, None
        sup.poller = zmq.Poller()
        sup.poller.register(ctl, zmq.POLLIN)
        proc = Proc("b", ["a", "b"], None, "never", 0, 1.0, 1.0, 1.0)
        sup.procs, sup.by_ident = {"b": proc}, ({b"peer": proc} if known else {})
        sup.wplans = wplans or {}
        peer.send_multipart(frames)
        raised = None
        try:
            for _ in range(100):  # until it has read the message (each poll waits up to 100 ms for it)
                sup._poll(100)  # noqa: SLF001 — the pump's control path under test
                if said:
                    break
        except ProcessFailure as e:
            raised = e
        return said, raised
    finally:
        ctl.close(linger=0)
        peer.close(linger=0)
        ctx.term()


def test_a_garbled_stranger_is_ignored_with_one_warning_and_the_supervisor_runs_on():
    said, raised = _supervisor_poll([msgpack.packb({"op": "stats", "k": "x"})], known=False)
    assert raised is None
    assert said == [
        "ignored a malformed control message from an unknown peer: "
        "control message 'stats': field 'k' should be int, got str 'x'"
    ]
    said, raised = _supervisor_poll([b"a", b"b"], known=False)  # two frames where one belongs
    assert raised is None and said == [
        "ignored a malformed control message from an unknown peer: control message: 2 frames, not 1"
    ]


def test_a_garbled_message_from_a_worker_fails_that_worker_by_name():
    from flowtact.runtime.supervisor_procs import describe_failure

    said, raised = _supervisor_poll([msgpack.packb({"op": "ready"})], known=True)
    assert isinstance(raised, ProcessFailure) and not said
    assert describe_failure(raised.proc, raised.report) == (
        "process 'b' (nodes a, b) sent a malformed control message: "
        "control message 'ready': field 'endpoints' is missing"
    )


def test_a_worker_ready_without_binding_its_inputs_fails_by_name_not_by_keyerror():
    _, placement = _placed(fast=False)
    wplans = {"b": placement.worker_plan("b", fast=False, tick_s=0.01, duration_s=2.0)}
    sid = wplans["b"].inbound[0].id
    said, raised = _supervisor_poll([encode(Ready({}))], known=True, wplans=wplans)
    assert isinstance(raised, ProcessFailure) and not said
    assert raised.report.message == f"said ready without an endpoint for stream(s) [{sid}]"


def test_the_flow_in_a_worker_plan_is_the_high_water_mark_of_both_socket_ends(tmp_path):
    import zmq

    from flowtact.runtime.links.zeromq.streams import ZmqInbound, ZmqOutbound, bind_address

    _, placement = _placed(fast=False)
    b, a = (placement.worker_plan(g, fast=False, tick_s=0.01, duration_s=2.0) for g in ("b", "a"))
    inbound = ZmqInbound(decode(encode(Plan(b))).plan.inbound[0])  # type: ignore[attr-defined]
    outbound = ZmqOutbound(
        next(s for s in decode(encode(Plan(a))).plan.outbound if s.group == "b")  # type: ignore[attr-defined]
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
