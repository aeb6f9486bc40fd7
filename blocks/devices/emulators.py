"""``flowtact sim DEVICE [options]``: run an emulated device on a pseudo-terminal.

Emulators are found through the ``flowtact.emulators`` entry-point group (name -> a ``main(argv)``
that takes the remaining arguments), so a domain ships its device's emulator beside its blocks.
"""

from __future__ import annotations

from collections.abc import Sequence
from importlib.metadata import entry_points

from flowtact.command import run_command
from flowtact.errors import UsageError

__all__ = ["GROUP", "main"]

GROUP = "flowtact.emulators"


def main(argv: Sequence[str]) -> int:
    """Dispatch ``flowtact sim DEVICE ...`` to the device's emulator; its exit status (an unknown
    device: one line, 2), through :func:`flowtact.command.run_command` like every command."""
    return run_command(lambda: _dispatch(list(argv)), prog="flowtact sim")


def _dispatch(argv: list[str]) -> int:
    emulators = {ep.name: ep for ep in entry_points(group=GROUP)}
    usage = f"usage: flowtact sim {{{','.join(sorted(emulators))}}} [options]   (flowtact sim DEVICE --help)"
    if not argv or argv[0] in ("-h", "--help"):
        print(usage)
        return 0
    if argv[0] not in emulators:
        raise UsageError(f"unknown device '{argv[0]}'; devices: {', '.join(sorted(emulators))}")
    return int(emulators[argv[0]].load()(argv[1:]) or 0)
