"""``flowtact sim DEVICE [options]``: run an emulated device on a pseudo-terminal.

Emulators are found through the ``flowtact.emulators`` entry-point group (name -> a ``main(argv)``
that takes the remaining arguments), so a domain ships its device's emulator beside its blocks.
"""

from __future__ import annotations

from collections.abc import Sequence
from importlib.metadata import entry_points
from typing import Any

from flowtact.commands import Command
from flowtact.console.command import run_command
from flowtact.errors import UsageError

__all__ = ["COMMAND", "GROUP", "main"]

GROUP = "flowtact.emulators"


def main(argv: Sequence[str]) -> int:
    """Dispatch ``flowtact sim DEVICE ...`` to the device's emulator; its exit status (an unknown
    device: one line, 2), through :func:`flowtact.console.command.run_command` like every command."""
    return run_command(lambda: _dispatch(list(argv)), prog="flowtact sim")


def _help(emulators: dict[str, Any]) -> str:
    """``flowtact sim --help``: what it does, each device with its one-line summary, an example."""
    from flowtact.commands import entry_point_summary

    width = max((len(n) for n in emulators), default=0) + 2
    devices = "\n".join(f"  {n:<{width}}{entry_point_summary(ep)}" for n, ep in sorted(emulators.items()))
    return (
        f"usage: flowtact sim {{{','.join(sorted(emulators))}}} [options]\n\n"
        "Run an emulated device, so graphs and tests run without the hardware: it prints the port to\n"
        "connect to (PORT <path>) and serves until Ctrl-C or SIGTERM.\n\n"
        f"devices:\n{devices}\n\n"
        "a device's own options: flowtact sim DEVICE --help\n\n"
        "examples:\n"
        "  flowtact sim exo                        # the exoskeleton on a pseudo-terminal; prints PORT\n"
        "  flowtact sim exo --link ~/exo --seed 3  # at a fixed path, another user's grasp"
    )


def _dispatch(argv: list[str]) -> int:
    emulators = {ep.name: ep for ep in entry_points(group=GROUP)}
    if not argv or argv[0] in ("-h", "--help"):
        print(_help(emulators))
        return 0
    if argv[0] not in emulators:
        raise UsageError(f"unknown device '{argv[0]}'; devices: {', '.join(sorted(emulators))}")
    return int(emulators[argv[0]].load()(argv[1:]) or 0)


COMMAND = Command(main=main)
"""``flowtact sim``: parses its own arguments (entry-point group ``flowtact.commands``)."""
