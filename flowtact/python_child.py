"""The command line of every Python child flowtact starts (workers, emulators, benchmark parts).

``python -m pkg`` and ``python script.py`` put the working directory (or the script's folder)
first on the child's import path, so a ``msgpack.py`` lying in the folder a user runs from would be
imported, and run, inside the child. ``-P`` (Python 3.11+) leaves it off; ``PYTHONPATH`` is still
honoured, being the user's own choice. ``-P`` rather than ``PYTHONSAFEPATH=1`` in the child's
environment: the variable would be inherited by every program the child starts in turn (a block's
own helper scripts would lose their folder), the flag holds for this one interpreter only.
"""

from __future__ import annotations

import sys

__all__ = ["python_command"]


def python_command(*args: str) -> list[str]:
    """``[python, -P, *args]``: this interpreter, without the working directory on its import path."""
    return [sys.executable, "-P", *args]
