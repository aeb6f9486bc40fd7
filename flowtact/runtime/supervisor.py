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
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

import zmq

from flowtact.errors import ProcessFailure, ProtocolError, WorkerFailed
from flowtact.running.compile import CompiledGraph
from flowtact.runtime.clock import tick_for
from flowtact.runtime.compile_notice import CompileNotices
from flowtact.runtime.executors import RunOptions
from flowtact.runtime.inproc import Sink
from flowtact.runtime.links.zeromq.wire import recv_message
from flowtact.runtime.placement import Placement, place
from flowtact.runtime.protocol import (
    Abort,
    Beat,
    Done,
    ErrorReport,
    Exit,
    Hello,
    Message,
    Ping,
    Ready,
    Start,
    Stats,
    Stop,
    Wired,
    decode,
    encode,
)
from flowtact.runtime.rundir import make_run_folder
from flowtact.runtime.summary import RunSummary
from flowtact.runtime.supervisor_liveness import SupervisorLiveness
from flowtact.runtime.supervisor_procs import (
    PING_S,
    WATCH_S,
    Proc,
    describe_failure,
    stop_tick,
)
from flowtact.runtime.supervisor_startup import SupervisorStartup
from flowtact.runtime.supervisor_stats import SupervisorStats

__all__ = ["ProcessExecutor", "describe_failure"]

_EVENTS, _POLLIN = int(zmq.EVENTS), int(zmq.POLLIN)


