"""The supervisor: runs a plan across worker processes, records it, and reports on it.

It places the nodes (:mod:`flowtact.runtime.placement`), starts one worker per local process
group (a group with a ``host:`` is started there by ``flowtact worker``), hands each its part of
the plan, wires the streams (ipc:// on this host, tcp:// with CurveZMQ to other hosts), starts
them on a common clock, and then, until every worker is done: writes recorded streams to the
recorder, collects heartbeats (rates, latencies, drops, CPU), pings the workers, watches their
processes, and stops everything cleanly on Ctrl-C. A worker that raises or dies is named with its
nodes and cause; the run then ends (recording flushed up to the failure) or, when its group says
``restart: on-failure``, the worker is started again and rejoins the running graph.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgpack
import zmq

from flowtact.compile import Plan
from flowtact.runtime.clock import tick_for
from flowtact.runtime.inproc import RunSummary, Sink
from flowtact.runtime.placement import Placement, place
from flowtact.runtime.stats import LatencyHistogram
from flowtact.runtime.wire import recv_message

__all__ = ["ProcessExecutor", "WorkerFailed", "describe_failure"]

PING_S = 0.25
STARTUP_S = 60.0
STOP_GRACE_S = 10.0
WARMUP_S = 1.0
"""CPU is reported over the running phase after this warm-up (JIT compilation, first allocations)."""


class WorkerFailed(RuntimeError):
    """A worker raised or died: names the process group, its nodes and the cause."""


@dataclass
class _Proc:
    name: str
    nodes: list[str]
    host: str | None
    restart: str
    max_restarts: int
    popen: subprocess.Popen[bytes] | None = None
    ident: bytes | None = None
    sock: zmq.Socket | None = None
    pid: int | None = None
    state: str = "starting"
    restarts: int = 0
    endpoints: dict[int, str] = field(default_factory=dict)
    stats: dict[str, Any] = field(default_factory=dict)
    warm: tuple[float, int] | None = None  # (cpu_s, wall_ns) at the end of the warm-up
    cpu_pct: float | None = None
    done: bool = False
    rec_done: bool = False
    counters: dict[str, dict[str, int]] = field(default_factory=dict)
    wired: bool = False
    last_k: int = 0
    violations: dict[str, int] = field(default_factory=dict)


class ProcessExecutor:
    """Runs a :class:`~flowtact.compile.Plan` across worker processes joined by ZeroMQ."""

    def __init__(
        self,
        plan: Plan,
        *,
        fast: bool = True,
        tick_s: float | None = None,
        recorder: Sink | None = None,
        progress: Callable[[float, float | None], None] | None = None,
        live: Any = None,
        warn: Callable[[str], None] | None = None,
    ) -> None:
        self.plan = plan
        self.fast = fast
        self.tick_s = tick_for(fast, tick_s)
        self.recorder = recorder
        self.progress = progress
        self.live = live
        self.warn = warn or (lambda text: print(f"flowtact: {text}", file=sys.stderr))
        self.placement: Placement = place(plan, fast=fast)
        self.rec_specs = {
            self.placement.stream_ids[(n, p)]: plan.specs[(n, p)]
            for n, p in plan.record
            if n in plan.demanded
        }

    # -- public -----------------------------------------------------------------------------
    def run(self, duration_s: float | None) -> RunSummary:
        """Run until ``duration_s`` of graph time (None: until interrupted; real time only)."""
        if duration_s is None and self.fast:
            raise ValueError("a --fast run needs a duration (--duration or the graph's duration_s)")
        self.duration_s = duration_s
        self.ctx = zmq.Context()
        self.rundir = tempfile.mkdtemp(prefix="flowtact-")
        self.procs: dict[str, _Proc] = {}
        self.auth = None
        self.by_ident: dict[bytes, _Proc] = {}
        self.samples: dict[str, int] = {}
        self.rec_ends = 0
        self.stopped = False
        self.refused_seen = 0
        self.ctl_tcp = self.rec_tcp = self.ctl_watch = None
        self.wplans = {
            g: self.placement.worker_plan(g, fast=self.fast, tick_s=self.tick_s, duration_s=duration_s)
            for g in self.placement.groups
        }
        self.t_start = time.monotonic()
        stopped_by = "duration"
        failure: str | None = None
        try:
            self._open_sockets()
            for g, nodes in self.placement.groups.items():
                pdef = self.placement.processes[g]
                self.procs[g] = _Proc(g, nodes, pdef.host, pdef.restart, pdef.max_restarts)
            for proc in self.procs.values():
                if proc.host is None:
                    self._spawn(proc)
                else:
                    self.warn(
                        f"waiting for process '{proc.name}' on {proc.host}: start it there with "
                        f"`flowtact worker {self.tcp_ctl} --process {proc.name}`"
                    )
            try:
                self._start_all()
                stopped_by = self._supervise()
            except KeyboardInterrupt:
                stopped_by = "interrupted"
                self._stop_all()
        except WorkerFailed as e:
            failure = str(e)
        finally:
            self._shutdown(failure is not None)
        summary = self._summary(stopped_by)
        if failure is not None:
            err = WorkerFailed(failure)
            err.summary = summary  # type: ignore[attr-defined]
            raise err
        return summary

    # -- set-up -----------------------------------------------------------------------------
    def _open_sockets(self) -> None:
        remote = self.plan.graph.deployment.remote
        self.ctl = self.ctx.socket(zmq.ROUTER)
        self.ctl.setsockopt(zmq.LINGER, 0)
        self.ctl.setsockopt(zmq.ROUTER_MANDATORY, 1)
        self.ctl.bind(f"ipc://{self.rundir}/ctl")
        self.rec = self.ctx.socket(zmq.PULL)
        self.rec.setsockopt(zmq.LINGER, 0)
        self.rec.bind(f"ipc://{self.rundir}/rec")
        self.poller = zmq.Poller()
        self.poller.register(self.ctl, zmq.POLLIN)
        self.poller.register(self.rec, zmq.POLLIN)
        self.tcp_ctl = self.tcp_rec = None
        if remote:
            from flowtact.runtime.security import Authenticator, HandshakeWatch, load_keys, secure_server

            net = self.plan.graph.deployment.network
            keys = net.keys
            if (
                keys is not None
                and not Path(keys).expanduser().is_absolute()
                and Path(self.plan.graph.path).is_file()
            ):
                keys = str(Path(self.plan.graph.path).parent / keys)  # relative to the graph file
            self.keys = load_keys(Path(keys).expanduser() if keys else None)
            self.keys_dir = str(Path(keys).expanduser()) if keys else os.environ["FLOWTACT_KEYS"]
            self.auth = Authenticator(self.ctx, self.keys).start()
            self.ctl_tcp = self.ctx.socket(zmq.ROUTER)
            self.ctl_tcp.setsockopt(zmq.LINGER, 0)
            secure_server(self.ctl_tcp, self.keys)
            self.ctl_watch = HandshakeWatch(self.ctl_tcp)
            self.ctl_tcp.bind(f"tcp://{net.listen}:{net.port}")
            self.tcp_ctl = self.ctl_tcp.last_endpoint.decode()
            self.rec_tcp = self.ctx.socket(zmq.PULL)
            self.rec_tcp.setsockopt(zmq.LINGER, 0)
            secure_server(self.rec_tcp, self.keys)
            port = self.rec_tcp.bind_to_random_port(f"tcp://{net.listen}")
            self.tcp_rec = f"tcp://{net.listen}:{port}"
            self.poller.register(self.ctl_tcp, zmq.POLLIN)
            self.poller.register(self.rec_tcp, zmq.POLLIN)

    def _spawn(self, proc: _Proc) -> None:
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(p for p in sys.path if p)  # `module:Class` blocks resolve alike
        env.setdefault("NUMBA_NUM_THREADS", "1")
        cmd = [
            sys.executable,
            "-m",
            "flowtact.runtime.worker",
            f"ipc://{self.rundir}/ctl",
            "--process",
            proc.name,
            "--child",
        ]
        if self.auth is not None:
            cmd += ["--keys", self.keys_dir]
        proc.popen = subprocess.Popen(cmd, env=env, start_new_session=True)
        proc.pid = proc.popen.pid
        proc.state = "starting"
        proc.ident = None
        proc.done = proc.rec_done = proc.wired = False

    def _bind_addresses(self, proc: _Proc) -> dict[int, str]:
        """Where each of the group's incoming streams is bound."""
        out = {}
        for d in self.wplans[proc.name]["inbound"]:
            sid = d["id"]
            if sid in proc.endpoints:  # a restart binds where the producers already connect
                out[sid] = proc.endpoints[sid]
            elif d["same_host"] and proc.host is None:
                out[sid] = f"ipc://{self.rundir}/s{sid}-{proc.name}"
            else:
                host = proc.host or self.plan.graph.deployment.network.listen
                out[sid] = f"tcp://{host}:0"
        return out

    def _send(self, proc: _Proc, op: str, **kw: Any) -> None:
        kw["op"] = op
        with contextlib.suppress(zmq.ZMQError):  # the worker is gone; its process watch reports it
            proc.sock.send_multipart([proc.ident, msgpack.packb(kw)])  # type: ignore[union-attr]

    def _start_all(self) -> None:
        """Handshake: hello -> plan -> ready -> wire -> wired -> start, for every worker."""
        deadline = time.monotonic() + STARTUP_S
        while not all(p.wired for p in self.procs.values()):
            if self.auth is not None:
                self._report_refusals()
            if time.monotonic() > deadline:
                missing = [p.name for p in self.procs.values() if not p.wired]
                raise WorkerFailed(f"processes {', '.join(missing)} did not start within {STARTUP_S:.0f} s")
            try:
                self._poll(50)
                self._watch()
            except _Failure as f:
                raise WorkerFailed(describe_failure(f.proc, f.report)) from None
            if all(p.endpoints or not self.wplans[p.name]["inbound"] for p in self.procs.values()) and all(
                p.state in ("ready", "wiring", "wired") for p in self.procs.values()
            ):
                for p in self.procs.values():
                    if p.state == "ready":
                        self._wire(p)
        t0 = time.monotonic_ns() + 20_000_000
        self.t0_ns = t0
        for p in self.procs.values():
            self._send(p, "start", t0_ns=t0, k0=0, resume=False)
            p.state = "running"
        self.t_run = time.monotonic()
        self.next_ping = time.monotonic()

    def _report_refusals(self) -> None:
        """Say so when a host tries to join with another key (ZAP refusal or a failed handshake)."""
        from flowtact.runtime.security import SecurityError

        seen = self.refused_seen
        for refused in self.auth.refused[seen:]:  # type: ignore[union-attr]
            self.warn(f"refused a connection: {refused}")
        self.refused_seen = len(self.auth.refused)  # type: ignore[union-attr]
        while True:
            try:
                self.ctl_watch.check()
                return
            except SecurityError as e:
                self.warn(f"refused a connection: {e}")

    def _wire(self, proc: _Proc) -> None:
        connect: dict[int, dict[str, str]] = {}
        for d in self.wplans[proc.name]["outbound"]:
            connect.setdefault(d["id"], {})[d["group"]] = self.procs[d["group"]].endpoints[d["id"]]
        remote = proc.host is not None
        record = self.tcp_rec if remote else f"ipc://{self.rundir}/rec"
        self._send(proc, "wire", connect=connect, record=record)
        proc.state = "wiring"

    # -- messages ---------------------------------------------------------------------------
    def _poll(self, timeout_ms: int) -> None:
        for sock, _ in self.poller.poll(timeout_ms):
            if sock is self.ctl or sock is self.ctl_tcp:
                while True:
                    try:
                        ident, raw = sock.recv_multipart(zmq.NOBLOCK)
                    except zmq.Again:
                        break
                    self._on_control(sock, ident, msgpack.unpackb(raw, strict_map_key=False))
            else:
                self._drain_records(sock)

    def _drain_records(self, sock: zmq.Socket) -> None:
        while True:
            try:
                m = recv_message(sock, zmq.NOBLOCK)
            except zmq.Again:
                return
            if m.is_end:  # a worker's last record message
                self.rec_ends += 1
                continue
            name = self.placement.stream_name(m.stream)
            self.samples[name] = self.samples.get(name, 0) + len(m.chunk)
            if self.recorder is not None:
                self.recorder.write(name, m.chunk)

    def _on_control(self, sock: zmq.Socket, ident: bytes, msg: dict[str, Any]) -> None:
        op = msg["op"]
        if op == "hello":
            proc = self.procs.get(msg["process"])
            if proc is None:
                return
            if proc.host is None and proc.popen is not None and msg["pid"] != proc.popen.pid:
                return  # a stale worker
            proc.ident, proc.sock, proc.pid = ident, sock, msg["pid"]
            self.by_ident[ident] = proc
            self._send(proc, "plan", plan=self.wplans[proc.name], bind=self._bind_addresses(proc))
            proc.state = "planned"
            return
        proc = self.by_ident.get(ident)
        if proc is None:
            return
        if op == "ready":
            proc.endpoints = {int(k): v for k, v in msg["endpoints"].items()}
            proc.state = "ready"
            if proc.restarts:
                self._wire(proc)
        elif op == "wired":
            proc.wired = True
            if proc.restarts:
                self._send(proc, "start", t0_ns=self.t0_ns, k0=proc.last_k, resume=True)
                proc.state = "running"
            else:
                proc.state = "wired"
        elif op == "stats":
            self._on_stats(proc, msg)
        elif op == "done":
            self._on_stats(proc, msg)
            proc.counters = msg.get("counters", {})
            proc.done = True
            proc.state = "done"
        elif op == "error":
            raise _Failure(proc, msg)

    def _on_stats(self, proc: _Proc, msg: dict[str, Any]) -> None:
        proc.stats = msg
        proc.last_k = msg["k"]
        wall = msg["wall_ns"]
        if proc.warm is None and time.monotonic() - self.t_run >= WARMUP_S:
            proc.warm = (msg["cpu_s"], wall)
        if proc.warm is not None and wall > proc.warm[1]:
            proc.cpu_pct = 100.0 * (msg["cpu_s"] - proc.warm[0]) / ((wall - proc.warm[1]) / 1e9)
        for name, p in msg["paths"].items():
            seen = proc.violations.get(name, 0)
            if p["violations"] > seen:
                budget = next(d.budget_s for d in self.plan.graph.deployment.deadlines if d.name == name)
                self.warn(
                    f"deadline {name} ({budget * 1e3:g} ms) missed {p['violations'] - seen}x "
                    f"(worst {p['worst_ns'] / 1e6:.2f} ms so far)"
                )
                proc.violations[name] = p["violations"]

    # -- running ----------------------------------------------------------------------------
    def _supervise(self) -> str:
        while not all(p.done for p in self.procs.values()):
            try:
                self._poll(20)
                self._watch()
            except _Failure as f:
                self._failed(f)
            self._tick_housekeeping()
        self._drain_until_records_end()
        return "interrupted" if self.stopped else "duration"

    def _failed(self, f: _Failure) -> None:
        """Restart the worker when its group asks for it and may; otherwise end the run."""
        proc, text = f.proc, describe_failure(f.proc, f.report)
        if (
            proc.restart != "on-failure"
            or proc.restarts >= proc.max_restarts
            or proc.host is not None
            or self.stopped
        ):
            raise WorkerFailed(text)
        proc.restarts += 1
        self.warn(f"{text}; restarting it ({proc.restarts}/{proc.max_restarts})")
        if proc.popen is not None and proc.popen.poll() is None:
            proc.popen.kill()
            proc.popen.wait()
        if proc.ident is not None:
            self.by_ident.pop(proc.ident, None)
        self._spawn(proc)
        proc.state = "restarting"

    def _tick_housekeeping(self) -> None:
        now = time.monotonic()
        if now >= self.next_ping:
            self.next_ping = now + PING_S
            for p in self.procs.values():
                if p.ident is not None and not p.done:
                    self._send(p, "ping")
            if self.live is not None:
                self.live.update(self.snapshot())
            if self.progress is not None:
                self.progress(self._graph_now(), self.duration_s)
        if self.recorder is not None:
            self.recorder.maybe_flush()

    def _graph_now(self) -> float:
        return min((p.stats.get("now", 0.0) for p in self.procs.values()), default=0.0)

    def _watch(self) -> None:
        """Notice a worker process that exited without saying done."""
        for p in self.procs.values():
            if p.popen is None or p.done:
                continue
            code = p.popen.poll()
            if code is None:
                continue
            cause = f"killed by {signal.Signals(-code).name}" if code < 0 else f"exited with status {code}"
            raise _Failure(p, {"node": None, "message": cause})

    def _stop_all(self) -> None:
        """Ctrl-C: sources stop, everything downstream drains and flushes."""
        self.stopped = True
        for p in self.procs.values():
            if p.ident is not None:
                self._send(p, "stop")
        deadline = time.monotonic() + STOP_GRACE_S
        while not all(p.done for p in self.procs.values()) and time.monotonic() < deadline:
            try:
                self._poll(20)
                self._watch()
            except _Failure as f:
                raise WorkerFailed(describe_failure(f.proc, f.report)) from None
            except KeyboardInterrupt:
                break
        self._drain_until_records_end()

    def _drain_until_records_end(self) -> None:
        """Write what is still in flight: every recording worker ends its records with a marker."""
        expected = sum(1 for g in self.procs if self.wplans[g]["record"])
        deadline = time.monotonic() + 5.0
        while self.rec_ends < expected and time.monotonic() < deadline:
            self.poller.poll(50)
            for sock in (self.rec, self.rec_tcp):
                if sock is not None:
                    self._drain_records(sock)

    def _shutdown(self, failed: bool) -> None:
        for p in self.procs.values():
            if p.ident is not None:
                self._send(p, "abort" if failed else "exit")
        deadline = time.monotonic() + 2.0
        for p in self.procs.values():
            if p.popen is None:
                continue
            try:
                p.popen.wait(max(0.05, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                p.popen.kill()
                p.popen.wait()
        if failed:
            for sock in (self.rec, self.rec_tcp):
                if sock is not None:
                    self._drain_records(sock)
        if self.auth is not None:
            self.ctl_watch.close()
            self.auth.stop()
        self.ctx.destroy(linger=0)
        shutil.rmtree(self.rundir, ignore_errors=True)

    # -- reporting --------------------------------------------------------------------------
    def snapshot(self) -> dict[str, Any]:
        """The live view's data: processes, streams, deadline paths."""
        streams, paths = self._stream_stats(), self._path_stats()
        return {
            "graph": self.plan.graph.name,
            "mode": "fast" if self.fast else "realtime",
            "now": self._graph_now(),
            "duration": self.duration_s,
            "wall": time.monotonic() - self.t_start,
            "processes": self._process_table(),
            "streams": {
                name: {
                    "rate_hz": s["messages"] / max(self._graph_now(), 1e-9),
                    "samples_hz": s["samples"] / max(self._graph_now(), 1e-9),
                    "p50_us": s["latency_us"]["p50"],
                    "p99_us": s["latency_us"]["p99"],
                    "dropped": s["dropped"],
                    "policy": s["policy"],
                }
                for name, s in streams.items()
            },
            "paths": {
                name: {
                    "p50_us": p["p50_us"],
                    "p99_us": p["p99_us"],
                    "budget_us": p["budget_us"],
                    "violations": p["violations"],
                }
                for name, p in paths.items()
            },
        }

    def _process_table(self) -> dict[str, dict[str, Any]]:
        return {
            p.name: {
                "pid": p.pid,
                "host": p.host or "local",
                "nodes": p.nodes,
                "cpu_pct": p.cpu_pct,
                "restarts": p.restarts,
                "state": p.state,
            }
            for p in self.procs.values()
        }

    def _stream_stats(self) -> dict[str, dict[str, Any]]:
        out: dict[str, dict[str, Any]] = {}
        sent_dropped: dict[int, int] = {}  # drops at the sending end ('latest' queue full)
        for q in self.procs.values():
            for sid, n in q.stats.get("sent_dropped", {}).items():
                sent_dropped[int(sid)] = sent_dropped.get(int(sid), 0) + n
        for p in self.procs.values():
            for sid, s in p.stats.get("inbound", {}).items():
                sid = int(sid)
                name = self.placement.stream_name(sid)
                key = name if len(self.placement.consumers(sid)) == 1 else f"{name}@{p.name}"
                policy, _queue = self.placement.crossings[(sid, p.name)]
                out[key] = {
                    "to": p.name,
                    "policy": policy,
                    "messages": s["messages"],
                    "samples": s["samples"],
                    "dropped": s["dropped"] + sent_dropped.get(sid, 0),
                    "gaps": s["gaps"],
                    "latency_us": LatencyHistogram.from_wire(s["lat"]).summary(),
                }
        return out

    def _path_stats(self) -> dict[str, dict[str, Any]]:
        out = {}
        for d in self.plan.graph.deployment.deadlines:
            h = LatencyHistogram()
            violations = 0
            for p in self.procs.values():
                ps = p.stats.get("paths", {}).get(d.name)
                if ps:
                    h.merge(LatencyHistogram.from_wire(ps["lat"]))
                    violations += ps["violations"]
            s = h.summary()
            out[d.name] = {
                "p50_us": s["p50"],
                "p99_us": s["p99"],
                "max_us": s["max"],
                "n": s["n"],
                "budget_us": d.budget_s * 1e6,
                "violations": violations,
            }
        return out

    def _summary(self, stopped_by: str) -> RunSummary:
        plan = self.plan
        events: dict[str, int] = {}
        samples: dict[str, int] = {}
        for n, p in plan.record:
            name = f"{n}.{p}"
            if n in plan.demanded:
                (events if plan.specs[(n, p)].events else samples)[name] = self.samples.get(name, 0)
        for proc in self.procs.values():
            for name, count in proc.stats.get("counts", {}).items():
                n, p = name.split(".", 1)
                if plan.specs[(n, p)].events and name not in events:
                    events[name] = count
        now = max((p.stats.get("now", 0.0) for p in self.procs.values()), default=0.0)
        return RunSummary(
            graph=plan.graph.name,
            duration_s=now,
            wall_s=time.monotonic() - self.t_start,
            stopped_by=stopped_by,
            samples=samples,
            events=events,
            event_units={k: plan.specs[tuple(k.split(".", 1))].n_units or 1 for k in events},  # type: ignore[index]
            counters={n: c for p in self.procs.values() for n, c in p.counters.items()},
            pruned=list(plan.pruned),
            ticks=max((p.last_k for p in self.procs.values()), default=0),
            processes=self._process_table(),
            streams=self._stream_stats(),
            paths=self._path_stats(),
        )


class _Failure(Exception):
    """Internal: a worker reported an error or died."""

    def __init__(self, proc: _Proc, report: dict[str, Any]) -> None:
        self.proc, self.report = proc, report
        super().__init__(report.get("message", ""))


def describe_failure(proc: _Proc, report: dict[str, Any]) -> str:
    """``node 'sa1' (nlif) in process 'neurons' failed at t=1.234 s: ...`` or a dead process."""
    node = report.get("node")
    if node:
        return (
            f"node '{node}' ({report.get('block')}) failed at t={report.get('now') or 0.0:.3f} s "
            f"in process '{proc.name}': {report['message']}"
        )
    return f"process '{proc.name}' (nodes {', '.join(proc.nodes)}) {report['message']}"
