"""The one progress bar of every long command (run, bench, sweep, training): a rich bar on a
terminal, nothing anywhere else (rich is imported only when a bar is shown). What each command
prints where there is no terminal (a line per suite, per N runs) is its own."""

from __future__ import annotations

import sys
from typing import Any, TextIO

__all__ = ["TerminalBar"]


class TerminalBar:
    """``label``, bar, done/total (with ``count``), elapsed time and a description, on ``stream``.

    Shown when ``show`` and the stream is a terminal (``force`` overrides the terminal test);
    otherwise every call does nothing, so callers need no branches of their own.
    """

    def __init__(self, label: str, total: float | None, *, show: bool = True, count: bool = True,
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
        """rich's ``Progress.update`` fields: ``advance``, ``completed``, ``total``, ``description``."""
        if self._bar is not None:
            self._bar.update(self._task, **fields)

    def print(self, text: str) -> None:
        """``text`` on its own line above the bar (only when the bar is shown)."""
        if self._bar is not None:
            self._bar.console.print(text, markup=False, highlight=False)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.stop()

    def __enter__(self) -> TerminalBar:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
