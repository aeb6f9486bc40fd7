"""Private run folders in the temp directory, and the safe removal of those a killed run left behind.

Every temporary folder flowtact makes for a run (the supervisor's ipc sockets, ``serial_io``'s
emulator link, ``flowtact sim exo``'s default link) is made here: 0700, named
``flowtact-<kind>-<random>`` (short: ipc socket paths inside it are limited to 107 bytes). Its
``lock`` file records the owning process's id and start time (clock ticks after boot, from
``/proc/<pid>/stat``; 0 where there is no ``/proc``), and the owner holds an exclusive ``flock`` on
it for as long as the folder lives; the kernel drops the lock when the process dies, even by SIGKILL.
The lock file appears already locked and filled (written under another name, then renamed).

A ``kill -9`` skips the owner's clean-up, so each new run folder first sweeps the temp directory
(:func:`clean_stale`). A folder is removed only when all of these hold: its name is exactly
flowtact's pattern; ``os.lstat`` shows a real directory (never a symlink) owned by this user with no
group or other permissions; its ``lock`` is a regular file (not followed if a symlink) naming a pid
and start time; nobody holds the lock; and that process is gone (no such pid, or a pid reused by a
process with another start time). Anything else — another user's folder, a symlink named like a run
folder, a live run's folder, a folder without a readable lock (older releases, or a run killed while
making it) — is left alone. Removal uses :func:`shutil.rmtree`, which does not follow symlinks.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import re
import shutil
import stat
import tempfile
from types import TracebackType

__all__ = ["LOCK_NAME", "MAX_STALE_PER_SWEEP", "RunFolder", "clean_stale", "is_stale", "make_run_folder"]

LOCK_NAME = "lock"
"""The file in each run folder whose ``flock`` its owner holds while the folder is in use."""
MAX_STALE_PER_SWEEP = 64
"""Most stale folders one sweep removes: a start after many killed runs stays quick; the next
starts remove the rest."""

_NAME = re.compile(r"flowtact-[a-z]+-[a-z0-9_]{8}")
_OWNER = re.compile(rb"([0-9]{1,10}) ([0-9]{1,20})\n")
_KIND = re.compile(r"[a-z]+")


def process_start(pid: int) -> int | None:
    """The start time of process ``pid`` (clock ticks after boot), 0 if unknown here, None if no such pid."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            text = f.read()
    except FileNotFoundError:
        return None
    except OSError:  # no /proc (macOS): only whether the pid exists can be known
        return 0 if _pid_exists(pid) else None
    fields = text[text.rfind(b")") + 2 :].split()  # the name may hold spaces and ')'
    return int(fields[19])  # field 22 of stat(5), counted after the name (field 2)


def _pid_exists(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's live process
        return True
    return True


class RunFolder:
    """A private (0700) temporary folder, locked by this process until :meth:`close` removes it."""

    def __init__(self, path: str, lock_fd: int) -> None:
        self.path = path
        self._lock_fd: int | None = lock_fd

    def close(self) -> None:
        """Remove the folder and everything in it, then release the lock (idempotent)."""
        if self._lock_fd is None:
            return
        shutil.rmtree(self.path, ignore_errors=True)
        os.close(self._lock_fd)
        self._lock_fd = None

    def __enter__(self) -> RunFolder:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()


def make_run_folder(kind: str, *, root: str | None = None) -> RunFolder:
    """Sweep stale run folders from ``root`` (default: the temp directory), then make and lock a new one.

    ``kind`` (lowercase letters) says which part of flowtact made it: ``run``, ``serial``, ``exo``.
    """
    if not _KIND.fullmatch(kind):
        raise ValueError(f"run folder kind must be lowercase letters; got {kind!r}")
    root = root or tempfile.gettempdir()
    clean_stale(root)
    path = tempfile.mkdtemp(prefix=f"flowtact-{kind}-", dir=root)
    tmp = os.path.join(path, f".{LOCK_NAME}.tmp")
    fd = os.open(tmp, os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o600)
    fcntl.flock(fd, fcntl.LOCK_EX)  # a new file nobody else has opened: never blocks
    pid = os.getpid()
    os.write(fd, f"{pid} {process_start(pid) or 0}\n".encode())
    os.rename(tmp, os.path.join(path, LOCK_NAME))  # appears locked and filled
    return RunFolder(path, fd)


def is_stale(path: str) -> bool:
    """Whether ``path`` is a run folder of this user whose owner is gone (see the module notes)."""
    if _NAME.fullmatch(os.path.basename(path)) is None:
        return False
    try:
        st = os.lstat(path)
    except OSError:
        return False
    if not stat.S_ISDIR(st.st_mode) or st.st_uid != os.getuid() or st.st_mode & 0o077:
        return False
    try:
        fd = os.open(
            os.path.join(path, LOCK_NAME), os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC
        )
    except OSError:  # no lock file (an older release's folder, or one being made), or a symlink
        return False
    try:
        return _owner_gone(fd)
    finally:
        os.close(fd)


def _owner_gone(fd: int) -> bool:
    """Whether the lock file open at ``fd`` names a process that is gone and nobody holds the lock."""
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        return False
    m = _OWNER.fullmatch(os.read(fd, 64))
    if m is None:
        return False
    pid, start = int(m[1]), int(m[2])
    now = process_start(pid)
    if now is not None and (now == start or 0 in (now, start)):
        return False  # the owner still runs (or a reused pid cannot be told apart here)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:  # held: e.g. an owner in another pid namespace
        return False
    return True


def clean_stale(root: str | None = None) -> list[str]:
    """Remove up to :data:`MAX_STALE_PER_SWEEP` stale run folders from ``root``; the paths removed.

    Best effort: a folder that cannot be judged or removed is left as it is.
    """
    root = root or tempfile.gettempdir()
    removed: list[str] = []
    try:
        entries = os.scandir(root)
    except OSError:
        return removed
    with entries:
        for entry in entries:
            if len(removed) >= MAX_STALE_PER_SWEEP:
                break
            if entry.name.startswith("flowtact-") and is_stale(entry.path):
                with contextlib.suppress(OSError):
                    shutil.rmtree(entry.path)
                if not os.path.lexists(entry.path):
                    removed.append(entry.path)
    return removed
