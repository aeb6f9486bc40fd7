"""``--debug`` and ``FLOWTACT_DEBUG=1``: a failure's one-line error, then its full Python traceback.

Without it the line ends with a hint that ``--debug`` shows the traceback. A block that failed in a
worker process has its traceback formatted there and sent with the failure report
(:attr:`~flowtact.errors.WorkerFailed.traceback`); in-process, a
:class:`~flowtact.errors.NodeError` keeps the block's exception as its ``cause``.
"""

from __future__ import annotations

import os
import sys
import traceback
from typing import TextIO

from flowtact.inputs.safe_text import shown

__all__ = ["ENV", "HINT", "debug_enabled", "failure_traceback", "has_traceback", "print_error"]

ENV = "FLOWTACT_DEBUG"
HINT = "(--debug shows the traceback)"


def debug_enabled(flag: bool = False) -> bool:
    """``--debug`` was given, or ``FLOWTACT_DEBUG`` is set to 1/true/yes/on."""
    return flag or os.environ.get(ENV, "").strip().lower() in ("1", "true", "yes", "on")


def failure_traceback(e: BaseException) -> str:
    """The traceback that explains ``e``: the block's own (from its worker, or its ``cause``), else ``e``'s."""
    remote = getattr(e, "traceback", None)
    if isinstance(remote, str) and remote.strip():
        return remote.rstrip("\n") + "\n"
    cause = getattr(e, "cause", None)
    if isinstance(cause, BaseException):
        e = cause
    return "".join(traceback.format_exception(type(e), e, e.__traceback__))


def has_traceback(e: BaseException) -> bool:
    """Whether ``--debug`` would show more than the line: a Python exception lies behind ``e``."""
    remote = getattr(e, "traceback", None)
    if remote is not None or hasattr(e, "cause"):
        return bool(remote) or isinstance(getattr(e, "cause", None), BaseException)
    return e.__traceback__ is not None


def print_error(line: str, e: BaseException, debug: bool, file: TextIO | None = None) -> None:
    """Print ``line``; then the traceback (``debug``) or, where one exists, the hint to ask for it.

    Error texts quote files and libraries: control characters in the line, and in each line of the
    traceback, are shown escaped (:func:`~flowtact.inputs.safe_text.shown`), so none reaches the terminal.
    """
    out = file if file is not None else sys.stderr
    line = shown(line)
    if debug:
        print(line, file=out)
        print("".join(shown(t) + "\n" for t in failure_traceback(e).splitlines()), end="", file=out)
    elif has_traceback(e):
        print(f"{line} {HINT}", file=out)
    else:
        print(line, file=out)
