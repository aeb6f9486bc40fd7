"""A worker process: runs one process group's nodes, joined to the others by ZeroMQ streams.

A worker is the engine (:class:`~flowtact.runtime.engine.Engine`, the tick schedule the in-process
executor runs) with ZeroMQ links, plus its control loop, so a ``--fast`` run gives the same chunks,
hence the same results, in both modes. Its nodes are joined within the process by ``local`` links
and across processes by the links of :mod:`flowtact.runtime.links.zeromq.stream_links`. Tick ``k``
covers graph time up to ``k * tick_s``; every chunk a node emits at tick ``k`` becomes available to
its consumers at tick ``k`` (or ``k + 1`` through a delay port). A ``block`` stream carries one
message per tick (an empty one when nothing came out), so a consumer knows when it has all of tick
``k``; a ``latest`` stream carries only data and the consumer takes whatever is newest. ``END``
messages follow each node's end-of-stream output (its flush). A node's remote inputs are read just
before it is gathered, so chains that leave a process and come back within a tick do not deadlock.

What is the worker's own stays out of the engine: which tick to run (the clock, catch-up when
behind it, ``--fast`` merging, the stop tick: :mod:`flowtact.runtime.worker_ticks`), control and
heartbeats (:mod:`flowtact.runtime.worker_control`), and what it measures per node-step, through
the engine's one watch (:mod:`flowtact.runtime.worker_watch`): CPU time per node, the node being
stepped, steps, latency origins and deadlines. Its recorder is an engine sink
(:mod:`flowtact.runtime.worker_records`).

The hot path: a block stream is read by blocking ``recv`` calls, one message each, without
catching ``zmq.Again`` on the way; control is read every :data:`CONTROL_NS`, not every tick;
recorded chunks are coalesced for :data:`RECORD_FLUSH_NS`; a source's data is stamped once its
step has made it, so latency is transport, not the source's own work. In ``--fast`` runs a worker
without sources that already holds ticks ``k+1..K`` on every input steps once at ``K`` when
:func:`~flowtact.runtime.worker_plan.ticks_mergeable` says no result can depend on it.

Lifecycle, driven by the supervisor over the control socket (typed messages, :mod:`flowtact.runtime.protocol`): hello -> plan ->
ready (bound endpoints) -> wire (connect) -> wired -> start -> stats -> done -> exit. A stop
names the tick every worker ends on (``stop`` with ``k``), so a loop through several processes
ends on the same tick everywhere and drains like the end of a timed run.

Liveness: a heartbeat thread reports the tick, the node being stepped and the steps done every
:data:`BEAT_S`, so the supervisor tells a worker stuck inside a block (or stopped) from one that
waits for its clock or its inputs. Before the start it reports its start-up phase instead
("building node 'sa1' (nlif)", "warming node 'sa1' (2/3), step 4/10", "opening node 'cam'"),
with counters that advance while it imports modules or numba runs compiler passes: each advance
restarts the supervisor's start-up window, so a long compile or warm-up is progress, not a stall. A worker the supervisor started dies with it (it checks its
parent, and on Linux ``PR_SET_PDEATHSIG``); one started by hand on another host exits after
:data:`ORPHAN_S` without a ping. So no process outlives a run.

Run as ``python -m flowtact.runtime.worker --connect ENDPOINT --process NAME`` (the supervisor
does this) or ``flowtact worker ENDPOINT --process NAME`` on another host.
"""

from __future__ import annotations

import argparse
import contextlib
import ctypes
import os
import signal
import socket
import sys
import threading
import time
import traceback

import zmq

from flowtact.errors import NodeFailure, WorkerStop
from flowtact.runtime.links.zeromq.control import heartbeat_socket, worker_control_socket
from flowtact.runtime.protocol import Beat, ErrorReport, Exit, Hello, Plan, Ready, Start, Wire, Wired, encode
from flowtact.runtime.warm_up import CompileWatch
from flowtact.runtime.worker_control import ORPHAN_S, WorkerControl
from flowtact.runtime.worker_setup import WorkerSetup
from flowtact.runtime.worker_ticks import FOREVER, WorkerTicks

