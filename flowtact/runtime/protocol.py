"""The typed boundary between the supervisor and its workers, and its one codec.

What crosses processes on the control socket is a :class:`Message`: a frozen dataclass per
:class:`Op` (:data:`MESSAGES`), handled as such on both ends (attributes, typed fields). A
worker's part of the plan is a :class:`WorkerPlan` of frozen dataclasses (the nodes it builds, its
local edges, the streams it receives and sends, what it records, its deadlines); a stream's
:class:`~flowtact.graphfile.deployment.Flow` (policy and queue bound) travels in it as one value from the
graph's edge to the socket. :func:`encode` and :func:`decode` are the only places that turn these
into msgpack bytes and back (never pickle): the decoder checks every field against its declared
type, so a garbled or foreign message is refused with one line naming its op and field
(:class:`~flowtact.errors.ProtocolError`), never a ``KeyError`` deep in a handler.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import MISSING, dataclass, field, fields, is_dataclass
from enum import StrEnum
from types import UnionType
from typing import Any, ClassVar, Union, get_args, get_origin, get_type_hints

import msgpack
import numpy as np

from flowtact.chunk import StreamSpec
from flowtact.errors import ProtocolError
from flowtact.graphfile.deployment import Flow
from flowtact.runtime.stats import LatencyHistogram

__all__ = [
    "MESSAGES",
    "Abort",
    "Beat",
    "DeadlinePlan",
    "Done",
    "ErrorReport",
    "Exit",
    "Hello",
    "InboundStats",
    "InboundStream",
    "LocalEdge",
    "Message",
    "NodeBuild",
    "Op",
    "OutboundStream",
    "PathStats",
    "Ping",
    "Plan",
    "Ready",
    "RecordedStream",
    "Start",
    "Stats",
    "Stop",
    "Wire",
    "Wired",
    "WorkerPlan",
    "decode",
    "encode",
    "spec_from_wire",
    "spec_to_wire",
]


class Op(StrEnum):
    """What a control message says. The lifecycle: hello -> plan -> ready (bound endpoints) ->
    wire (connect) -> wired -> start -> stats... -> done -> exit; ``beat`` from the heartbeat
    thread, ``ping`` from the supervisor, ``stop`` (at tick ``k``), ``abort`` and ``error`` at any time."""

    HELLO = "hello"
    PLAN = "plan"
    READY = "ready"
    WIRE = "wire"
    WIRED = "wired"
    START = "start"
    STATS = "stats"
    BEAT = "beat"
    PING = "ping"
    STOP = "stop"
    DONE = "done"
    ERROR = "error"
    ABORT = "abort"
    EXIT = "exit"


@dataclass(frozen=True, slots=True)
class NodeBuild:
    """How a worker re-creates one node: its block by registry name, parameters and seed, bound
    to its input streams, with its demanded outputs and needed inputs."""

    name: str
    block: str
    params: dict[str, Any]
    seed: int
    inputs: dict[str, StreamSpec]
    demanded: tuple[str, ...]
    needed: tuple[str, ...]
    src_idx: int | None
    """Its index among the graph's sources (latency origins, deadlines), or None."""


@dataclass(frozen=True, slots=True)
class LocalEdge:
    """An edge between two nodes of the same worker."""

    src: str
    src_port: str
    dst: str
    dst_port: str
    delayed: bool


@dataclass(frozen=True, slots=True)
class InboundStream:
    """A stream a worker receives from another process, and the inputs it feeds."""

    id: int
    stream: str
    spec: StreamSpec
    flow: Flow
    dsts: tuple[tuple[str, str, bool], ...]
    """(node, port, through a delay port) of each input it feeds."""
    same_host: bool
    """Its producer runs on this host: an ipc:// address, latencies on one clock."""


@dataclass(frozen=True, slots=True)
class OutboundStream:
    """A demanded output a worker sends to one consumer process."""

    id: int
    node: str
    port: str
    group: str
    flow: Flow


@dataclass(frozen=True, slots=True)
class RecordedStream:
    node: str
    port: str
    id: int


@dataclass(frozen=True, slots=True)
class DeadlinePlan:
    name: str
    src_idx: int
    dst: str
    budget_s: float


@dataclass(frozen=True, slots=True)
class WorkerPlan:
    """Everything one worker (one process group) needs to run its part of the graph."""

    process: str
    graph: str
    allow_modules: tuple[str, ...]
    """The user's --allow-module, for ``module:Class`` blocks."""
    fast: bool
    merge_ticks: bool
    tick_s: float
    duration_s: float | None
    nodes: tuple[NodeBuild, ...]
    edges: tuple[LocalEdge, ...]
    inbound: tuple[InboundStream, ...]
    outbound: tuple[OutboundStream, ...]
    record: tuple[RecordedStream, ...]
    deadlines: tuple[DeadlinePlan, ...]


