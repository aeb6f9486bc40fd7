"""Keep the LSL of a test on this machine, and prove it: the config file, the environment, the sockets.

liblsl reads the file ``LSLAPICFG`` names (keys checked against liblsl 1.18's own: ``ports.IPv6``,
``multicast.ResolveScope``, ``multicast.ListenAddress``, ``multicast.AddressesOverride``,
``multicast.Interfaces``, ``lab.KnownPeers``). With it, discovery queries go to 127.0.0.1 only
(no multicast group, no broadcast), the multicast listener binds 127.0.0.1, and there is no IPv6.
liblsl prints ``Configuration loaded from PATH`` on stderr when it read the file (log level 0).
"""

from __future__ import annotations

import os
import socket
from pathlib import Path

import psutil

CONFIG = """\
[ports]
IPv6 = disable
[multicast]
ResolveScope = machine
ListenAddress = 127.0.0.1
AddressesOverride = {127.0.0.1}
Interfaces = {127.0.0.1}
[lab]
KnownPeers = {127.0.0.1}
"""

#: Local addresses a socket may be bound to: loopback, or the wildcard (listening sockets: liblsl
#: binds its outlets' TCP/UDP service ports to 0.0.0.0; they answer, they never send first).
ALLOWED_LOCAL = {"127.0.0.1", "0.0.0.0"}


def write_config(folder: Path) -> Path:
    path = folder / "lsl_api.cfg"
    path.write_text(CONFIG)
    return path


def confined_env(cfg: Path) -> dict[str, str]:
    """This process's environment with LSLAPICFG set (and nothing else changed)."""
    return {**os.environ, "LSLAPICFG": str(cfg)}


def socket_problems(pids: list[int]) -> tuple[list[str], int]:
    """Every inet socket of these processes (and their children) that is not on loopback: bound to
    a non-loopback address, connected to one, or IPv6; and how many sockets were looked at."""
    procs = []
    for pid in pids:
        try:
            p = psutil.Process(pid)
            procs += [p, *p.children(recursive=True)]
        except psutil.NoSuchProcess:
            continue
    problems, seen = [], 0
    for p in procs:
        try:
            conns = p.net_connections(kind="inet")
        except psutil.NoSuchProcess:
            continue
        for c in conns:
            seen += 1
            if c.family == socket.AF_INET6:
                problems.append(f"pid {p.pid}: IPv6 socket {c.laddr}")
            elif c.laddr and c.laddr.ip not in ALLOWED_LOCAL:
                problems.append(f"pid {p.pid}: bound to {c.laddr.ip}:{c.laddr.port}")
            if c.raddr and c.raddr.ip != "127.0.0.1":
                problems.append(f"pid {p.pid}: connected to {c.raddr.ip}:{c.raddr.port}")
    return problems, seen
