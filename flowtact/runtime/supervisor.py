"""The supervisor: runs a plan across worker processes, records it, and reports on it.

It places the nodes (:mod:`flowtact.runtime.placement`), starts one worker per local process
group (a group with a ``host:`` is started there by ``flowtact worker``), hands each its part of
the plan, wires the streams (ipc:// on this host, tcp:// with CurveZMQ to other hosts), starts
them on a common clock, and then, until every worker is done: writes recorded streams to the
recorder, collects heartbeats and statistics, pings the workers, and watches their processes.

Every phase runs the same pump (:meth:`ProcessExecutor._pump`), so pings, records, exits and
liveness are handled alike while starting, running and stopping. Failures are told truly:

* a worker has its group's ``startup_s`` (or ``--startup-s``) *without progress* to join: its
  window restarts on every start-up report it makes (a phase entered, a module imported, a
  compiler pass run; before its first message, CPU time spent starting the interpreter), so a
  first run that compiles for minutes joins, and one that hangs is named with its last phase;
  a worker that waits for the others (ready, wired) has no window;
* a worker that raises or dies is named with its nodes and cause;
* a worker that shows no progress for its group's ``stall_s`` (no heartbeat, or one node's step
  that does not return) is named with the node and tick, and killed;
* either ends the run (recording flushed up to the failure) or, under ``restart: on-failure``,
  restarts the group, which rejoins the running graph (or, before graph time 0, the start-up);
* Ctrl-C or SIGTERM picks one tick on which every worker stops (a loop through several processes
  drains like the end of a timed run); a group still draining after ``stop_grace_s`` is aborted,
  named, and the run exits non-zero; a second Ctrl-C aborts at once;
* a real-time run that falls behind its clock is warned about once, naming the busiest nodes.
"""

from __future__ import annotations

import contextlib
import math
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgpack
import zmq

from flowtact.errors import WorkerFailed
from flowtact.running.compile import CompiledGraph
from flowtact.running.python_child import python_command
from flowtact.runtime.clock import LAG_WARN_S, tick_for
from flowtact.runtime.compile_notice import CompileNotices
from flowtact.runtime.inproc import RunSummary, Sink, explain_counters
from flowtact.runtime.placement import Placement, place
from flowtact.runtime.rundir import make_run_folder
from flowtact.runtime.stats import LatencyHistogram, format_factor
from flowtact.runtime.warm_up import warm_shared_kernels
from flowtact.runtime.wire import recv_message

__all__ = ["ProcessExecutor", "describe_failure"]

PING_S = 0.25
WATCH_S = 0.02
"""Exits and stalls of workers are looked for this often (the pump also wakes for every message)."""
_EVENTS, _POLLIN = int(zmq.EVENTS), int(zmq.POLLIN)
WARMUP_S = 1.0
"""CPU is reported over the running phase after this warm-up (JIT compilation, first allocations)."""
STOP_MARGIN_S = 0.25
"""A stop ends on the tick this far (in wall time) ahead of the furthest worker: it reaches them first."""
DEADLINE_WARN_EVERY_S = 5.0
"""Deadline misses are told at the first one, then at most this often (with their count)."""
WAITING_EVERY_S = 15.0
"""How often the run repeats that it is waiting for a worker on another host."""
LAST_WORDS_S = 0.2
"""After a worker exits, how long its last control messages (an error report) may take to arrive."""
SILENT_PROBE_S = 0.3
"""How long a worker without progress has its CPU time watched, to tell a hung process from a busy one."""
IDLE_CPU = 0.05
"""A worker without progress that uses less than this share of a core is not working: it has stalled."""


