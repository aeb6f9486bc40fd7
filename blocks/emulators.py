"""Run an emulated device on a pseudo-terminal: `flowtact sim exo [options]` (see `flowtact sim exo --help`)."""

from __future__ import annotations

import importlib
import sys
from collections.abc import Sequence

__all__ = ["EMULATORS", "main"]

#: Emulated devices: name -> "module:main" taking the remaining arguments.
EMULATORS = {"exo": "flowtact.blocks.exo_device:main"}


def main(argv: Sequence[str]) -> int:
    """Dispatch ``flowtact sim DEVICE ...`` to the device's emulator."""
    argv = list(argv)
    usage = f"usage: flowtact sim {{{','.join(EMULATORS)}}} [options]   (flowtact sim DEVICE --help)"
    if not argv or argv[0] in ("-h", "--help"):
        print(usage)
        return 0
    if argv[0] not in EMULATORS:
        print(f"{usage}\nflowtact sim: unknown device '{argv[0]}'", file=sys.stderr)
        return 2
    module, _, attr = EMULATORS[argv[0]].partition(":")
    return int(getattr(importlib.import_module(module), attr)(argv[1:]) or 0)
