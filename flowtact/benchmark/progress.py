"""Progress of a bench run: a bar on a terminal (rich), one line per suite otherwise."""

from __future__ import annotations

import sys
from typing import Any, TextIO

__all__ = ["Progress"]


class Progress:
    """``begin(name)``, ``step(text)`` and ``end(name, status, line)`` for each suite of a run."""

    def __init__(self, total: int, stream: TextIO | None = None, bar: bool | None = None) -> None:
        self.stream = stream or sys.stdout
        self.total = total
        self.done = 0
        self._bar: Any = None
        if bar if bar is not None else self.stream.isatty():
            from rich.console import Console
            from rich.progress import (
                BarColumn,
                MofNCompleteColumn,
                TextColumn,
                TimeElapsedColumn,
            )
            from rich.progress import (
                Progress as RichProgress,
            )

            self._bar = RichProgress(
                TextColumn("[bold]{task.fields[suite]:<18}"),
                BarColumn(),
                MofNCompleteColumn(),
                TimeElapsedColumn(),
                TextColumn("{task.description}"),
                console=Console(file=self.stream),
            )
            self._task = self._bar.add_task("", total=total, suite="")

    def __enter__(self) -> Progress:
        if self._bar:
            self._bar.start()
        return self

    def __exit__(self, *exc: object) -> None:
        if self._bar:
            self._bar.stop()

    def begin(self, name: str) -> None:
        if self._bar:
            self._bar.update(self._task, suite=name, description="starting")

    def step(self, text: str) -> None:
        if self._bar:
            self._bar.update(self._task, description=text[:60])

    def end(self, line: str) -> None:
        """The suite's one-line outcome (printed above the bar on a terminal)."""
        self.done += 1
        text = f"[{self.done}/{self.total}] {line}"
        if self._bar:
            self._bar.console.print(text, markup=False, highlight=False)
            self._bar.update(self._task, completed=self.done, description="")
        else:
            print(text, file=self.stream, flush=True)
