"""The progress bar of long commands: a rich bar on a terminal, nothing anywhere else (rich is
imported only when a bar is shown)."""

from __future__ import annotations

import sys
from typing import Any, TextIO

__all__ = ["TerminalBar"]


class TerminalBar:
    """``label``, bar, done/total (with ``count``), elapsed time and a description, on ``stream``.

    Shown when ``show`` and the stream is a terminal (``force`` overrides the terminal test);
    otherwise every call does nothing, so callers need no branches of their own.
    """

    def __init__(self, label: str, total: float, *, show: bool = True, count: bool = True,
                 stream: TextIO | None = None, force: bool | None = None, description: str = "") -> None:  # fmt: skip
        self._bar: Any = None
        stream = stream or sys.stderr
        if show and (force if force is not None else stream.isatty()):
            from rich.console import Console
            from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

            columns = [TextColumn(f"[bold]{label}"), BarColumn(), *([MofNCompleteColumn()] if count else [])]
            self._bar = Progress(*columns, TimeElapsedColumn(), TextColumn("{task.description}"),
                                 console=Console(file=stream))  # fmt: skip
            self._task = self._bar.add_task(description, total=total)
            self._bar.start()

    @property
    def shown(self) -> bool:
        return self._bar is not None

    def update(self, **fields: Any) -> None:
        """rich's ``Progress.update`` fields: ``advance``, ``completed``, ``description``."""
        if self._bar is not None:
            self._bar.update(self._task, **fields)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.stop()

    def __enter__(self) -> TerminalBar:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
