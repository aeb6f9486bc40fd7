# PYTHON_ARGCOMPLETE_OK  (shell completion: eval "$(register-python-argcomplete flowtact)")
"""The ``flowtact`` command: run, validate, draw and document graphs; list blocks; plot recordings.

Every command, the built-in ones included, is a :class:`flowtact.commands.Command` found through
the entry-point group ``flowtact.commands`` (:mod:`flowtact.commands`); only the one being run is
imported. Every command fails the same way (:func:`flowtact.console.command.run_command`): ONE line on
stderr naming the place (``file:line:col``, the flag, or the file), control characters escaped,
no traceback unless ``--debug`` (``flowtact --debug CMD ...`` or ``FLOWTACT_DEBUG=1``). Exit status:

- 0: done;
- 2: bad usage or bad input, refused before the work starts: an unknown command or flag, a flag
  value out of its documented range (:mod:`flowtact.inputs.limits`), a graph's problems, a file the user
  named that is missing, a folder, unreadable or not what was asked for;
- 1: the command ran and failed: a block failed (its node named), a worker died, memory ran out;
- 130: interrupted.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
from collections.abc import Mapping, Sequence
from typing import Any

from flowtact.commands import Command, entry_point_summary, find_commands, load_command, one_line_summary
from flowtact.commands.graph_args import add_allow_module
from flowtact.console.command import CommandParser, run_command

__all__ = ["add_allow_module", "build_parser", "entry_point_summary", "main", "one_line_summary"]

DEBUG_HELP = "on failure, print the full Python traceback after the error (also: FLOWTACT_DEBUG=1)"


def build_parser(
    loaded: Mapping[str, Command] | None = None, commands: Mapping[str, Any] | None = None
) -> argparse.ArgumentParser:
    """The ``flowtact`` parser: one sub-parser per command of ``commands`` (default: the entry-point
    group); those in ``loaded`` with their own arguments, the others listed by name and help line
    only. ``loaded`` None: every command loaded (the whole parser, for completion and tests)."""
    from flowtact.help.rst_text import inline_text

    commands = find_commands() if commands is None else commands
    if loaded is None:
        loaded = {name: load_command(ep) for name, ep in commands.items()}
    p = CommandParser(
        prog="flowtact",
        description=inline_text(__doc__.splitlines()[0]),
        epilog="Each command's own options and examples: flowtact COMMAND --help. Shell completion: "
        'eval "$(register-python-argcomplete flowtact)" (see the README).',
    )
    p.add_argument("--version", action="version", version=f"flowtact {_version()}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, ep in commands.items():
        help_line = entry_point_summary(ep)
        cmd = loaded.get(name)
        if cmd is None or cmd.main is not None:  # not loaded, or parses its own arguments
            sp = sub.add_parser(name, help=help_line, add_help=False)
            sp.add_argument("args", nargs=argparse.REMAINDER)
            continue
        sp = sub.add_parser(
            name,
            help=help_line,
            description=cmd.description or help_line[:1].upper() + help_line[1:] + ".",
            epilog=cmd.epilog,
            formatter_class=argparse.RawDescriptionHelpFormatter if cmd.epilog else argparse.HelpFormatter,
        )
        if cmd.add_arguments is not None:
            cmd.add_arguments(sp)
        sp.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help=DEBUG_HELP)
    p.add_argument("--debug", action="store_true", help=DEBUG_HELP)
    return p


def _version() -> str:
    from flowtact import __version__

    return __version__


def _chosen(argv: Sequence[str], commands: Mapping[str, Any]) -> str | None:
    """The command ``argv`` names: its first word after an optional leading ``--debug``."""
    words = argv[1:] if argv[:1] == ["--debug"] else argv
    return words[0] if words and words[0] in commands else None


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``flowtact`` command: its exit status (see the module notes)."""
    from flowtact.console.debug import debug_enabled

    as_program = argv is None  # the process's own command line: its exit status is ours to keep
    argv = list(sys.argv[1:] if argv is None else argv)
    commands = find_commands()
    completing = as_program and "_ARGCOMPLETE" in os.environ
    name = _chosen(argv, commands)
    loaded: dict[str, Command] = {}
    if completing:  # the shell asks for completions: every command's arguments, unloadable ones left out
        for other, ep in commands.items():
            try:
                loaded[other] = load_command(ep)
            except Exception:  # noqa: BLE001 — a broken plugin only loses its completions
                continue
    elif name is not None:
        status = run_command(
            lambda: loaded.update({name: load_command(commands[name])}), prog=f"flowtact {name}"
        )
        if status:
            return _decided(status, as_program)
    cmd = loaded.get(name) if name else None
    if cmd is not None and cmd.main is not None and not completing:
        return _decided(_own_argv(cmd, name, argv), as_program)  # type: ignore[arg-type]
    parser = build_parser(loaded, commands)
    if completing:
        import argcomplete

        argcomplete.autocomplete(parser)
    args = parser.parse_args(argv)
    cmd = loaded[args.command]
    problem = cmd.check(args) if cmd.check is not None else None
    if problem:
        parser.error(problem)
    assert cmd.run is not None
    return _decided(run_command(lambda: cmd.run(args), debug=debug_enabled(args.debug)), as_program)


def _own_argv(cmd: Command, name: str, argv: list[str]) -> int:
    """Run a command that parses its own arguments: ``main(argv after NAME)``; ``flowtact --debug
    NAME ...`` sets ``FLOWTACT_DEBUG`` while it runs (the command reads it)."""
    from flowtact.console.debug import ENV

    debug = argv[:1] == ["--debug"]
    rest = argv[2:] if debug else argv[1:]
    before = os.environ.get(ENV)
    if debug:
        os.environ[ENV] = "1"
    try:
        assert cmd.main is not None
        return run_command(lambda: cmd.main(rest), prog=f"flowtact {name}")
    finally:  # main() called in process leaves the environment as it found it
        if debug and before is None:
            del os.environ[ENV]
        elif debug:
            os.environ[ENV] = before  # type: ignore[assignment]


def _decided(status: int, as_program: bool) -> int:
    """``status``, final: as the program, a Ctrl-C arriving from here on (while the interpreter
    exits: threads joined, files closed) is ignored, so a finished run's 0 does not become -2
    (killed by SIGINT) after its full summary. Called in-process (``main([...])``), nothing changes."""
    if as_program and threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    return status


if __name__ == "__main__":
    sys.exit(main())
