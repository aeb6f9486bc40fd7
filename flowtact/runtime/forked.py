"""Start a local worker as a fork of the supervisor: no second interpreter, imports or numba set-up.

A worker started as its own interpreter (``python -P -m flowtact.runtime.worker``) first spends
about 0.5 s of CPU importing numpy, numba and its blocks and about 0.4 s on numba's first
dispatch (its target set-up) before it loads a kernel of its own; three workers on two cores paid
that three times over, and on a busy laptop that was most of a 12 s start-up. The supervisor has
imported the blocks already (to check the graph) and makes numba's first dispatch once (loading
the kernel every worker calls); a fork of it starts with all of that done.

A fork copies only the calling thread: a lock another thread held stays held in the child forever.
So a worker is forked only while the supervisor runs one Python thread and before it has made a
ZeroMQ context (whose I/O threads are native): at the start of a run, on Linux. A group
restarted during the run, or a process when this cannot be ensured, starts as its own interpreter
(:func:`flowtact.running.python_child.python_command`), as before.
"""

from __future__ import annotations

import contextlib
import ctypes
import gc
import os
import signal
import subprocess
import sys
import threading
import time
import traceback

__all__ = ["ForkedWorker", "can_fork", "comm_name", "fork_worker"]

NO_FORK_ENV = "FLOWTACT_NO_FORK"
"""Set (to anything) to start every worker as its own interpreter: for comparing the two."""


def can_fork() -> bool:
    """Whether a worker may be forked from this process now: Linux (macOS system libraries are not
    safe to use in a fork that does not exec), one Python thread, not turned off."""
    return (
        sys.platform.startswith("linux") and threading.active_count() == 1 and not os.environ.get(NO_FORK_ENV)
    )


class ForkedWorker:
    """A forked worker seen as :class:`subprocess.Popen` is: ``pid``, ``poll``, ``wait``, ``kill``."""

    def __init__(self, pid: int) -> None:
        self.pid = pid
        self.returncode: int | None = None

    def poll(self) -> int | None:
        """Its exit status (negative: the signal that ended it), or None while it runs."""
        if self.returncode is None:
            try:
                pid, status = os.waitpid(self.pid, os.WNOHANG)
            except ChildProcessError:  # reaped elsewhere: gone, cause unknown
                self.returncode = -signal.SIGKILL
                return self.returncode
            if pid:
                self.returncode = os.waitstatus_to_exitcode(status)
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        """Wait for it to exit (as ``Popen.wait``: ``subprocess.TimeoutExpired`` after ``timeout``)."""
        deadline = None if timeout is None else time.monotonic() + timeout
        delay = 0.0005
        while self.poll() is None:
            if deadline is not None and time.monotonic() >= deadline:
                raise subprocess.TimeoutExpired(f"worker {self.pid}", timeout)  # type: ignore[arg-type]
            time.sleep(delay)  # as Popen.wait does with a timeout: short, growing naps
            delay = min(2 * delay, 0.05)
        return self.returncode  # type: ignore[return-value]

    def kill(self) -> None:
        """SIGKILL, unless it has been reaped already (its pid may then belong to another process)."""
        if self.returncode is None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(self.pid, signal.SIGKILL)


def comm_name(process: str) -> str:
    """The name ``ps -o comm`` and ``top`` show for a forked worker of group ``process`` (its
    command line is the supervisor's): ``ft:`` and the group, cut to Linux's 15 bytes."""
    return f"ft:{process}".encode()[:15].decode(errors="ignore")


def _name(process: str) -> None:
    """Linux: name this process :func:`comm_name` (``prctl(PR_SET_NAME)``); elsewhere nothing."""
    with contextlib.suppress(OSError, AttributeError):
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(15, ctypes.c_char_p(comm_name(process).encode()), 0, 0, 0)  # PR_SET_NAME


def fork_worker(control: str, process: str) -> ForkedWorker:
    """Fork, and run process group ``process`` of the run whose supervisor listens on ``control``
    in the child, in a session of its own (as ``start_new_session``); the child never returns."""
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()  # or the child would write the parent's buffered text again
    pid = os.fork()
    if pid:
        return ForkedWorker(pid)
    code = 1
    try:
        os.setsid()
        _name(process)
        gc.freeze()  # the supervisor's objects stay as they are: never collected or written here
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # the supervisor coordinates a Ctrl-C
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        from flowtact.runtime.worker import run_child

        code = run_child(control, process)
    except BaseException:  # noqa: BLE001 - anything: reported, then this process ends here
        traceback.print_exc()
    finally:
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        os._exit(code)  # never the parent's exit handlers: its files and folders are its own
