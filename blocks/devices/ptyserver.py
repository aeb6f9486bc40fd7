"""Serve a line-oriented device model on a pseudo-terminal, so host code talks to it over a real tty.

An emulator process (``flowtact sim exo``) builds a :class:`LineDevice` and hands it to
:class:`PtyServer`, which owns the wall clock: it calls ``tick`` when the device is due, feeds each
line the host writes to ``receive``, and writes the device's lines to the pty (optionally after a
fixed + random latency, in order). The pty's slave side is reached through a stable symlink
(``link``), re-pointed atomically on every replug, so the host always opens the same path. The link
never replaces what it does not own: ``link`` must be new or a stale pty link (:func:`link_problem`),
and ``close`` removes it only while it still points to this server's pty.

Unplug (``unplug()``, e.g. from a SIGUSR1 handler): the pty is closed — the host's reads and
writes fail as with a pulled USB cable — and after ``replug_s`` a new pty is opened, the symlink
re-pointed and ``plugged(now, first=False)`` called (a real board power-cycles). Writes never
block: if the host does not read and the tty buffer fills, lines are dropped and counted
(``dropped``), as a USB CDC device drops them.

Linux/macOS only (``os.openpty``). This is an emulator process, not a block: it may sleep.
"""

from __future__ import annotations

import contextlib
import errno
import os
import secrets
import select
import stat
import time
import tty
from collections import deque
from typing import Protocol

import numpy as np

from flowtact.inputs.bounded_files import file_kind

__all__ = ["LineDevice", "LinkError", "PtyServer", "link_problem"]


class LineDevice(Protocol):
    """What :class:`PtyServer` drives. Times are host ``time.monotonic()`` seconds."""

    def next_due(self) -> float:
        """When ``tick`` should be called next."""
        ...

    def tick(self, now: float) -> list[bytes]:
        """Advance one device tick; return the lines to send."""
        ...

    def receive(self, line: bytes, now: float) -> list[bytes]:
        """Handle one line from the host (without its newline); return replies."""
        ...

    def plugged(self, now: float, first: bool) -> list[bytes]:
        """The link came up (first time, or a replug); return lines to send (a hello)."""
        ...


#: Drop queued output beyond this many bytes when the host does not read.
MAX_OUT_BYTES = 16384
#: Longest line accepted from the host.
MAX_LINE = 1024


class LinkError(ValueError):
    """The ``link`` path is something a pty link may not replace (a file, a folder, another link)."""


def link_problem(path: str) -> str | None:
    """Why a pty symlink may not be made at ``path``, or None.

    Allowed: a path that does not exist (the folder must), or a symlink to a character device, or a
    dangling symlink into ``/dev/`` (a stale link of an earlier emulator run, whose pty is gone).
    Anything else — a regular file, a folder, a FIFO, a link to a file — belongs to someone else.
    """
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        parent = os.path.dirname(path) or "."
        return None if os.path.isdir(parent) else f"its folder {parent} does not exist"
    except OSError as e:
        return f"cannot be inspected ({e.strerror})"
    if not stat.S_ISLNK(st.st_mode):
        return f"exists and is {file_kind(st.st_mode)}; it is never replaced (give a new path, or a stale pty link)"
    target = os.readlink(path)
    try:
        if stat.S_ISCHR(os.stat(path).st_mode):
            return None
    except FileNotFoundError:
        if os.path.isabs(target) and target.startswith("/dev/"):
            return None
    except OSError:
        pass
    return f"is a symlink to {target!r}, not to a pty; it is never replaced"


def _new_symlink(target: str, beside: str) -> str:
    """A new symlink to ``target`` in the folder of ``beside``, at a fresh name (nothing is overwritten)."""
    while True:
        tmp = f"{beside}.{os.getpid()}.{secrets.token_hex(4)}.tmp"
        try:
            os.symlink(target, tmp)
        except FileExistsError:
            continue
        return tmp