@dataclass
class _Proc:
    name: str
    nodes: list[str]
    host: str | None
    restart: str
    max_restarts: int
    stall_s: float
    startup_s: float
    stop_grace_s: float
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
    summaries: dict[str, str] = field(default_factory=dict)
    """What its blocks said of the run (``Block.summary``), per node, sent with ``done``."""
    wired: bool = False
    last_k: int = 0
    violations: dict[str, int] = field(default_factory=dict)
    since: float = 0.0  # when it was (re)started or started running: the clock of its windows
    beat_at: float = 0.0  # when its last heartbeat arrived
    beat: dict[str, Any] = field(default_factory=dict)
    busy_since: float = 0.0  # since when its current step (same node, same step count) runs
    next_waiting: float = math.inf  # when to repeat that the run waits for it (another host)
    tick_rate: float = 0.0  # ticks per second lately (from heartbeats)
    silent_mark: tuple[float, float] | None = None  # (when, CPU seconds) as its heartbeats fell silent
    progress_at: float = 0.0  # when it last showed start-up progress
    progress: Any = None  # its last start-up progress report (or CPU seconds before its first message)
    phase: str = "starting its interpreter"  # its last reported start-up phase

    def describe(self) -> str:
        where = f" on {self.host}" if self.host else ""
        return f"process '{self.name}'{where} (nodes {', '.join(self.nodes)})"


