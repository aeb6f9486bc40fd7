"""Where and how a graph runs: process groups, restarts, hosts, network keys and path deadlines.

These are the graph file's ``processes:``, ``network:`` and ``deadlines:`` sections. They never
change what a graph computes, only how it is spread over processes and hosts and what the run
reports; :mod:`flowtact.graphfile.graph` calls :func:`parse_deployment` and reports problems with locations.

.. code-block:: yaml

    processes:
      neurons: {restart: on-failure, max_restarts: 3, stall_s: 0.5}
      vision:  {host: 10.0.0.2, startup_s: 300}   # started there by `flowtact worker`
    network: {listen: 10.0.0.1, port: 5550, keys: ~/.flowtact/keys}
    deadlines:
      - {from: sensor, to: sa1_stim, budget: 4ms}
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

from flowtact.graphfile.located import GraphProblem, Loc, Located
from flowtact.inputs.limits import host_problem
from flowtact.params import did_you_mean

__all__ = [
    "Deadline",
    "Deployment",
    "Flow",
    "Network",
    "ProcessDef",
    "deadline_path_errors",
    "parse_deployment",
    "parse_duration",
]

PROCESS_KEYS = ("restart", "max_restarts", "host", "stall_s", "startup_s", "stop_grace_s")
NETWORK_KEYS = ("listen", "port", "keys")
DEADLINE_KEYS = ("from", "to", "budget")
RESTARTS = ("never", "on-failure")
POLICIES = ("block", "latest")
DEFAULT_QUEUE = 64


@dataclass(frozen=True)
class Flow:
    """How an edge's stream flows across processes: its policy (``block``: lossless, back-pressure;
    ``latest``: keep the newest ``queue`` messages) and its queue bound, in messages. One value
    from the graph's edge (:attr:`flowtact.graphfile.graph.Edge.flow`) to the socket's high-water mark."""

    policy: str = "block"
    queue: int = DEFAULT_QUEUE


_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6}


STALL_REALTIME_S = 1.0
"""Default ``stall_s`` in real time: a worker that shows no progress this long has stalled."""
STALL_FAST_S = 30.0
"""Default ``stall_s`` on the virtual clock, where one tick may carry seconds of data."""
STARTUP_LOCAL_S = 60.0
"""Default ``startup_s`` of a group on this host: the longest start-up step without progress (starting
the interpreter, one import, one compiler pass, one warm-up step, one block's ``open()``)."""
STARTUP_REMOTE_S = 120.0
"""Default ``startup_s`` of a group with ``host:``: someone has to start it there by hand."""
MAX_STARTUP_S = 86_400.0
"""Longest start-up window ``--startup-s`` takes (a day): a window is time *without progress*, so
even a first run that compiles for an hour needs far less; more is a typing slip."""
STOP_GRACE_S = 10.0
"""Default ``stop_grace_s``: how long a stopped run may drain before it is aborted."""


@dataclass(frozen=True)
class ProcessDef:
    """A process group: restart policy, host (None: this machine) and supervision windows.

    ``stall_s`` (None: :data:`STALL_REALTIME_S` in real time, :data:`STALL_FAST_S` with
    ``--fast``) bounds how long a worker may show no progress; ``startup_s`` how long it may show
    no start-up progress before it joins (each phase, import, compiler pass and warm-up step it
    reports restarts the window; ``flowtact run --startup-s`` replaces it for every group) and
    how long a node's first step may take; ``stop_grace_s`` how long it may drain after a stop.
    """

    name: str
    restart: str = "never"
    max_restarts: int = 3
    host: str | None = None
    stall_s: float | None = None
    startup_s: float | None = None
    stop_grace_s: float = STOP_GRACE_S

    def stall_window(self, fast: bool) -> float:
        """Seconds without progress after which this group's worker counts as stalled."""
        if self.stall_s is not None:
            return self.stall_s
        return STALL_FAST_S if fast else STALL_REALTIME_S

    def startup_window(self) -> float:
        """Seconds this group's worker may go without start-up progress before it joins the run."""
        if self.startup_s is not None:
            return self.startup_s
        return STARTUP_REMOTE_S if self.host else STARTUP_LOCAL_S


@dataclass(frozen=True)
class Network:
    """Off-host transport: the supervisor's listen address and port, and the CURVE keys folder."""

    listen: str = "127.0.0.1"
    port: int = 5550
    keys: str | None = None


@dataclass(frozen=True)
class Deadline:
    """A latency budget from a source node's emission to a node's output."""

    src: str
    dst: str
    budget_s: float
    loc: Loc | None = None

    @property
    def name(self) -> str:
        return f"{self.src} -> {self.dst}"


@dataclass
class Deployment:
    """Everything about placement and supervision a graph declares."""

    processes: dict[str, ProcessDef] = field(default_factory=dict)
    network: Network = field(default_factory=Network)
    deadlines: list[Deadline] = field(default_factory=list)

    def process(self, name: str) -> ProcessDef:
        """The declared group, or the defaults for one named only on nodes."""
        return self.processes.get(name) or ProcessDef(name)

    @property
    def remote(self) -> bool:
        """Does any group run on another host?"""
        return any(p.host for p in self.processes.values())


def parse_duration(value: Any) -> float | None:
    """``4ms``, ``500us``, ``0.004s`` or a number of seconds -> seconds (None if malformed)."""
    if isinstance(value, bool):
        return None
    if isinstance(value, (int, float)):
        return float(value) if value > 0 else None
    m = re.fullmatch(r"\s*([0-9]*\.?[0-9]+(?:e-?[0-9]+)?)\s*(s|ms|us|µs)\s*", str(value))
    if not m:
        return None
    seconds = float(m.group(1)) * _UNITS[m.group(2)]
    return seconds if seconds > 0 else None


def parse_deployment(doc: dict[str, Any], y: Located, node_docs: dict[str, Any]) -> Deployment:
    """Read ``processes:``, ``network:`` and ``deadlines:``; append problems to ``y.errors``."""
    return Deployment(
        processes=_parse_processes(doc, y, node_docs),
        network=_parse_network(doc, y),
        deadlines=_parse_deadlines(doc, y, node_docs),
    )


def _parse_processes(doc: dict[str, Any], y: Located, node_docs: dict[str, Any]) -> dict[str, ProcessDef]:
    """The ``processes:`` groups that hold nodes; a group no node names is an error."""
    used = {
        n.get("process")
        for n in node_docs.values()
        if isinstance(n, dict) and isinstance(n.get("process"), str)
    }
    for name, n in node_docs.items():  # a sharded node's groups: its process list, else <node>_s<k>
        if not isinstance(n, dict) or not isinstance(n.get("shards"), int):
            continue
        given = n.get("process")
        if isinstance(given, list):
            used.update(g for g in given if isinstance(g, str))
        elif given is None:
            used.update(f"{name}_s{k}" for k in range(n["shards"]))
    raw = doc.get("processes") or {}
    if not isinstance(raw, dict):
        y.errors.append(
            GraphProblem(y.loc("processes"), "'processes' must map a process name to its settings")
        )
        raw = {}
    out: dict[str, ProcessDef] = {}
    for name, pdoc in raw.items():
        if name not in used:
            y.errors.append(
                GraphProblem(
                    y.key_loc("processes", name),
                    f"process '{name}' has no nodes{did_you_mean(str(name), [u for u in used if u])}",
                    "place nodes in it with `process: NAME` on each node",
                )
            )
            continue
        process = _parse_process(name, pdoc or {}, y)
        if process is not None:
            out[str(name)] = process
    return out


def _parse_process(name: Any, pdoc: Any, y: Located) -> ProcessDef | None:
    """One group's supervision settings (defaults for what is missing or malformed); None if not a mapping."""
    where = f"process '{name}'"
    if not isinstance(pdoc, dict):
        y.errors.append(GraphProblem(y.loc("processes", name), f"{where} must be a mapping"))
        return None
    y.errors.extend(y.unknown_keys(pdoc, PROCESS_KEYS, where, "processes", name))
    restart = pdoc.get("restart", "never")
    if restart not in RESTARTS:
        y.errors.append(
            GraphProblem(
                y.loc("processes", name, "restart"),
                f"{where}: restart must be one of {', '.join(RESTARTS)}; got {restart!r}",
            )
        )
        restart = "never"
    max_restarts = pdoc.get("max_restarts", 3)
    if isinstance(max_restarts, bool) or not isinstance(max_restarts, int) or max_restarts < 0:
        y.errors.append(
            GraphProblem(
                y.loc("processes", name, "max_restarts"), f"{where}: max_restarts must be an integer >= 0"
            )
        )
        max_restarts = 3
    host = pdoc.get("host")
    problem = host_problem(host) if host is not None else None
    if problem:
        y.errors.append(GraphProblem(y.loc("processes", name, "host"), f"{where}: host {problem}"))
        host = None
    windows = _process_windows(name, pdoc, y)
    return ProcessDef(str(name), restart, max_restarts, host, **windows)  # type: ignore[arg-type]


def _process_windows(name: Any, pdoc: dict[str, Any], y: Located) -> dict[str, float]:
    """The group's ``stall_s``, ``startup_s`` and ``stop_grace_s`` that are given and valid, in seconds."""
    windows: dict[str, float] = {}
    for key in ("stall_s", "startup_s", "stop_grace_s"):
        if key not in pdoc:
            continue
        seconds = parse_duration(pdoc[key])
        if seconds is None or not math.isfinite(seconds):
            y.errors.append(
                GraphProblem(
                    y.loc("processes", name, key),
                    f"process '{name}': {key} must be a positive duration such as 1 or 500ms; got {pdoc[key]!r}",
                )
            )
            continue
        windows[key] = seconds
    return windows


def _parse_network(doc: dict[str, Any], y: Located) -> Network:
    """``network:`` (listen address, port, CURVE keys directory), defaults for what is missing or bad."""
    net = doc.get("network") or {}
    if not isinstance(net, dict):
        y.errors.append(GraphProblem(y.loc("network"), "'network' must be a mapping (listen, port, keys)"))
        net = {}
    y.errors.extend(y.unknown_keys(net, NETWORK_KEYS, "network", "network"))
    port = net.get("port", 5550)
    if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port < 65536:
        y.errors.append(
            GraphProblem(y.loc("network", "port"), f"network: port must be 0..65535; got {port!r}")
        )
        port = 5550
    listen = net.get("listen", "127.0.0.1")
    problem = host_problem(listen, wildcard=True)
    if problem:
        y.errors.append(GraphProblem(y.loc("network", "listen"), f"network: listen {problem}"))
        listen = "127.0.0.1"
    keys = net.get("keys")
    return Network(str(listen), port, str(keys) if keys is not None else None)


def _parse_deadlines(doc: dict[str, Any], y: Located, node_docs: dict[str, Any]) -> list[Deadline]:
    """The valid entries of ``deadlines:``."""
    raw = doc.get("deadlines") or []
    if not isinstance(raw, list):
        y.errors.append(GraphProblem(y.loc("deadlines"), "'deadlines' must be a list of {from, to, budget}"))
        raw = []
    deadlines = (_parse_deadline(i, d, y, node_docs) for i, d in enumerate(raw))
    return [d for d in deadlines if d is not None]


def _parse_deadline(i: int, d: Any, y: Located, node_docs: dict[str, Any]) -> Deadline | None:
    """Deadline ``i``: two known nodes and a positive budget, or None (the problems go to ``y.errors``)."""
    loc = y.loc("deadlines", i)
    if not isinstance(d, dict):
        y.errors.append(
            GraphProblem(loc, "a deadline is a mapping like {from: sensor, to: stim, budget: 4ms}")
        )
        return None
    y.errors.extend(y.unknown_keys(d, DEADLINE_KEYS, "deadline", "deadlines", i))
    ends = []
    for key in ("from", "to"):
        node = d.get(key)
        if node not in node_docs:
            y.errors.append(
                GraphProblem(
                    y.loc("deadlines", i, key),
                    f"deadline '{key}': unknown node {node!r}{did_you_mean(str(node), map(str, node_docs))}",
                )
            )
        ends.append(node)
    budget = parse_duration(d.get("budget"))
    if budget is None:
        y.errors.append(
            GraphProblem(
                y.loc("deadlines", i, "budget"),
                f"deadline budget must be a positive duration such as 4ms or 500us; got {d.get('budget')!r}",
            )
        )
    if all(e in node_docs for e in ends) and budget is not None:
        return Deadline(str(ends[0]), str(ends[1]), budget, loc)
    return None


def deadline_path_errors(deadlines: Iterable[Deadline], edges: Iterable[Any]) -> list[GraphProblem]:
    """An error at each deadline whose ``to`` node no path of ``edges`` (``.src`` -> ``.dst``)
    leads to from its ``from`` node: its latency could never be measured."""
    after: dict[str, set[str]] = {}
    for e in edges:
        after.setdefault(e.src, set()).add(e.dst)
    errors = []
    for d in deadlines:
        reached, todo = {d.src}, [d.src]
        while todo:
            for nxt in after.get(todo.pop(), ()):
                if nxt not in reached:
                    reached.add(nxt)
                    todo.append(nxt)
        if d.dst not in reached:
            errors.append(
                GraphProblem(
                    d.loc or Loc("?"),
                    f"deadline {d.src} -> {d.dst}: no path of edges leads from '{d.src}' to '{d.dst}'",
                    "a deadline times data along a path; pick nodes that one feeds the other",
                )
            )
    return errors