# -- control messages -----------------------------------------------------------------------
class Message:
    """A control message: a frozen dataclass whose class says its :class:`Op`."""

    __slots__ = ()
    op: ClassVar[Op]


@dataclass(frozen=True, slots=True)
class Hello(Message):
    """Worker -> supervisor, first: which group this process runs."""

    op: ClassVar[Op] = Op.HELLO
    process: str
    pid: int
    host: str


@dataclass(frozen=True, slots=True)
class Plan(Message):
    """Supervisor -> worker: its part of the plan, and where to bind each inbound stream (by id)."""

    op: ClassVar[Op] = Op.PLAN
    plan: WorkerPlan
    bind: dict[int, str] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class Ready(Message):
    """Worker -> supervisor: built, warm, its inputs bound (stream id -> endpoint)."""

    op: ClassVar[Op] = Op.READY
    endpoints: dict[int, str]
    compiled: int = 0
    """Kernels numba compiled while it warmed up."""
    compile_s: float = 0.0
    setup: dict[str, float] = field(default_factory=dict)
    """Its own start-up parts (s): ``build``, ``warm_up``, ``bind``."""


@dataclass(frozen=True, slots=True)
class Wire(Message):
    """Supervisor -> worker: where each outbound stream's consumers are (id -> group -> endpoint)
    and where the recorder is."""

    op: ClassVar[Op] = Op.WIRE
    connect: dict[int, dict[str, str]]
    record: str


@dataclass(frozen=True, slots=True)
class Wired(Message):
    """Worker -> supervisor: its outputs are connected and its blocks opened."""

    op: ClassVar[Op] = Op.WIRED


@dataclass(frozen=True, slots=True)
class Start(Message):
    """Supervisor -> worker: graph time 0 is ``t0_ns`` (monotonic); begin at tick ``k0``
    (``resume``: a restarted group rejoining a running graph)."""

    op: ClassVar[Op] = Op.START
    t0_ns: int
    k0: int = 0
    resume: bool = False


@dataclass(frozen=True, slots=True)
class InboundStats:
    """What a worker received on one inbound stream so far."""

    messages: int
    samples: int
    dropped: int
    gaps: int
    lat: LatencyHistogram


@dataclass(frozen=True, slots=True)
class PathStats:
    """One deadline path's latencies as its end node's worker measured them."""

    lat: LatencyHistogram
    violations: int
    worst_ns: int


@dataclass(frozen=True, slots=True)
class Stats(Message):
    """Worker -> supervisor, every ``HEARTBEAT_S``: where it is, its CPU, per-node step time,
    per-stream counts and latencies. ``Stats()`` is "nothing reported yet"."""

    op: ClassVar[Op] = Op.STATS
    k: int = 0
    now: float = 0.0
    cpu_s: float = 0.0
    wall_ns: int = 0
    lag_s: float = 0.0
    max_lag_s: float = 0.0
    merged_ticks: int = 0
    node_ns: dict[str, int] = field(default_factory=dict)
    counts: dict[str, int] = field(default_factory=dict)
    """Samples out per ``node.port``."""
    inbound: dict[int, InboundStats] = field(default_factory=dict)
    sent_dropped: dict[int, int] = field(default_factory=dict)
    """Drops at the sending end (a ``latest`` queue full), per stream id, when any."""
    paths: dict[str, PathStats] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class Beat(Message):
    """Worker heartbeat thread -> supervisor, every ``BEAT_S``: its progress (liveness)."""

    op: ClassVar[Op] = Op.BEAT
    process: str
    pid: int
    k: int
    steps: int
    node: str | None
    """The node being built, opened or stepped; None while waiting."""
    first: bool
    """... for the first time: kernels may be compiling."""
    lag_s: float
    compiling: str | None
    """The kernel numba compiles now, if any."""
    compiled: int
    phase: str
    progress: tuple[int, int, int]
    """Start-up progress: phases entered, modules imported, compiler passes run."""
    sent_ns: int
    """The sender's monotonic clock: rates from it, not from arrivals."""


@dataclass(frozen=True, slots=True)
class Ping(Message):
    """Supervisor -> worker: it is alive (a worker on another host exits without pings)."""

    op: ClassVar[Op] = Op.PING


@dataclass(frozen=True, slots=True)
class Stop(Message):
    """Supervisor -> worker: end on tick ``k`` (the same tick everywhere)."""

    op: ClassVar[Op] = Op.STOP
    k: int


@dataclass(frozen=True, slots=True)
class Done(Message):
    """Worker -> supervisor: finished; its last statistics, counters and block summaries."""

    op: ClassVar[Op] = Op.DONE
    stats: Stats
    counters: dict[str, dict[str, int]] = field(default_factory=dict)
    """Per node, its block's counters (those that counted anything)."""
    summaries: dict[str, str] = field(default_factory=dict)
    """Per node, what its block said of the run (``Block.summary``)."""