class ProcessExecutor:
    """Runs a :class:`~flowtact.running.compile.CompiledGraph` across worker processes joined by ZeroMQ."""

    def __init__(
        self,
        plan: CompiledGraph,
        *,
        fast: bool = True,
        tick_s: float | None = None,
        recorder: Sink | None = None,
        progress: Callable[[float, float | None], None] | None = None,
        live: Any = None,
        warn: Callable[[str], None] | None = None,
        startup_s: float | None = None,
    ) -> None:
        self.plan = plan
        self.startup_s = startup_s
        """``--startup-s``: every group's start-up window (None: each group's own ``startup_s``)."""
        self.fast = fast
        self.tick_s = tick_for(fast, tick_s)
        self.recorder = recorder
        self.progress = progress
        self.live = live
        self.warn = warn or (lambda text: print(f"flowtact: {text}", file=sys.stderr))
        self.compiles = CompileNotices(self.warn)
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
        self.run_folder = make_run_folder("run")  # ipc sockets; also sweeps folders of killed runs
        self.rundir = self.run_folder.path
        self.procs: dict[str, _Proc] = {}
        self.auth = None
        self.by_ident: dict[bytes, _Proc] = {}
        self.samples: dict[str, int] = {}
        self.rec_ends = 0
        self.stopped = False
        self.stop_at = 0.0
        self.stop_k = 0
        self.deadline_quiet: dict[str, float] = {}  # deadline path -> no warning before then
        self.interrupts = 0
        self.refused_seen = 0
        self.max_lag_s = 0.0
        self.self_warm: tuple[float, float] | None = None
        """The supervisor's own CPU seconds and monotonic time when the first worker was warm."""
        self.late: list[str] = []  # the busiest nodes when the run fell behind real time
        self.ctl_tcp = self.rec_tcp = self.ctl_watch = None
        self.shared_warm: threading.Thread | None = None
        self.t_run = self.next_ping = time.monotonic()
        self.next_watch = 0.0
        self.t0_ns = 0
        self.go_ns = 0
        """Graph time 0 on the monotonic clock (ns): ``t0_ns`` in real time, the start message in --fast."""
        self.last_done_ns = 0
        """When the last worker said it was done (monotonic ns): with t0_ns, the running span."""
        self.wplans = {
            g: self.placement.worker_plan(g, fast=self.fast, tick_s=self.tick_s, duration_s=duration_s)
            for g in self.placement.groups
        }
        self.t_start = time.monotonic()
        stopped_by = "duration"
        failure: str | None = None
        remote_tb: str | None = None
        restore = self._catch_signals()
        try:
            self._open_sockets()
            for g, nodes in self.placement.groups.items():
                pdef = self.placement.processes[g]
                self.procs[g] = _Proc(
                    g,
                    nodes,
                    pdef.host,
                    pdef.restart,
                    pdef.max_restarts,
                    stall_s=pdef.stall_window(self.fast),
                    startup_s=self.startup_s or pdef.startup_window(),
                    stop_grace_s=pdef.stop_grace_s,
                    since=self.t_start,
                )
            self._warm_shared()
            for proc in self.procs.values():
                if proc.host is None:
                    self._spawn(proc)
                else:
                    self._say_waiting(proc)
            stopped_by = self._supervise() if self._start_all() else "interrupted"
        except WorkerFailed as e:
            failure, remote_tb = str(e), e.traceback
        finally:
            restore()
            self._shutdown(failure is not None)
        summary = self._summary(stopped_by)
        if failure is not None:
            err = WorkerFailed(failure, remote_tb)
            err.summary = summary  # type: ignore[attr-defined]
            raise err
        return summary

    def _warm_shared(self) -> None:
        """Compile once, here, the kernels every local worker calls (the bad-data screen's), so
        that the workers load them from numba's cache rather than each compile them at once.

        In a thread, while the workers start their interpreters and import (seconds): done before
        spawning, it delayed every worker by its compile time (4 s at load 9 for touch.yaml)."""
        self.shared_warm = None
        if sum(1 for p in self.procs.values() if p.host is None) < 2:
            return
        specs = [spec for (node, _port), spec in self.plan.specs.items() if node in self.plan.demanded]
        self.shared_warm = threading.Thread(
            target=warm_shared_kernels, args=(specs, self.warn), name="flowtact-shared-kernels", daemon=True
        )
        self.shared_warm.start()

    def _catch_signals(self) -> Callable[[], None]:
        """Ctrl-C and SIGTERM become a flag the pump reads: no exception lands mid-write."""
        if threading.current_thread() is not threading.main_thread():
            return lambda: None

        def on_signal(_signum: int, _frame: Any) -> None:
            self.interrupts += 1

        old = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}

        def restore() -> None:
            for sig, handler in old.items():
                signal.signal(sig, handler)

        return restore

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
        cmd = python_command(
            "-m", "flowtact.runtime.worker", f"ipc://{self.rundir}/ctl", "--process", proc.name, "--child"
        )
        if self.auth is not None:
            cmd += ["--keys", self.keys_dir]
        proc.popen = subprocess.Popen(cmd, env=env, start_new_session=True)
        proc.pid = proc.popen.pid
        proc.state = "starting"
        proc.ident = None
        proc.beat = {}
        proc.since = proc.progress_at = time.monotonic()
        proc.progress, proc.phase = None, "starting its interpreter"
        proc.done = proc.rec_done = proc.wired = False

    def _say_waiting(self, proc: _Proc) -> None:
        waited = time.monotonic() - proc.since
        if waited < 1.0:
            allow = "".join(f" --allow-module {m}" for m in self.plan.graph.allow_modules)  # that host's say
            self.warn(
                f"waiting for process '{proc.name}' on {proc.host} (up to {proc.startup_s:g} s, its "
                f"startup_s): start it there with `flowtact worker {self.tcp_ctl} --process {proc.name}{allow}`"
            )
        else:
            self.warn(
                f"still waiting for process '{proc.name}' on {proc.host} ({waited:.0f} of {proc.startup_s:g} s)"
            )
        proc.next_waiting = time.monotonic() + WAITING_EVERY_S

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

    def _start_all(self) -> bool:
        """Handshake: hello -> plan -> ready -> wire -> wired -> start; False if interrupted first."""
        while not all(p.wired for p in self.procs.values()):
            if self.interrupts:
                return False
            if self.auth is not None:
                self._report_refusals()
            now = time.monotonic()
            for p in self.procs.values():
                if p.wired:
                    continue
                self._check_startup(p, now)
                if p.host and p.ident is None and now >= p.next_waiting:
                    self._say_waiting(p)
            try:
                self._pump(50)
            except _Failure as f:
                self._failed(f)  # under restart: on-failure the group starts again
            if all(p.endpoints or not self.wplans[p.name]["inbound"] for p in self.procs.values()) and all(
                p.state in ("ready", "wiring", "wired") for p in self.procs.values()
            ):
                for p in self.procs.values():
                    if p.state == "ready":
                        self._wire(p)
        t0 = time.monotonic_ns() + 20_000_000
        self.t0_ns = t0
        self.go_ns = t0 if not self.fast else t0 - 20_000_000  # --fast workers start at once
        self.t_run = time.monotonic()
        for p in self.procs.values():
            self._send(p, "start", t0_ns=t0, k0=0, resume=False)
            self._running(p)
        return True

    def _check_startup(self, p: _Proc, now: float) -> None:
        """A worker that shows no start-up progress for its window did not join: name its last phase
        and how to widen the window. One that waits for the others (ready, wired) has no window."""
        if p.state in ("ready", "wired"):
            p.progress_at = now
            return
        if p.ident is None and p.host is None and p.pid is not None:  # before its first message
            seen = _proc_stat(p.pid)
            if seen is not None and seen[1] != p.progress:  # the interpreter starts, imports
                p.progress, p.progress_at = seen[1], now
        quiet = now - max(p.since, p.progress_at)
        if quiet <= p.startup_s:
            return
        if p.host and p.ident is None:
            raise WorkerFailed(
                f"{p.describe()} did not join within {p.startup_s:g} s: start it with `flowtact worker` "
                f"there, or give it longer with --startup-s S or startup_s under processes: {p.name}: in the graph"
            )
        if p.popen is not None and p.popen.poll() is None:
            p.popen.kill()  # hung: it cannot take part in an orderly end
        raise WorkerFailed(
            f"{p.describe()} did not join: no start-up progress for {quiet:.0f} s (its start-up window, "
            f"{p.startup_s:g} s) while {p.phase}; if it needs longer, widen the window with "
            f"--startup-s S or startup_s under processes: {p.name}: in the graph"
        )

    def _running(self, proc: _Proc) -> None:
        proc.state = "running"
        proc.since = proc.beat_at = proc.busy_since = time.monotonic()

    def _report_refusals(self) -> None:
        """Say so when a host tries to join with another key (ZAP refusal or a failed handshake)."""
        from flowtact.errors import SecurityError

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

    # -- the pump: every phase runs it ------------------------------------------------------
    def _pump(self, timeout_ms: int) -> None:
        """Receive control messages and records, notice exits and stalls, ping, show progress."""
        self._poll(timeout_ms)
        now = time.monotonic()
        if now >= self.next_watch:  # the pump also wakes for every message: look every WATCH_S
            self.next_watch = now + WATCH_S
            self._watch()
            self._check_liveness()
        if now >= self.next_ping:
            self.next_ping = now + PING_S
            for p in self.procs.values():
                if p.ident is not None:
                    self._send(p, "ping")
            if self.t0_ns:
                self._check_overload()
                if self.live is not None:
                    self.live.update(self.snapshot())
                if self.progress is not None:
                    self.progress(self._graph_now(), self.duration_s)
        if self.recorder is not None:
            self.recorder.maybe_flush()

    def _poll(self, timeout_ms: int) -> None:
        for sock, _ in self.poller.poll(timeout_ms):
            if sock is self.ctl or sock is self.ctl_tcp:
                while sock.getsockopt(_EVENTS) & _POLLIN:  # not zmq.Again: an exception per wake-up
                    ident, raw = sock.recv_multipart(zmq.NOBLOCK)
                    self._on_control(sock, ident, msgpack.unpackb(raw, strict_map_key=False))
            else:
                self._drain_records(sock)

    def _drain_records(self, sock: zmq.Socket, budget: int = 10_000) -> None:
        """Write what arrived (at most ``budget`` messages: control keeps its turn)."""
        for _ in range(budget):
            if not sock.getsockopt(_EVENTS) & _POLLIN:
                return
            m = recv_message(sock, zmq.NOBLOCK)
            if m.is_end:  # a worker's last record message
                self.rec_ends += 1
                continue
            name = self.placement.stream_name(m.stream)
            self.samples[name] = self.samples.get(name, 0) + len(m.chunk)
            if self.recorder is not None:
                self.recorder.write(name, m.chunk)

    def _on_control(self, sock: zmq.Socket, ident: bytes, msg: dict[str, Any]) -> None:
        op = msg["op"]
        if op == "beat":  # from the worker's heartbeat thread (a socket of its own)
            proc = self.procs.get(msg["process"])
            if proc is not None and msg["pid"] == proc.pid:
                self._on_beat(proc, msg)
            return
        if op == "hello":
            proc = self.procs.get(msg["process"])
            if proc is None:
                return
            if proc.host is None and proc.popen is not None and msg["pid"] != proc.popen.pid:
                return  # a stale worker
            proc.ident, proc.sock, proc.pid = ident, sock, msg["pid"]
            proc.progress_at, proc.phase = time.monotonic(), "waiting for its plan"
            self.by_ident[ident] = proc
            self._send(proc, "plan", plan=self.wplans[proc.name], bind=self._bind_addresses(proc))
            proc.state = "planned"
            return
        proc = self.by_ident.get(ident)
        if proc is None:
            return
        proc.progress_at = time.monotonic()  # every message before the start is start-up progress
        if op == "ready":
            self.compiles.on_ready(proc.describe(), msg)
            proc.endpoints = {int(k): v for k, v in msg["endpoints"].items()}
            proc.state = "ready"
            if proc.restarts and self.t0_ns:  # a restart after the start rejoins the running graph
                self._wire(proc)
        elif op == "wired":
            proc.wired = True
            if proc.restarts and self.t0_ns:
                self._send(proc, "start", t0_ns=self.t0_ns, k0=proc.last_k, resume=True)
                self._running(proc)
                if self.stopped:
                    self._send(proc, "stop", k=self.stop_k)
            else:
                proc.state = "wired"
        elif op == "stats":
            self._on_stats(proc, msg)
        elif op == "done":
            self._on_stats(proc, msg)
            proc.counters = msg.get("counters", {})
            proc.summaries = msg.get("summaries", {})
            proc.done = True
            self.last_done_ns = time.monotonic_ns()
            proc.state = "done"
        elif op == "error":
            raise _Failure(proc, msg)

    def _on_beat(self, proc: _Proc, beat: dict[str, Any]) -> None:
        now = time.monotonic()
        old = proc.beat
        if beat["node"] is None or beat["node"] != old.get("node") or beat["steps"] != old.get("steps"):
            proc.busy_since = now  # waiting, or a new step: progress
            proc.silent_mark = None
        if old:  # ticks per second, for where a stop can reach it
            proc.tick_rate = max(_tick_rate(old, beat), 0.5 * proc.tick_rate)  # slow to forget a fast spell
        proc.beat, proc.beat_at = beat, now
        if proc.state != "running":
            proc.phase = beat.get("phase") or proc.phase
            if beat.get("progress") != proc.progress:  # start-up advances: its window restarts
                proc.progress, proc.progress_at = beat.get("progress"), now
        self.compiles.on_beat(proc.name, proc.describe(), proc.state == "running", beat)
        proc.last_k = max(proc.last_k, beat["k"])

    def _on_stats(self, proc: _Proc, msg: dict[str, Any]) -> None:
        proc.stats = msg
        proc.last_k = max(proc.last_k, msg["k"])
        wall = msg["wall_ns"]
        if proc.warm is None and time.monotonic() - self.t_run >= WARMUP_S:
            proc.warm = (msg["cpu_s"], wall)
            if self.self_warm is None:
                self.self_warm = (time.process_time(), time.monotonic())
        if proc.warm is not None and wall > proc.warm[1]:
            proc.cpu_pct = 100.0 * (msg["cpu_s"] - proc.warm[0]) / ((wall - proc.warm[1]) / 1e9)
        self.max_lag_s = max(self.max_lag_s, msg.get("max_lag_s", 0.0))
        if self.fast:  # deadlines are wall-clock budgets: a virtual clock cannot miss them
            return
        now = time.monotonic()
        for name, p in msg["paths"].items():
            seen = proc.violations.get(name, 0)
            if p["violations"] > seen and now >= self.deadline_quiet.get(name, 0.0):
                budget = next(d.budget_s for d in self.plan.graph.deployment.deadlines if d.name == name)
                self.warn(
                    f"deadline {name} ({budget * 1e3:g} ms) missed {p['violations'] - seen}x "
                    f"(worst {p['worst_ns'] / 1e6:.2f} ms so far)"
                )
                proc.violations[name] = p["violations"]
                self.deadline_quiet[name] = now + DEADLINE_WARN_EVERY_S

    # -- liveness -----------------------------------------------------------------------------
    def _watch(self) -> None:
        """Notice a worker process that exited without saying done (after its last words)."""
        for p in self.procs.values():
            if p.popen is None or p.done:
                continue
            code = p.popen.poll()
            if code is None:
                continue
            deadline = time.monotonic() + LAST_WORDS_S  # an error report may still be in flight
            while not p.done and time.monotonic() < deadline:
                self._poll(20)
            if p.done:
                continue
            cause = f"killed by {signal.Signals(-code).name}" if code < 0 else f"exited with status {code}"
            raise _Failure(p, {"node": None, "message": cause})

    def _check_liveness(self) -> None:
        """A running worker that shows no progress for ``stall_s`` has stalled.

        No progress: its heartbeats stopped, or the node it steps has not returned. A worker on
        this host is then asked of the kernel: stopped (``kill -STOP``) or idle (blocked in a call)
        is a stall; burning CPU (a long computation, or kernels loading while they hold the
        interpreter so the heartbeat thread cannot run) is given the start-up window first. A worker
        on another host is judged by its heartbeats alone.
        """
        now = time.monotonic()
        for p in self.procs.values():
            if p.state != "running" or p.done:
                continue
            window = p.startup_s if p.beat.get("first", True) else p.stall_s
            node = p.beat.get("node")
            quiet = now - p.beat_at
            stuck = now - p.busy_since if node else 0.0
            if max(quiet, stuck) <= window:
                continue
            why = self._why_stalled(p, now, max(quiet, stuck))
            if why is None:
                continue
            what = (
                f"no heartbeat for {quiet:.1f} s" + (f" inside node '{node}'" if node else "")
                if quiet > window
                else f"node '{node}' has not returned from its step for {stuck:.1f} s"
            )
            raise _Failure(
                p,
                {
                    "node": None,
                    "message": f"stalled at tick {p.last_k} (t={p.last_k * self.tick_s:.3f} s): {what}, {why} "
                    f"(stall_s {window:g} s)",
                    "stalled": True,
                },
            )

    def _why_stalled(self, p: _Proc, now: float, idle_for: float) -> str | None:
        """Why a worker without progress counts as stalled now, or None while it may be working."""
        seen = _proc_stat(p.pid) if p.host is None and p.pid is not None else None
        if seen is None:  # another host, or no /proc
            return "stopped, hung or starved"
        state, cpu_s = seen
        if state == "T":
            return "its process is stopped (SIGSTOP)"
        if p.silent_mark is None:
            p.silent_mark = (now, cpu_s)
            return None
        t_mark, cpu_mark = p.silent_mark
        if now - t_mark < SILENT_PROBE_S:
            return None
        if (cpu_s - cpu_mark) / (now - t_mark) < IDLE_CPU:
            return "and its process is idle (blocked in a call, or waiting on something that never comes)"
        if idle_for > p.startup_s:
            return f"while computing (longer than startup_s, {p.startup_s:g} s)"
        return None

    def _check_overload(self) -> None:
        """Warn once when a real-time run falls behind its clock, naming the busiest nodes."""
        if self.fast or self.late:
            return
        lagging = [p for p in self.procs.values() if p.stats.get("max_lag_s", 0.0) > LAG_WARN_S]
        if not lagging:
            return
        worst = max(lagging, key=lambda p: p.stats["max_lag_s"])
        wall = max((worst.stats["wall_ns"] - self.t0_ns) / 1e9, 1e-9)
        share = {
            n: ns / 1e9 / wall for p in self.procs.values() for n, ns in p.stats.get("node_ns", {}).items()
        }
        self.late = sorted(share, key=share.get, reverse=True)[:3]  # type: ignore[arg-type]
        busiest = ", ".join(f"{n} {100 * share[n]:.0f} %" for n in self.late)
        self.warn(
            f"falling behind real time: {worst.describe()} ran {worst.stats['max_lag_s']:.2f} s late by "
            f"t={worst.stats['now']:.2f} s (real-time factor {format_factor(worst.stats['now'] / wall)}); "
            f"busiest nodes (share of wall time in their steps): {busiest}"
        )

    # -- running ----------------------------------------------------------------------------
    def _supervise(self) -> str:
        while not all(p.done for p in self.procs.values()):
            if self.interrupts and not self.stopped:
                self._stop_all()
            elif self.interrupts > 1:
                raise WorkerFailed(f"interrupted again while stopping: aborted {self._draining()}")
            if self.stopped:
                self._check_grace()
            try:
                self._pump(20)
            except _Failure as f:
                self._failed(f)
        self._drain_until_records_end()
        return "interrupted" if self.stopped else "duration"

    def _stop_all(self) -> None:
        """Ctrl-C: every worker ends on one tick ahead, then drains and flushes."""
        self.stopped = True
        now = self.stop_at = time.monotonic()
        # No worker may have started a tick past the stop tick when the stop reaches it: in a loop
        # through several processes one would wait inside that tick for a peer that stopped.
        # Real time: no worker runs ahead of the wall clock. --fast: extrapolate from heartbeats.
        reach = max(
            (p.last_k + p.tick_rate * (now - p.beat_at + STOP_MARGIN_S) for p in self.procs.values()),
            default=0.0,
        )
        if not self.fast:
            wall = (time.monotonic_ns() - self.t0_ns) / 1e9 + STOP_MARGIN_S
            reach = max(reach, wall / self.tick_s)
        k = math.ceil(reach) + 1
        self.stop_k = k
        for p in self.procs.values():
            if p.ident is not None:
                self._send(p, "stop", k=k)

    def _draining(self) -> str:
        left = [p for p in self.procs.values() if not p.done]
        return "; ".join(f"{p.describe()} still at tick {p.last_k} of {self.stop_k}" for p in left)

    def _check_grace(self) -> None:
        """A group still draining after its ``stop_grace_s`` is aborted and named."""
        waited = time.monotonic() - self.stop_at
        late = [p for p in self.procs.values() if not p.done and waited > p.stop_grace_s]
        if late:
            grace = max(p.stop_grace_s for p in late)
            raise WorkerFailed(
                f"the stop did not finish within stop_grace_s ({grace:g} s): aborted {self._draining()}; "
                "the recording holds what arrived until then"
            )

    def _failed(self, f: _Failure) -> None:
        """Restart the worker when its group asks for it and may; otherwise end the run."""
        proc, text = f.proc, describe_failure(f.proc, f.report)
        if f.report.get("stalled") and proc.popen is not None and proc.popen.poll() is None:
            proc.popen.kill()  # stopped or hung: it cannot take part in an orderly end
            proc.popen.wait()
        if (
            proc.restart != "on-failure"
            or proc.restarts >= proc.max_restarts
            or proc.host is not None
            or self.stopped
        ):
            raise WorkerFailed(text, f.report.get("traceback"))
        proc.restarts += 1
        self.warn(f"{text}; restarting it ({proc.restarts}/{proc.max_restarts})")
        if proc.popen is not None and proc.popen.poll() is None:
            proc.popen.kill()
            proc.popen.wait()
        if proc.ident is not None:
            self.by_ident.pop(proc.ident, None)
        self._spawn(proc)
        proc.state = "restarting"

    def _graph_now(self) -> float:
        return min((p.stats.get("now", 0.0) for p in self.procs.values()), default=0.0)

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
        if self.shared_warm is not None:
            self.shared_warm.join()  # a compile under way ends before the interpreter does
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
        self.run_folder.close()

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
            "running": max(time.monotonic_ns() - self.go_ns, 0) / 1e9 if self.t0_ns else None,
            "startup": self.go_ns / 1e9 - self.t_start if self.t0_ns else None,
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
                if not self.fast  # wall-clock budgets: nothing to show on a virtual clock
            },
        }

    def _own_cpu_pct(self) -> float | None:
        """The supervisor's CPU (its every thread: control, recording, live view) in % of one core,
        over the workers' window (after the warm-up), so the two add up; None before any warm-up."""
        if self.self_warm is None:
            return None
        cpu0, t0 = self.self_warm
        wall = time.monotonic() - t0
        return 100.0 * (time.process_time() - cpu0) / wall if wall > 0 else None

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
        counters = {n: c for p in self.procs.values() for n, c in p.counters.items()}
        return RunSummary(
            graph=plan.graph.name,
            duration_s=now,
            wall_s=time.monotonic() - self.t_start,
            running_s=(self.last_done_ns - self.go_ns) / 1e9 if self.t0_ns and self.last_done_ns else None,
            startup_s=self.go_ns / 1e9 - self.t_start if self.t0_ns else None,
            stopped_by=stopped_by,
            samples=samples,
            events=events,
            event_units={k: plan.specs[tuple(k.split(".", 1))].n_units or 1 for k in events},  # type: ignore[index]
            counters=counters,
            pruned=list(plan.pruned),
            ticks=max((p.last_k for p in self.procs.values()), default=0),
            processes=self._process_table(),
            supervisor_cpu_pct=self._own_cpu_pct(),
            streams=self._stream_stats(),
            paths=self._path_stats(),
            counter_docs=explain_counters(plan, counters),
            realtime=None if self.fast else self.max_lag_s < LAG_WARN_S,
            max_lag_s=self.max_lag_s,
            late_nodes=list(self.late),
            block_summaries={
                n: t for n in plan.order for p in self.procs.values() if (t := p.summaries.get(n))
            },
        )


