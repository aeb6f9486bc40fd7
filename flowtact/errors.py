"""Every public error flowtact raises, under one base: ``except FlowtactError`` catches them all.

They live here, together, so a reader sees the whole list and a caller imports any of them from one
place (all are exported by ``flowtact`` too; tests/test_errors.py keeps it so). Each error also keeps
the built-in base that says what kind of mistake it is (a bad value is a ``ValueError``, an unknown
name a ``LookupError``, a failed run a ``RuntimeError``, a damaged file an ``OSError``).
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from flowtact.inputs.safe_text import shown

__all__ = [
    "BadDataError",
    "BlockSpecsFailed",
    "ConfigError",
    "ConformanceError",
    "FileRefused",
    "FlowtactError",
    "GraphFileError",
    "MisalignedError",
    "ModuleNotAllowedError",
    "NodeError",
    "NodeFailure",
    "NotARecording",
    "ProcessFailure",
    "ProtocolError",
    "RecordingCorrupted",
    "RecordingError",
    "RecordingRefused",
    "SafeYamlError",
    "SecurityError",
    "SpecError",
    "SuiteSkipped",
    "SweepSpecError",
    "UnknownBlockError",
    "UsageError",
    "WireError",
    "WorkerDied",
    "WorkerFailed",
    "WorkerStop",
]


class FlowtactError(Exception):
    """Base class of flowtact's errors: bad configs, graphs, streams, data, devices and runs."""


class UsageError(FlowtactError, ValueError):
    """Bad usage or bad input named on the command line (a flag's value, a file the user gave):
    the command refuses it before doing its work, with one line and exit status 2."""


# -- blocks and their configs ----------------------------------------------------------------------


class ConfigError(FlowtactError, ValueError):
    """A parameter broke a rule: ``"<owner>: 'field' must be <rule>; got <value>"``. ``unknown``:
    the parameter given that the config does not have (so a caller can locate it without reading
    the message)."""

    def __init__(
        self,
        owner: str,
        field: str | None,
        message: str,
        *,
        type_error: bool = False,
        unknown: str | None = None,
    ) -> None:
        self.owner, self.field, self.rule = owner, field, message
        self.type_error = type_error  # the value had the wrong type (vs. broke a rule)
        self.unknown = unknown
        where = f"'{field}' " if field else ""
        super().__init__(f"{owner}: {where}{message}")


class SpecError(FlowtactError, ValueError):
    """An input stream does not fit what a block expects (``port`` names the input, if any).

    ``where`` is (file, line, column) when the problem sits in a data file the block reads (a
    replayed CSV log): the graph compiler then reports it there instead of at the node.
    """

    def __init__(self, port: str | None, message: str, where: tuple[str, int, int] | None = None) -> None:
        self.port = port
        self.where = where
        super().__init__(message)


class BadDataError(FlowtactError, ValueError):
    """Non-finite samples reached a block whose policy is ``raise``."""


class MisalignedError(FlowtactError, ValueError):
    """Samples that should describe the same instant carry different timestamps."""


class UnknownBlockError(FlowtactError, LookupError):
    """No block of that name is registered (the message suggests the closest one)."""


class ModuleNotAllowedError(UnknownBlockError):
    """A ``module:Class`` block whose module the user did not allow: it was not imported."""


class ConformanceError(FlowtactError, AssertionError):
    """A block failed a conformance check: ``"<block>: <check>: expected …; <what happened>"``."""

    def __init__(self, block: str, check: str, expected: str, happened: str) -> None:
        self.block, self.check, self.expected, self.happened = block, check, expected, happened
        super().__init__(f"{block}: {check}: expected {expected}; {happened}")


# -- graph files -----------------------------------------------------------------------------------


class GraphFileError(FlowtactError):
    """Raised with every :class:`~flowtact.graphfile.located.GraphProblem` found in a graph (each
    at its ``file:line:col``); ``str()`` lists them one per line, ``errors`` holds them.

    Typed loosely (``object``, shown with ``str``) so that this module imports none of the modules
    whose errors it holds: they all import it."""

    def __init__(self, errors: Iterable[object]) -> None:
        self.errors = list(errors)
        super().__init__("\n".join(map(str, self.errors)))


class SafeYamlError(FlowtactError, ValueError):
    """A graph file refused by a limit or by the YAML parser, at 1-based ``line``:``col``."""

    def __init__(self, message: str, line: int = 1, col: int = 1, hint: str = "") -> None:
        self.message, self.line, self.col, self.hint = message, line, col, hint
        super().__init__(f"{line}:{col}: {message}")


class BlockSpecsFailed(FlowtactError, RuntimeError):
    """A block's ``specs()`` raised something other than a SpecError: a bug in the block, not in
    the graph. Names the node (``loc`` is its graph-file place) and keeps the exception (``cause``)
    for ``--debug``."""

    def __init__(self, loc: object, node: str, block: str, cause: BaseException) -> None:
        self.node, self.block, self.cause = node, block, cause
        super().__init__(f"{loc}: node '{node}' ({block}): specs() raised {type(cause).__name__}: {cause}")


