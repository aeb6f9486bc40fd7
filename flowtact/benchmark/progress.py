"""Progress of a bench run: the one bar (:class:`flowtact.console.terminal_bar.TerminalBar`) on a terminal,
one line per suite otherwise."""

from __future__ import annotations

import sys
from typing import TextIO

from flowtact.console.terminal_bar import TerminalBar

__all__ = ["Progress"]


class Progress:
    """``begin(name)``, ``step(text)`` and ``end(line)`` for each suite of a run."""

    def __init__(self, total: int, stream: TextIO | None = None, bar: bool | None = None) -> None:
        self.stream = stream or sys.stdout
        self.total = total
        self.done = 0
        self.suite = ""
        self._bar = TerminalBar("bench", total, stream=self.stream, force=bar)

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: object) -> None:
        self._bar.close()

    def begin(self, name: str) -> None:
        self.suite = name
        self._bar.update(description=f"{name}: starting")

    def step(self, text: str) -> None:
        self._bar.update(description=f"{self.suite}: {text}"[:80])

    def end(self, line: str) -> None:
        """The suite's one-line outcome (printed above the bar on a terminal)."""
        self.done += 1
        text = f"[{self.done}/{self.total}] {line}"
        if self._bar.shown:
            self._bar.print(text)
            self._bar.update(completed=self.done, description="")
        else:
            print(text, file=self.stream, flush=True)
