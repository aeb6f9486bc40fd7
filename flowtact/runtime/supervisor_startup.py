"""The supervisor's start-up: sockets, spawning workers, the join window, the handshake, wiring.

Part of :class:`flowtact.runtime.supervisor.ProcessExecutor` (which holds the state these methods
share). A local worker is a fork of the supervisor (:meth:`SupervisorStartup._fork_local`,
:mod:`flowtact.runtime.forked`) where that is safe, else its own interpreter (:meth:`_spawn`).
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import zmq

from flowtact.errors import ProcessFailure, WorkerFailed
from flowtact.running.python_child import python_command
from flowtact.runtime.forked import ForkedWorker, can_fork, fork_worker
from flowtact.runtime.links.zeromq.control import supervisor_sockets, supervisor_tcp_sockets
from flowtact.runtime.links.zeromq.streams import bind_address
from flowtact.runtime.protocol import ErrorReport, Hello, Plan, Ready, Start, Wire
from flowtact.runtime.supervisor_liveness import proc_stat
from flowtact.runtime.supervisor_procs import WAITING_EVERY_S, Proc
from flowtact.runtime.warm_up import load_shared_kernels, warm_shared_kernels

__all__ = ["SupervisorStartup"]


class SupervisorStartup:
    """Start-up and join of a :class:`~flowtact.runtime.supervisor.ProcessExecutor`'s workers."""

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

    def _open_sockets(self) -> None:
        remote = self.plan.graph.deployment.remote
        self.ctl, self.rec = supervisor_sockets(self.ctx, str(self.rundir))
        self.poller = zmq.Poller()
        self.poller.register(self.ctl, zmq.POLLIN)
        self.poller.register(self.rec, zmq.POLLIN)
        self.tcp_ctl = self.tcp_rec = None
        if remote:
            from flowtact.runtime.links.zeromq.security import Authenticator, load_keys

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
            self.ctl_tcp, self.ctl_watch, self.tcp_ctl, self.rec_tcp, self.tcp_rec = supervisor_tcp_sockets(
                self.ctx, net.listen, net.port, self.keys
            )
            self.poller.register(self.ctl_tcp, zmq.POLLIN)
            self.poller.register(self.rec_tcp, zmq.POLLIN)

    def _spawn(self, proc: Proc) -> None:
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(p for p in sys.path if p)  # `module:Class` blocks resolve alike
        env.setdefault("NUMBA_NUM_THREADS", "1")
        cmd = python_command(
            "-m", "flowtact.runtime.worker", f"ipc://{self.rundir}/ctl", "--process", proc.name, "--child"
        )
        if self.auth is not None:
            cmd += ["--keys", self.keys_dir]
        self._started(proc, subprocess.Popen(cmd, env=env, start_new_session=True))

    def _fork_local(self) -> bool:
        """Start every local group as a fork of this process, with numba set up and the kernel
        every worker calls loaded here once; False (nothing started) where forking is not safe
        or the graph spans hosts (its workers get CURVE keys as their own interpreters do)."""
        local = [p for p in self.procs.values() if p.host is None]
        if not local or self.plan.graph.deployment.remote or not can_fork():
            return False
        t0 = time.monotonic()
        specs = [spec for (node, _port), spec in self.plan.specs.items() if node in self.plan.demanded]
        load_shared_kernels(specs)
        self.parts["kernels"] = time.monotonic() - t0
        for proc in local:
            self._started(proc, fork_worker(f"ipc://{self.rundir}/ctl", proc.name))
        return True

    def _started(self, proc: Proc, popen: subprocess.Popen[bytes] | ForkedWorker) -> None:
        """Watch a newly started worker process of group ``proc`` from its start-up on."""
        proc.popen = popen
        proc.pid = popen.pid
        proc.spawned_at = time.monotonic()
        proc.state = "starting"
        proc.ident = None
        proc.beat = None
        proc.since = proc.progress_at = time.monotonic()
        proc.progress, proc.phase = None, "starting its interpreter"
        proc.done = proc.rec_done = proc.wired = False

    def _say_waiting(self, proc: Proc) -> None:
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

    def _bind_addresses(self, proc: Proc) -> dict[int, str]:
        """Where each of the group's incoming streams is bound."""
        out = {}
        for d in self.wplans[proc.name].inbound:
            sid = d.id
            if sid in proc.endpoints:  # a restart binds where the producers already connect
                out[sid] = proc.endpoints[sid]
            else:
                out[sid] = bind_address(
                    str(self.rundir), d, proc.name, proc.host, self.plan.graph.deployment.network.listen
                )
        return out

    def _on_hello(self, sock: zmq.Socket, ident: bytes, msg: Hello) -> None:
        """A worker of a known group introduced itself: it gets its plan (a stale one is ignored)."""
        proc = self.procs.get(msg.process)
        if proc is None:
            return
        if proc.host is None and proc.popen is not None and msg.pid != proc.popen.pid:
            return  # a stale worker
        proc.ident, proc.sock, proc.pid = ident, sock, msg.pid
        proc.hello_at = time.monotonic()
        proc.progress_at, proc.phase = time.monotonic(), "waiting for its plan"
        self.by_ident[ident] = proc
        self._send(proc, Plan(self.wplans[proc.name], self._bind_addresses(proc)))
        proc.state = "planned"

    def _on_ready(self, proc: Proc, msg: Ready) -> None:
        """A worker is built, warm and bound: it must have bound every stream it receives."""
        missing = sorted({d.id for d in self.wplans[proc.name].inbound} - msg.endpoints.keys())
        if missing:
            raise ProcessFailure(proc, ErrorReport(f"said ready without an endpoint for stream(s) {missing}"))
        self.compiles.on_ready(proc.describe(), msg)
        proc.ready_at, proc.setup = time.monotonic(), msg.setup
        proc.endpoints = dict(msg.endpoints)
        proc.state = "ready"
        if proc.restarts and self.t0_ns:  # a restart after the start rejoins the running graph
            self._wire(proc)

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
            except ProcessFailure as f:
                self._failed(f)  # under restart: on-failure the group starts again
            if all(p.endpoints or not self.wplans[p.name].inbound for p in self.procs.values()) and all(
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
            self._send(p, Start(t0, k0=0, resume=False))
            self._running(p)
        return True

    def _check_startup(self, p: Proc, now: float) -> None:
        """A worker that shows no start-up progress for its window did not join: name its last phase
        and how to widen the window. One that waits for the others (ready, wired) has no window."""
        if p.state in ("ready", "wired"):
            p.progress_at = now
            return
        if p.ident is None and p.host is None and p.pid is not None:  # before its first message
            seen = proc_stat(p.pid)
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

    def _running(self, proc: Proc) -> None:
        proc.state = "running"
        proc.since = proc.beat_at = proc.busy_since = time.monotonic()

    def _report_refusals(self) -> None:
        """Say so when a host tries to join with another key (ZAP refusal or a failed handshake)."""
        from flowtact.runtime.links.zeromq.security import SecurityError

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

    def _wire(self, proc: Proc) -> None:
        connect: dict[int, dict[str, str]] = {}
        for d in self.wplans[proc.name].outbound:
            connect.setdefault(d.id, {})[d.group] = self.procs[d.group].endpoints[d.id]
        remote = proc.host is not None
        record = self.tcp_rec if remote else f"ipc://{self.rundir}/rec"
        self._send(proc, Wire(connect, record))
        proc.state = "wiring"
