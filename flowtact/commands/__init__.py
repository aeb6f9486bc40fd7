"""Sub-commands of ``flowtact``: what one is (:class:`Command`) and where they are found.

Every command, the built-in ones included, is a :class:`Command` named in the entry-point group
``flowtact.commands`` (``name = "package.module:COMMAND"``); an installed package adds a command
the same way. ``flowtact --help`` lists each with the first sentence of its module's docstring,
read without importing it; only the command being run is imported.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

__all__ = ["GROUP", "Command", "entry_point_summary", "find_commands", "one_line_summary"]

GROUP = "flowtact.commands"
"""The entry-point group every command is named in."""


@dataclass(frozen=True)
class Command:
    """One ``flowtact NAME`` command: either ``add_arguments`` + ``run(args)`` (``flowtact`` parses
    its arguments, its ``--help`` and usage errors as every command's), or ``main(argv)`` alone (a
    command that parses its own arguments, e.g. one dispatching further). Either returns the exit
    status (None: 0) and raises what went wrong (:func:`flowtact.console.command.run_command` says it)."""

    run: Callable[[argparse.Namespace], int | None] | None = None
    add_arguments: Callable[[argparse.ArgumentParser], None] | None = None
    main: Callable[[Sequence[str]], int | None] | None = None
    description: str | None = None
    """The command's ``--help`` text (default: its help line)."""
    epilog: str | None = None
    """Shown after the options, as written (examples)."""
    check: Callable[[argparse.Namespace], str | None] | None = None
    """A usage problem that the arguments together make, or None (``--from`` after ``--to``)."""

    def __post_init__(self) -> None:
        if (self.run is None) == (self.main is None):
            raise TypeError("a Command has either run(args) (with add_arguments) or main(argv)")


def find_commands() -> dict[str, Any]:
    """The commands declared in the ``flowtact.commands`` group: name -> entry point (not loaded)."""
    from importlib.metadata import entry_points

    return {ep.name: ep for ep in entry_points(group=GROUP)}


def load_command(ep: Any) -> Command:
    """The :class:`Command` an entry point names; a TypeError naming it when it names something else."""
    obj = ep.load()
    if not isinstance(obj, Command):
        raise TypeError(f"entry point {ep.name} = {ep.value} ({GROUP}) is not a flowtact.commands.Command")
    return obj


def entry_point_summary(ep: Any) -> str:
    """An entry point's one-line summary for help lists: the first sentence of its module's
    docstring as plain text (reST markup gone, :func:`flowtact.help.rst_text.inline_text`), without a
    leading ``flowtact NAME ...:`` or trailing ``: flowtact NAME`` that repeats the name beside
    it. Cheap: the module is parsed, not imported."""
    import ast
    import importlib.util
    from pathlib import Path

    from flowtact.help.rst_text import inline_text

    try:
        spec = importlib.util.find_spec(ep.value.partition(":")[0])
    except (ImportError, ValueError):
        spec = None
    if spec is None or spec.origin is None:
        return "(not importable)"
    try:
        doc = ast.get_docstring(ast.parse(Path(spec.origin).read_text()))
    except (OSError, SyntaxError, ValueError):
        doc = None
    return one_line_summary(inline_text(doc or ep.value))


def one_line_summary(text: str) -> str:
    """The first sentence of ``text`` (its first paragraph joined), without a ``flowtact ...:``
    prefix or a ``: flowtact ...`` suffix, its first letter lower-cased as argparse's own help is."""
    import re

    para = " ".join(text.strip().split("\n\n", 1)[0].split())
    first = re.split(r"(?<=[a-z0-9)])\. ", para, maxsplit=1)[0].rstrip(".")
    first = re.sub(r"^flowtact [\w-]+[^:]*:\s*", "", first)
    first = re.sub(r":\s*flowtact [\w-]+[^:]*$", "", first)
    if first[:1].isupper() and first[1:2].islower():
        first = first[0].lower() + first[1:]
    return first