@dataclass(frozen=True, slots=True)
class ErrorReport(Message):
    """Worker -> supervisor: a block or the worker itself failed. The supervisor also tells a
    death or a stall in this form (``node`` None)."""

    op: ClassVar[Op] = Op.ERROR
    message: str
    node: str | None = None
    block: str | None = None
    now: float | None = None
    """Graph time of the failing step (s)."""
    traceback: str | None = None


@dataclass(frozen=True, slots=True)
class Abort(Message):
    """Supervisor -> worker: stop at once (a failure elsewhere, a second Ctrl-C)."""

    op: ClassVar[Op] = Op.ABORT


@dataclass(frozen=True, slots=True)
class Exit(Message):
    """Supervisor -> worker: the run is over, exit."""

    op: ClassVar[Op] = Op.EXIT


MESSAGES: dict[Op, type[Message]] = {
    cls.op: cls
    for cls in (
        Hello,
        Plan,
        Ready,
        Wire,
        Wired,
        Start,
        Stats,
        Beat,
        Ping,
        Stop,
        Done,
        ErrorReport,
        Abort,
        Exit,
    )
}
"""The message class of every op."""


# -- the codec ------------------------------------------------------------------------------
def encode(msg: Message) -> bytes:
    """A control message as msgpack bytes: a map of its fields and ``"op"``."""
    out = _plain(msg)
    out["op"] = msg.op.value
    return msgpack.packb(out, default=_plain)


def decode(raw: bytes) -> Message:
    """Inverse of :func:`encode`. Anything else (not msgpack, an unknown op, a missing, unknown
    or mistyped field, at any depth) raises :class:`~flowtact.errors.ProtocolError` with one line
    naming the op and the field: a peer of another version, or a garbled one, is refused by name."""
    try:
        fields_ = msgpack.unpackb(raw, strict_map_key=False)
    except Exception as e:  # noqa: BLE001 — msgpack raises several kinds for bad bytes
        why = f"{type(e).__name__}: {e}" if str(e) else type(e).__name__
        raise ProtocolError(f"control message: not msgpack ({why})") from None
    if not isinstance(fields_, dict):
        raise ProtocolError(f"control message: not a map of fields but {_shown(fields_)}")
    op = fields_.pop("op", None)
    cls = MESSAGES.get(op) if isinstance(op, str) else None  # type: ignore[call-overload]
    if cls is None:
        raise ProtocolError(f"control message: unknown op {op!r:.40}")
    try:
        return _read(cls, fields_)
    except _Malformed as e:
        raise ProtocolError(f"control message '{op}': {e}") from None


def spec_to_wire(spec: StreamSpec) -> dict[str, Any]:
    """A stream spec as plain data (its fields by name)."""
    return _plain(spec)


def spec_from_wire(d: Any) -> StreamSpec:
    """Inverse of :func:`spec_to_wire` (:class:`~flowtact.errors.ProtocolError` when malformed)."""
    try:
        return _read(StreamSpec, d)
    except _Malformed as e:
        raise ProtocolError(f"stream spec: {e}") from None


_NAMES: dict[type, tuple[str, ...]] = {}


def _plain(obj: Any) -> Any:
    """msgpack's hook: a dataclass as a map of its fields, a histogram as its wire form, numpy
    scalars as Python numbers (containers and the rest msgpack packs itself)."""
    if isinstance(obj, np.generic):
        return obj.item()
    if is_dataclass(obj):
        names = _NAMES.get(type(obj))
        if names is None:
            names = _NAMES[type(obj)] = tuple(f.name for f in fields(obj))
        return {name: getattr(obj, name) for name in names}
    if isinstance(obj, LatencyHistogram):
        return obj.to_wire()
    raise TypeError(f"cannot send {type(obj).__name__}")


class _Malformed(Exception):
    """A value that does not fit its declared type. ``problem`` has a NUL character where the
    field's path goes; the path is collected while the exception unwinds, so that reading a good
    message builds no strings."""

    def __init__(self, problem: str) -> None:
        super().__init__(problem)
        self.problem = problem
        self.path: list[str] = []

    def __str__(self) -> str:
        return self.problem.replace("\0", "".join(reversed(self.path)).lstrip("."))


Reader = Callable[[Any], Any]
_READERS: dict[Any, Reader] = {}


def _shown(v: Any) -> str:
    return f"{type(v).__name__} {v!r:.40}"


def _read(tp: Any, v: Any) -> Any:
    """``v`` (as msgpack decoded it) checked against type ``tp`` and built into it."""
    return _reader(tp)(v)


def _reader(tp: Any) -> Reader:
    """The function that checks and builds a value of type ``tp`` (made once per type)."""
    got = _READERS.get(tp)
    if got is None:
        got = _READERS[tp] = _make_reader(tp)
    return got