# -- files from others and recordings --------------------------------------------------------------


class FileRefused(FlowtactError, ValueError):
    """A file flowtact will not read: not a regular file, not the expected format, or over a budget.

    ``str(e)`` is one line, ``PATH: reason``, with the path shown as data (control characters
    escaped); ``e.reason`` is the reason alone (for a message located at the file).
    """

    def __init__(self, path: str | os.PathLike[str], reason: str) -> None:
        self.path, self.reason = str(path), reason
        super().__init__(f"{shown(self.path)}: {reason}")


class RecordingError(FlowtactError, OSError):
    """A recording that cannot be read: missing, not HDF5, truncated, or damaged."""


class RecordingCorrupted(RecordingError):
    """Part of a recording does not match its checksum or cannot be read; names file and object."""

    def __init__(self, path: str | Path, where: str, what: str = "checksum mismatch") -> None:
        self.path, self.where, self.what = str(path), where, what
        super().__init__(f"{shown(path)}: {shown(where, limit=200)}: {what} (the file is corrupted)")


class NotARecording(FlowtactError, ValueError):
    """An HDF5 file that is not a flowtact recording (no ``/streams`` group)."""


class RecordingRefused(RecordingError):
    """A file refused before it is read: not a regular file, not HDF5, or beyond a documented bound
    (``MAX_STREAMS``, ``MAX_CHUNK_BYTES``, ... in :mod:`flowtact.recording.integrity`): bad input
    rather than damage."""


# -- runs ------------------------------------------------------------------------------------------


class NodeError(FlowtactError, RuntimeError):
    """A block raised while stepping: names the node, its block and the graph time."""

    def __init__(self, node: str, block: str, now: float, cause: BaseException) -> None:
        self.node, self.block, self.now, self.cause = node, block, now, cause
        super().__init__(f"node '{node}' ({block}) failed at t={now:.3f} s: {type(cause).__name__}: {cause}")


class WorkerFailed(FlowtactError, RuntimeError):
    """A worker raised, died or stalled, or a stop overran its grace: names process, nodes, cause.

    ``traceback`` is the failing block's Python traceback as the worker formatted it (None when
    no Python exception caused the failure: a death, a stall); ``flowtact --debug`` prints it.
    """

    def __init__(self, message: str, traceback: str | None = None) -> None:
        super().__init__(message)
        self.traceback = traceback


class SecurityError(FlowtactError, RuntimeError):
    """CURVE keys are missing or malformed, or a peer was refused (or refused us)."""


class WireError(FlowtactError, ValueError):
    """A frame that is not a flowtact stream message (another version, a stray sender, corruption)."""


class ProtocolError(FlowtactError, ValueError):
    """A control message that is not one (not msgpack, an unknown op, a missing, unknown or
    mistyped field): one line naming the op and the field (:mod:`flowtact.runtime.protocol`)."""


# -- sweeps and benchmarks -------------------------------------------------------------------------


class SweepSpecError(FlowtactError, ValueError):
    """A sweep's grid, table, replay pattern or metric is wrong: one line, exit status 2."""


class WorkerDied(FlowtactError, RuntimeError):
    """The process running a row died before it answered (killed, out of memory, timed out)."""


class SuiteSkipped(FlowtactError):
    """Raised by ``ctx.skip(reason)``: the suite cannot run here (a missing package, no --peers)."""


# -- a worker's own control flow (caught inside the worker, never shown as such) ---------------------


class WorkerStop(FlowtactError):
    """The supervisor asked this worker to abort at once, or is gone."""


class NodeFailure(FlowtactError):
    """A block raised in a worker: what the worker reports (node, block, graph time, message,
    traceback) to the supervisor, which names it in :class:`WorkerFailed`."""

    def __init__(self, node: str, block: object, now: float, cause: BaseException) -> None:
        import traceback

        super().__init__(str(cause))
        self.report = {
            "node": node,
            "block": getattr(block, "name", str(block)),
            "now": now,
            "message": f"{type(cause).__name__}: {cause}",
            "traceback": "".join(traceback.format_exception(cause)),
        }


class ProcessFailure(FlowtactError):
    """A worker reported an error or died (caught by the supervisor: restart the group or end the
    run with :class:`WorkerFailed`). ``proc`` is the supervisor's record of the group, ``report``
    the failure (a :class:`flowtact.runtime.protocol.ErrorReport`); ``stalled``: it hung, kill it."""

    def __init__(self, proc: object, report: Any, *, stalled: bool = False) -> None:
        self.proc, self.report, self.stalled = proc, report, stalled
        super().__init__(report.message)