class PtyServer:
    """Drive a :class:`LineDevice` on a pty reachable at ``link`` (see the module notes)."""

    def __init__(
        self,
        device: LineDevice,
        link: str,
        *,
        latency_s: float = 0.0,
        jitter_s: float = 0.0,
        replug_s: float = 0.3,
        seed: int = 0,
    ) -> None:
        self.device = device
        self.link = os.path.abspath(link)
        self.latency_s = float(latency_s)
        self.jitter_s = float(jitter_s)
        self.replug_s = float(replug_s)
        self.rng = np.random.default_rng(seed)
        self.master: int | None = None
        self.slave: int | None = None
        self._queue: deque[tuple[float, bytes]] = deque()  # (send at, line)
        self._out = bytearray()
        self._in = bytearray()
        self._stop = False
        self._unplug = False
        self._last_send = -1.0
        self.dropped = 0
        self.replugs = 0
        self.lines_in = 0
        self._target: str | None = None  # the pty the link points to, while this server owns it

    # -- control (signal-handler safe: they only set flags) -------------------------------
    def stop(self) -> None:
        self._stop = True

    def unplug(self) -> None:
        self._unplug = True

    # -- pty ---------------------------------------------------------------------------------
    def open(self) -> None:
        """Create the pty and point ``link`` at it (refusing a path that is not a pty link)."""
        problem = link_problem(self.link)
        if problem:
            raise LinkError(problem)
        master, slave = os.openpty()
        tty.setraw(slave)  # no echo, no line editing, no CR/LF translation
        os.set_blocking(master, False)
        self.master, self.slave = master, slave
        target = os.ttyname(slave)
        tmp = _new_symlink(target, self.link)
        os.replace(tmp, self.link)  # atomic: the host never sees a missing link during a replug
        self._target = target
        self._in.clear()
        self._out.clear()
        self._queue.clear()

    def close(self, *, remove_link: bool = True) -> None:
        """Close the pty (the host sees a vanished device) and, by default, remove the link.

        The link is removed only while it is still the symlink this server made (to its pty):
        whatever replaced it since is not ours.
        """
        for fd in (self.master, self.slave):
            if fd is not None:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self.master = self.slave = None
        if remove_link and self._target is not None:
            with contextlib.suppress(OSError):
                if os.readlink(self.link) == self._target:
                    os.unlink(self.link)
            self._target = None

    # -- the loop ----------------------------------------------------------------------------
    def serve(self, duration_s: float | None = None, parent_pid: int | None = None) -> None:
        """Run until ``stop()``, ``duration_s``, or the process ``parent_pid`` is no longer our parent."""
        start = time.monotonic()
        self._send(self.device.plugged(start, True), start)
        while not self._stop:
            now = time.monotonic()
            if duration_s is not None and now - start >= duration_s:
                break
            if parent_pid is not None and os.getppid() != parent_pid:  # orphaned: the host died
                break
            if self._unplug:
                self._do_replug()
                continue
            due = self.device.next_due()
            if now >= due:
                self._send(self.device.tick(now), now)
            self._flush(now)
            wake = min(self.device.next_due(), self._queue[0][0] if self._queue else float("inf"))
            self._wait_read(max(0.0, min(wake - time.monotonic(), 0.05)))

    def _do_replug(self) -> None:
        self._unplug = False
        self.close(remove_link=False)  # the stale link points to a vanished pty, like /dev/ttyACM0
        deadline = time.monotonic() + self.replug_s
        while not self._stop and time.monotonic() < deadline:
            time.sleep(min(0.01, max(0.0, deadline - time.monotonic())))
        if self._stop:
            return
        self.open()
        self.replugs += 1
        now = time.monotonic()
        self._send(self.device.plugged(now, False), now)

    def _send(self, lines: list[bytes], now: float) -> None:
        if not lines:
            return
        at = now + self.latency_s + (self.rng.uniform(0.0, self.jitter_s) if self.jitter_s > 0 else 0.0)
        at = max(at, self._last_send)  # a serial line is FIFO
        self._last_send = at
        for line in lines:
            self._queue.append((at, line))

    def _flush(self, now: float) -> None:
        while self._queue and self._queue[0][0] <= now:
            self._out += self._queue.popleft()[1]
        if not self._out or self.master is None:
            return
        try:
            n = os.write(self.master, self._out)
            del self._out[:n]
        except BlockingIOError:
            pass
        except OSError as e:
            if e.errno not in (errno.EAGAIN, errno.EIO):
                raise
        if len(self._out) > MAX_OUT_BYTES:  # nobody reads: drop whole old lines
            cut = self._out.find(b"\n", len(self._out) - MAX_OUT_BYTES) + 1
            self.dropped += self._out[:cut].count(b"\n")
            del self._out[:cut]

    def _wait_read(self, timeout: float) -> None:
        if self.master is None:
            time.sleep(timeout)
            return
        try:
            ready, _, _ = select.select([self.master], [], [], timeout)
        except InterruptedError:  # a signal: the loop re-checks its flags
            return
        if not ready:
            return
        try:
            data = os.read(self.master, 4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as e:
            if e.errno == errno.EIO:  # no slave open right now
                time.sleep(timeout)
                return
            raise
        self._in += data
        now = time.monotonic()
        while True:
            i = self._in.find(b"\n")
            if i < 0:
                if len(self._in) > MAX_LINE:
                    self._in.clear()
                break
            line = bytes(self._in[:i])
            del self._in[: i + 1]
            self.lines_in += 1
            self._send(self.device.receive(line, now), now)