def _make_reader(tp: Any) -> Reader:
    if tp is Any:
        return lambda v: v
    origin = get_origin(tp)
    if origin is not None:
        return _generic_reader(origin, get_args(tp))
    if tp in _SCALARS:
        return _SCALARS[tp]
    if tp is LatencyHistogram:
        return _histogram
    if isinstance(tp, type) and is_dataclass(tp):
        return _dataclass_reader(tp)
    raise TypeError(f"the control protocol cannot carry {tp!r}")  # a mistake in this module


def _wrong(what: str, v: Any) -> _Malformed:
    return _Malformed(f"field '\0' should be {what}, got {_shown(v)}")


def _int(v: Any) -> int:
    if type(v) is int:
        return v
    raise _wrong("int", v)


def _float(v: Any) -> float:
    if type(v) is float:
        return v
    if type(v) is int:
        return float(v)
    raise _wrong("float", v)


def _str(v: Any) -> str:
    if type(v) is str:
        return v
    raise _wrong("str", v)


def _bool(v: Any) -> bool:
    if type(v) is bool:
        return v
    raise _wrong("bool", v)


_SCALARS: dict[type, Reader] = {int: _int, float: _float, str: _str, bool: _bool}


def _histogram(v: Any) -> LatencyHistogram:
    try:
        return LatencyHistogram.from_wire(v)
    except (TypeError, ValueError, OverflowError) as e:
        raise _Malformed(f"field '\0': {e}") from None


def _generic_reader(origin: Any, args: tuple[Any, ...]) -> Reader:
    """``X | None``, ``dict[K, V]``, ``tuple[X, ...]`` and ``tuple[X, Y, ...]``."""
    if origin is UnionType or origin is Union:
        (rest,) = (a for a in args if a is not type(None))  # the protocol's unions are X | None
        inner = _reader(rest)
        return lambda v: None if v is None else inner(v)
    if origin is dict:
        return _dict_reader(_reader(args[0]), _reader(args[1]))
    if origin is tuple and len(args) == 2 and args[1] is Ellipsis:
        return _list_reader(_reader(args[0]))
    if origin is tuple:
        return _row_reader(tuple(_reader(a) for a in args))
    raise TypeError(f"the control protocol cannot carry {origin!r}")  # a mistake in this module


def _dict_reader(key: Reader, value: Reader) -> Reader:
    def read(v: Any) -> dict[Any, Any]:
        if type(v) is not dict:
            raise _wrong("a map", v)
        out = {}
        for k, x in v.items():
            try:
                out[key(k)] = value(x)
            except _Malformed as e:
                e.path.append(f"[{k!r}]")
                raise
        return out

    return read


def _list_reader(item: Reader) -> Reader:
    def read(v: Any) -> tuple[Any, ...]:
        if not isinstance(v, (list, tuple)):
            raise _wrong("a list", v)
        out = []
        for i, x in enumerate(v):
            try:
                out.append(item(x))
            except _Malformed as e:
                e.path.append(f"[{i}]")
                raise
        return tuple(out)

    return read


def _row_reader(items: tuple[Reader, ...]) -> Reader:
    def read(v: Any) -> tuple[Any, ...]:
        if not isinstance(v, (list, tuple)):
            raise _wrong("a list", v)
        if len(v) != len(items):
            raise _Malformed(f"field '\0' should have {len(items)} items, got {len(v)}")
        out = []
        for i, (r, x) in enumerate(zip(items, v, strict=True)):
            try:
                out.append(r(x))
            except _Malformed as e:
                e.path.append(f"[{i}]")
                raise
        return tuple(out)

    return read


def _dataclass_reader(cls: type) -> Reader:
    hints = get_type_hints(cls)
    declared = [
        (f.name, f.default is MISSING and f.default_factory is MISSING, hints[f.name]) for f in fields(cls)
    ]
    names = {name for name, _, _ in declared}
    readers: list[tuple[str, bool, Reader]] = []

    def read(v: Any) -> Any:
        if type(v) is not dict:
            raise _wrong("a map", v)
        if not readers:  # resolved on first use: a dataclass may hold itself
            readers.extend((name, required, _reader(tp)) for name, required, tp in declared)
        if not v.keys() <= names:
            raise _named(_Malformed("unknown field '\0'"), next(str(k) for k in v if k not in names))
        kw = {}
        for name, required, r in readers:
            if name in v:
                try:
                    kw[name] = r(v[name])
                except _Malformed as e:
                    raise _named(e, name) from None
            elif required:
                raise _named(_Malformed("field '\0' is missing"), name)
        return cls(**kw)

    return read


def _named(e: _Malformed, name: str) -> _Malformed:
    """``e`` with the field ``name`` put in front of its path."""
    e.path.append(f".{name}")
    return e