__all__ = ["BEAT_S", "ORPHAN_S", "Worker", "main"]

BEAT_S = 0.1
"""How often the heartbeat thread reports progress (tick, node being stepped, steps done)."""
LATENCY_WARMUP_S = 1.0
"""Latencies count for data that left its source this long after the start: loading JIT-compiled
kernels and first allocations are start-up, not transport."""


class Worker(WorkerControl, WorkerSetup, WorkerTicks):
    """One process group of a running graph: its control loop (worker_control), start-up
    (worker_setup) and tick loop (worker_ticks), sharing the state set up here."""

    def __init__(
        self,
        control: str,
        process: str,
        *,
        keys_dir: str | None = None,
        child: bool = False,
        allow_modules: tuple[str, ...] | None = None,
    ) -> None:
        self.process = process
        self.allow_modules = allow_modules
        """Modules whose ``module:Class`` blocks this worker may import: None (a child of the local
        supervisor) takes the user's list from the plan; a worker on another host has its own."""
        self.ctx = zmq.Context()
        self.keys = None
        self.auth = None
        if control.startswith("tcp://") or keys_dir:  # a graph across hosts: CURVE on every tcp socket
            from flowtact.runtime.links.zeromq.security import Authenticator, load_keys

            self.keys = load_keys(keys_dir)
            self.auth = Authenticator(self.ctx, self.keys).start()
        self.ctl = worker_control_socket(self.ctx, control, self.keys)
        self.last_ping = time.monotonic()
        self.parent = os.getppid() if child else None
        self.stop_k = FOREVER
        self.rec: zmq.Socket | None = None
        # progress, read by the heartbeat thread (plain attribute writes: cheap on the hot path)
        self.k = 0
        self.steps = 0
        self.busy: str | None = None  # the node being built, opened or stepped
        self.busy_first = True  # ... for the first time: kernels may be compiling
        self.lag_s = 0.0
        self.compiles = CompileWatch()  # numba compilations: announced while warming, a stall after
        self.phase = "starting"  # what the start-up is doing now (reported by the heartbeat)
        self.marks = 0  # start-up phases entered so far: each one is progress
        self.heart = _Heartbeat(self, control)

    def serve(self) -> int:
        """Run the whole lifecycle; returns the process exit status."""
        self._send(Hello(self.process, os.getpid(), socket.gethostname()))
        self.heart.start()
        try:
            self._phase("waiting for the plan")
            msg = self._expect(Plan)
            t_plan = time.monotonic()
            self._build(msg.plan)
            t_built = time.monotonic()
            self._warm_up()
            t_warm = time.monotonic()
            self._phase("binding its inputs")
            endpoints = self._bind(msg.bind)
            self._send(
                Ready(
                    endpoints=endpoints,
                    compiled=self.warm_report.total_compiled,
                    compile_s=self.compiles.seconds,
                    setup={
                        "build": t_built - t_plan,
                        "warm_up": t_warm - t_built,
                        "bind": time.monotonic() - t_warm,
                    },
                )
            )
            self._phase("waiting for the other processes")
            wire = self._expect(Wire)
            self._phase("connecting its outputs")
            self._connect(wire.connect, wire.record)
            try:
                self._open()  # devices, cameras, weights: before the clock starts, not on its time
                self._send(Wired())
                self._phase("waiting for the start")
                start = self._expect(Start)
                self.t0_ns = start.t0_ns or time.monotonic_ns()
                self.warm_ns = self.t0_ns + int(_latency_from_s() * 1e9)
                self.k = start.k0
                self._run(resume=start.resume)
                self._finish()  # steps and flushes the blocks once more: before they are closed
            finally:
                self._close_blocks()
            self._expect(Exit)
            return 0
        except WorkerStop:
            self._salvage_records()
            return 0
        except NodeFailure as f:
            self._salvage_records()
            self._send(ErrorReport(**f.report))
            return 1
        except Exception as e:  # noqa: BLE001 — any framework failure is reported to the supervisor, not lost
            self._salvage_records()
            self._send(ErrorReport(f"{type(e).__name__}: {e}", traceback=traceback.format_exc()))
            return 1
        finally:
            self.heart.halt()
            if self.auth is not None:
                self.auth.stop()
            self.ctx.destroy()  # each socket's own linger: the control socket's last words get out