def _proc_stat(pid: int) -> tuple[str, float] | None:
    """Linux: a process' state letter and CPU seconds (user + system), or None where unknown."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None
    return fields[0], (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


class _Failure(Exception):
    """Internal: a worker reported an error or died."""

    def __init__(self, proc: _Proc, report: dict[str, Any]) -> None:
        self.proc, self.report = proc, report
        super().__init__(report.get("message", ""))


def _tick_rate(old: dict[str, Any], beat: dict[str, Any]) -> float:
    """Ticks per second between two heartbeats, timed by the worker that sent them: on a loaded
    machine beats queue and arrive together, and their arrival times would make a rate of
    millions of ticks per second (and a stop tick minutes ahead of every worker)."""
    dt = (beat.get("sent_ns", 0) - old.get("sent_ns", 0)) / 1e9
    return max(beat["k"] - old["k"], 0) / dt if dt > 0 else 0.0


def describe_failure(proc: _Proc, report: dict[str, Any]) -> str:
    """``node 'sa1' (nlif) in process 'neurons' failed at t=1.234 s: ...`` or a dead process."""
    node = report.get("node")
    if node:
        return (
            f"node '{node}' ({report.get('block')}) failed at t={report.get('now') or 0.0:.3f} s "
            f"in process '{proc.name}': {report['message']}"
        )
    return f"process '{proc.name}' (nodes {', '.join(proc.nodes)}) {report['message']}"