class ProcessExecutor(SupervisorStartup, SupervisorLiveness, SupervisorStats):
    """Runs a :class:`~flowtact.running.compile.CompiledGraph` across worker processes joined by ZeroMQ.

    Start-up (:mod:`~flowtact.runtime.supervisor_startup`), liveness
    (:mod:`~flowtact.runtime.supervisor_liveness`) and statistics
    (:mod:`~flowtact.runtime.supervisor_stats`) are its parts; the run, the pump and the stop are here.
    """

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
        launched_at: float | None = None,
    ) -> None:
        self.plan = plan
        self.startup_s = startup_s
        self.launched_at = launched_at
        """When the command started (monotonic), if known: start-up and wall time count from there."""
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

    @classmethod
    def for_run(cls, plan: CompiledGraph, options: RunOptions) -> ProcessExecutor:
        """The executor ``flowtact run`` makes by default."""
        o = options
        return cls(
            plan,
            fast=o.fast,
            tick_s=o.tick_s,
            recorder=o.recorder,
            progress=o.progress,
            live=o.live,
            warn=o.warn,
            startup_s=o.startup_s,
            launched_at=o.launched_at,
        )

    def run(self, duration_s: float | None) -> RunSummary:
        """Run until ``duration_s`` of graph time (None: until interrupted; real time only)."""
        if duration_s is None and self.fast:
            raise ValueError("a --fast run needs a duration (--duration or the graph's duration_s)")
        self.duration_s = duration_s
        self.ctx: zmq.Context | None = None  # made after local workers are forked (flowtact.runtime.forked)
        self.ctl = self.rec = None
        self.parts: dict[str, float] = {}
        """Start-up parts measured here (s): ``kernels`` (numba set up before forking workers)."""
        self.run_folder = make_run_folder("run")  # ipc sockets; also sweeps folders of killed runs
        self.rundir = self.run_folder.path
        self.procs: dict[str, Proc] = {}
        self.auth = None
        self.by_ident: dict[bytes, Proc] = {}
        self.samples: dict[str, int] = {}
        self.rec_ends = 0
        self.stopped = False
        self.stop_at = 0.0
        self.stop_k = 0
        self.deadline_quiet: dict[str, float] = {}  # deadline path -> no warning before then
        self.interrupts = 0
        self.refused_seen = 0
        self.max_lag_s = 0.0
        self.strangers = 0  # malformed control messages from no known worker
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
            for g, nodes in self.placement.groups.items():
                pdef = self.placement.processes[g]
                self.procs[g] = Proc(
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
            forked = self._fork_local()  # before any socket or thread: see flowtact.runtime.forked
            self.ctx = zmq.Context()
            self._open_sockets()
            self._warm_shared()
            for proc in self.procs.values():
                if proc.host is not None:
                    self._say_waiting(proc)
                elif not forked:
                    self._spawn(proc)
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

    def _send(self, proc: Proc, msg: Message) -> None:
        with contextlib.suppress(zmq.ZMQError):  # the worker is gone; its process watch reports it
            proc.sock.send_multipart([proc.ident, encode(msg)])  # type: ignore[union-attr]

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
                    self._send(p, Ping())
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
                    frames = sock.recv_multipart(zmq.NOBLOCK)
                    try:
                        if len(frames) != 2:
                            raise ProtocolError(f"control message: {len(frames) - 1} frames, not 1")
                        msg = decode(frames[1])
                    except ProtocolError as e:
                        self._malformed(frames[0], e)
                        continue
                    self._on_control(sock, frames[0], msg)
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

    def _malformed(self, ident: bytes, e: ProtocolError) -> None:
        """A message the codec refused: from a known worker, that worker has failed (named, with
        the op and field); from no known worker (a stray or hostile peer), said once and dropped."""
        proc = self.by_ident.get(ident)
        if proc is not None:
            raise ProcessFailure(proc, ErrorReport(f"sent a malformed control message: {e}"))
        self.strangers += 1
        if self.strangers == 1:
            self.warn(f"ignored a malformed control message from an unknown peer: {e}")

    def _on_control(self, sock: zmq.Socket, ident: bytes, msg: Message) -> None:
        if isinstance(msg, Beat):  # from the worker's heartbeat thread (a socket of its own)
            proc = self.procs.get(msg.process)
            if proc is not None and msg.pid == proc.pid:
                self._on_beat(proc, msg)
            return
        if isinstance(msg, Hello):
            self._on_hello(sock, ident, msg)
            return
        proc = self.by_ident.get(ident)
        if proc is None:
            return
        proc.progress_at = time.monotonic()  # every message before the start is start-up progress
        if isinstance(msg, Ready):
            self._on_ready(proc, msg)
        elif isinstance(msg, Wired):
            proc.wired = True
            if proc.restarts and self.t0_ns:
                self._send(proc, Start(self.t0_ns, proc.last_k, resume=True))
                self._running(proc)
                if self.stopped:
                    self._send(proc, Stop(self.stop_k))
            else:
                proc.state = "wired"
        elif isinstance(msg, Stats):
            self._on_stats(proc, msg)
        elif isinstance(msg, Done):
            self._on_stats(proc, msg.stats)
            proc.counters = msg.counters
            proc.summaries = msg.summaries
            proc.done = True
            self.last_done_ns = time.monotonic_ns()
            proc.state = "done"
        elif isinstance(msg, ErrorReport):
            raise ProcessFailure(proc, msg)

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
            except ProcessFailure as f:
                self._failed(f)
        self._drain_until_records_end()
        return "interrupted" if self.stopped else "duration"

    def _stop_all(self) -> None:
        """Ctrl-C: every worker ends on one tick ahead, then drains and flushes."""
        self.stopped = True
        now = self.stop_at = time.monotonic()
        wall_s = None if self.fast else (time.monotonic_ns() - self.t0_ns) / 1e9
        k = stop_tick(self.procs.values(), now, wall_s, self.tick_s)
        self.stop_k = k
        for p in self.procs.values():
            if p.ident is not None:
                self._send(p, Stop(k))

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

    def _failed(self, f: ProcessFailure) -> None:
        """Restart the worker when its group asks for it and may; otherwise end the run."""
        proc, text = f.proc, describe_failure(f.proc, f.report)
        if f.stalled and proc.popen is not None and proc.popen.poll() is None:
            proc.popen.kill()  # stopped or hung: it cannot take part in an orderly end
            proc.popen.wait()
        if (
            proc.restart != "on-failure"
            or proc.restarts >= proc.max_restarts
            or proc.host is not None
            or self.stopped
        ):
            raise WorkerFailed(text, f.report.traceback)
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
        return min((p.stats.now for p in self.procs.values()), default=0.0)

    def _drain_until_records_end(self) -> None:
        """Write what is still in flight: every recording worker ends its records with a marker."""
        expected = sum(1 for g in self.procs if self.wplans[g].record)
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
                self._send(p, Abort() if failed else Exit())
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
        if self.ctx is not None:
            self.ctx.destroy(linger=0)
        self.run_folder.close()
