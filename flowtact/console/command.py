"""One error path for every ``flowtact`` command, the built-in ones and the plugins alike.

:func:`run_command` runs a command's body and turns whatever it raises into ONE line on stderr,
``PROG: error: ...`` (the file's name first where the exception carries one, control characters
escaped), with the traceback only under ``--debug`` / ``FLOWTACT_DEBUG=1``, and an exit status:

- 2: bad usage or bad input: an argument or flag refused (:class:`CommandParser`, whose usage
  errors are one line too), :class:`~flowtact.errors.UsageError`, a graph's problems, a path the
  user named that cannot be used (missing, a folder, not permitted);
- 1: the command ran and failed (a block, a worker, out of memory, anything else);
- 130: interrupted (Ctrl-C, SIGTERM where the command maps it to an interrupt).

A plugin command (entry-point group ``flowtact.commands``) wraps its ``main`` in
:func:`run_command`, so it behaves the same run as ``flowtact NAME`` or called directly; the
``flowtact`` command runs it under the same function again, which catches what escapes a plugin
that does not.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Callable
from typing import NoReturn

from flowtact.console.debug import debug_enabled, print_error
from flowtact.errors import FlowtactError, UsageError
from flowtact.inputs.safe_text import shown

__all__ = ["EXIT_INTERRUPTED", "EXIT_RUN_ERROR", "EXIT_USAGE", "CommandParser", "error_text", "run_command"]

EXIT_USAGE = 2
EXIT_RUN_ERROR = 1
EXIT_INTERRUPTED = 130
MAX_ERROR_CHARS = 2000
"""Longest error line printed (a library's message quoting a whole file is cut, saying so)."""

_PATH_ERRORS = (FileNotFoundError, IsADirectoryError, NotADirectoryError, PermissionError, FileExistsError)
"""A path the user named cannot be used as asked: bad input (exit 2), not a failed run."""
_SAID = (FlowtactError, ValueError, ImportError, OSError)
"""Errors whose message says what went wrong without their type's name."""


class CommandParser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line: ``PROG: error: MESSAGE (PROG --help)``."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f"{self.prog}: error: {shown(message)} (see {self.prog} --help)\n")


def error_text(e: BaseException) -> str:
    """What went wrong, in words: the file's name first where ``e`` carries one (OSError)."""
    if isinstance(e, OSError) and e.filename is not None and e.strerror:
        names = f"{e.filename} -> {e.filename2}" if e.filename2 is not None else f"{e.filename}"
        return f"{names}: {e.strerror}"
    if isinstance(e, MemoryError):
        return f"not enough memory{': ' + str(e) if str(e) else ''}"
    if isinstance(e, RecursionError):
        return f"input nested too deeply to read ({e})"
    if isinstance(e, json.JSONDecodeError):
        return f"not valid JSON: {e}"
    if isinstance(e, _SAID) and str(e):
        return str(e)
    return f"{type(e).__name__}: {e}" if str(e) else type(e).__name__


def exit_status(e: BaseException) -> int:
    """2 for bad usage or input (see the module notes), else 1."""
    return EXIT_USAGE if isinstance(e, (UsageError, *_PATH_ERRORS)) else EXIT_RUN_ERROR


def _graph_errors(e: BaseException) -> int | None:
    """Print a graph's located problems (``file:line:col: message`` each) and their count."""
    from flowtact.errors import GraphFileError

    if not isinstance(e, GraphFileError):
        return None
    for line in str(e).splitlines():
        print(shown(line), file=sys.stderr)
    n = len(e.errors)
    print(f"flowtact: {n} problem{'s' if n != 1 else ''} in the graph", file=sys.stderr)
    return EXIT_USAGE


def _system_exit(e: SystemExit) -> int:
    """The status a ``sys.exit`` asked for (argparse has printed its own line already)."""
    if e.code is None or isinstance(e.code, int):
        return int(e.code or 0)
    print(shown(e.code), file=sys.stderr)
    return EXIT_RUN_ERROR


def run_command(body: Callable[[], int | None], *, prog: str = "flowtact", debug: bool | None = None) -> int:
    """Run a command's ``body`` and return its exit status; what it raises becomes one line on
    stderr and a status (2 bad usage or input, 1 failed, 130 interrupted). ``debug`` (default:
    ``FLOWTACT_DEBUG``) adds the traceback after the line."""
    debug = debug_enabled() if debug is None else debug
    try:
        return int(body() or 0)
    except SystemExit as e:
        return _system_exit(e)
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:  # the reader left (flowtact blocks | head): nothing went wrong here
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at exit
        return 0
    except Exception as e:  # noqa: BLE001 — every failure: one line naming it, the traceback with --debug
        status = _graph_errors(e)
        if status is not None:
            return status
        line = f"{prog}: error: {shown(error_text(e), limit=MAX_ERROR_CHARS)}"
        status = exit_status(e)
        if status == EXIT_USAGE and not debug:  # the input's fault: no traceback to offer
            print(line, file=sys.stderr)
        else:
            print_error(line, e, debug)
        return status
