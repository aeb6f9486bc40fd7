"""The control sockets between a supervisor and its workers: how each is made, bound and connected.

The supervisor binds a ROUTER for control and a PULL for recorded streams on ipc:// in its run
folder and, when a group runs on another host, both again on tcp:// with CurveZMQ; a worker
connects a DEALER for control (CURVE and a handshake check on tcp://) and its heartbeat thread a
DEALER of its own. What travels on them is :mod:`flowtact.runtime.protocol`'s.
"""

from __future__ import annotations

from typing import Any

import zmq

__all__ = ["heartbeat_socket", "supervisor_sockets", "supervisor_tcp_sockets", "worker_control_socket"]

HANDSHAKE_S = 10.0
"""How long a worker on another host waits for the CurveZMQ handshake with its supervisor."""
BEAT_HWM = 8
"""Heartbeats queued at most: a stalled link drops old beats rather than blocking the thread."""


LOCAL_RECONNECT_MS = 5
"""A forked worker connects before its supervisor has bound (it forks first, then makes its ZeroMQ
context): retried this often (ms) instead of ZeroMQ's 100 ms default, which every start-up waited."""


def worker_control_socket(ctx: zmq.Context, endpoint: str, keys: Any = None) -> zmq.Socket:
    """A worker's control DEALER, connected to ``endpoint`` (tcp://: CURVE, handshake checked)."""
    sock = ctx.socket(zmq.DEALER)
    sock.setsockopt(zmq.LINGER, 2000)  # the last words (an error report) get out
    sock.setsockopt(zmq.RECONNECT_IVL, LOCAL_RECONNECT_MS)
    if not endpoint.startswith("tcp://"):
        sock.connect(endpoint)
        return sock
    from flowtact.runtime.links.zeromq.security import HandshakeWatch, secure_client

    secure_client(sock, keys)
    watch = HandshakeWatch(sock)
    sock.connect(endpoint)
    try:
        watch.wait(HANDSHAKE_S, endpoint=endpoint)
    finally:
        watch.close()
    return sock


def heartbeat_socket(ctx: zmq.Context, endpoint: str, keys: Any = None) -> zmq.Socket:
    """The heartbeat thread's own DEALER, connected to the supervisor's control ``endpoint``."""
    sock = ctx.socket(zmq.DEALER)
    sock.setsockopt(zmq.LINGER, 0)
    sock.setsockopt(zmq.SNDHWM, BEAT_HWM)
    if endpoint.startswith("tcp://"):
        from flowtact.runtime.links.zeromq.security import secure_client

        secure_client(sock, keys)
    sock.connect(endpoint)
    return sock


def supervisor_sockets(ctx: zmq.Context, rundir: str) -> tuple[zmq.Socket, zmq.Socket]:
    """The supervisor's control ROUTER and record PULL, bound on ipc:// in the run folder."""
    ctl = ctx.socket(zmq.ROUTER)
    ctl.setsockopt(zmq.LINGER, 0)
    ctl.setsockopt(zmq.ROUTER_MANDATORY, 1)
    ctl.bind(f"ipc://{rundir}/ctl")
    rec = ctx.socket(zmq.PULL)
    rec.setsockopt(zmq.LINGER, 0)
    rec.bind(f"ipc://{rundir}/rec")
    return ctl, rec


def supervisor_tcp_sockets(
    ctx: zmq.Context, listen: str, port: int, keys: Any
) -> tuple[zmq.Socket, Any, str, zmq.Socket, str]:
    """For groups on other hosts: the control ROUTER bound at ``listen:port`` and a record PULL on
    a port the OS picks, both CURVE servers. Returns (control socket, its handshake watch, its
    address, record socket, its address)."""
    from flowtact.runtime.links.zeromq.security import HandshakeWatch, secure_server

    ctl = ctx.socket(zmq.ROUTER)
    ctl.setsockopt(zmq.LINGER, 0)
    secure_server(ctl, keys)
    watch = HandshakeWatch(ctl)
    ctl.bind(f"tcp://{listen}:{port}")
    rec = ctx.socket(zmq.PULL)
    rec.setsockopt(zmq.LINGER, 0)
    secure_server(rec, keys)
    rec_port = rec.bind_to_random_port(f"tcp://{listen}")
    return ctl, watch, ctl.last_endpoint.decode(), rec, f"tcp://{listen}:{rec_port}"