class _Heartbeat:
    """Sends the worker's progress every :data:`BEAT_S` from a thread and a socket of its own.

    The main thread only writes plain attributes (``k``, ``busy``, ``steps``, ``lag_s``); a worker
    stuck inside a block keeps beating with the same step count, a stopped one falls silent.
    """

    def __init__(self, worker: Worker, control: str) -> None:
        self.worker, self.control = worker, control
        self.stopped = threading.Event()
        self.thread = threading.Thread(target=self._run, name="flowtact-heartbeat", daemon=True)

    def start(self) -> None:
        self.thread.start()

    def halt(self) -> None:
        """Stop beating and close the socket (before the context is destroyed)."""
        self.stopped.set()
        if self.thread.is_alive():
            self.thread.join(timeout=5.0)

    def _run(self) -> None:
        w = self.worker
        sock = heartbeat_socket(w.ctx, self.control, w.keys)
        pid = os.getpid()
        try:
            while not self.stopped.wait(BEAT_S):
                beat = Beat(
                    process=w.process,
                    pid=pid,
                    k=w.k,
                    steps=w.steps,
                    node=w.busy,
                    first=w.busy_first,
                    lag_s=w.lag_s,
                    compiling=w.compiles.current,
                    compiled=w.compiles.count,
                    phase=w.phase,
                    progress=(w.marks, len(sys.modules), w.compiles.passes),
                    sent_ns=time.monotonic_ns(),
                )
                with contextlib.suppress(zmq.Again):
                    sock.send(encode(beat), zmq.NOBLOCK)
        finally:
            sock.close(linger=0)


def _latency_from_s() -> float:
    """:data:`LATENCY_WARMUP_S`, or ``$FLOWTACT_LATENCY_FROM_S`` (the start-up bench counts from 0)."""
    with contextlib.suppress(KeyError, ValueError):
        return max(float(os.environ["FLOWTACT_LATENCY_FROM_S"]), 0.0)
    return LATENCY_WARMUP_S


def _die_with_parent() -> None:
    """Linux: this process gets SIGKILL when the process that started it dies."""
    try:
        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
        if os.getppid() == 1:  # the parent died before prctl
            os._exit(1)
    except OSError:
        pass


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``python -m flowtact.runtime.worker``."""
    p = argparse.ArgumentParser(prog="flowtact worker", description="run one process group of a graph")
    p.add_argument("connect", help="the supervisor's control endpoint (ipc://... or tcp://host:port)")
    p.add_argument("--process", required=True, help="the process group to run")
    p.add_argument("--keys", help="CURVE keys folder for tcp (default: $FLOWTACT_KEYS)")
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    from flowtact.commands.graph_args import add_allow_module

    add_allow_module(p)
    args = p.parse_args(argv)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the supervisor coordinates a Ctrl-C
    if args.child and sys.platform.startswith("linux"):
        _die_with_parent()
    from flowtact.runtime.links.zeromq.security import SecurityError

    try:
        allow = None if args.child else tuple(args.allow_modules)  # on another host: this host's own word
        worker = Worker(args.connect, args.process, keys_dir=args.keys, child=args.child, allow_modules=allow)
    except SecurityError as e:
        print(f"flowtact worker: {e}", file=sys.stderr)
        return 1

    return worker.serve()


def run_child(control: str, process: str) -> int:
    """Run process group ``process`` in a fork of the supervisor (:mod:`flowtact.runtime.forked`)."""
    if sys.platform.startswith("linux"):
        _die_with_parent()
    return Worker(control, process, child=True).serve()


if __name__ == "__main__":
    sys.exit(main())
