"""The command line of every Python child flowtact starts (workers, emulators, benchmark parts).

``python -m pkg`` and ``python script.py`` put the working directory (or the script's folder)
first on the child's import path, so a ``msgpack.py`` lying in the folder a user runs from would be
imported, and run, inside the child. ``-P`` (Python 3.11+) leaves it off; ``PYTHONPATH`` is still
honoured, being the user's own choice. ``-P`` rather than ``PYTHONSAFEPATH=1`` in the child's
environment: the variable would be inherited by every program the child starts in turn (a block's
own helper scripts would lose their folder), the flag holds for this one interpreter only.
Children a library starts with a command line of its own (multiprocessing's fork server and
resource tracker, ``python -c ...``) get the variable instead, only while they start
(:func:`safe_path_env`).
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterator

__all__ = ["python_command", "safe_path_env"]


def python_command(*args: str) -> list[str]:
    """``[python, -P, *args]``: this interpreter, without the working directory on its import path."""
    return [sys.executable, "-P", *args]


@contextlib.contextmanager
def safe_path_env() -> Iterator[None]:
    """``PYTHONSAFEPATH=1`` in this process's environment for the block: Python children started
    meanwhile (by a library that builds their command itself) leave the working directory off
    their import path, as :func:`python_command`'s do. The environment is restored after."""
    old = os.environ.get("PYTHONSAFEPATH")
    os.environ["PYTHONSAFEPATH"] = "1"
    try:
        yield
    finally:
        if old is None:
            del os.environ["PYTHONSAFEPATH"]
        else:
            os.environ["PYTHONSAFEPATH"] = old
