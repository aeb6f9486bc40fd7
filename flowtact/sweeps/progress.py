"""A sweep's progress: a bar with done / failed / remaining on a terminal, else a line per N runs."""

from __future__ import annotations

import sys
from typing import TextIO

from flowtact.console.terminal_bar import TerminalBar

__all__ = ["SweepProgress"]


class SweepProgress:
    """``row(ok)`` after each run; a context manager around the sweep."""

    def __init__(self, total: int, stream: TextIO | None = None, bar: bool | None = None,
                 every: int | None = None, enabled: bool = True) -> None:  # fmt: skip
        self.stream = stream or sys.stderr
        self.total, self.done, self.failed = total, 0, 0
        self.enabled = enabled
        self.every = every or max(1, total // 10)
        self._bar = TerminalBar(
            "sweep", total, show=enabled, stream=self.stream, force=bar, description=self._text()
        )

    def _text(self) -> str:
        return f"{self.done} done, {self.failed} failed, {self.total - self.done} remaining"

    def __enter__(self) -> SweepProgress:
        return self

    def __exit__(self, *exc: object) -> None:
        self._bar.close()

    def row(self, ok: bool) -> None:
        """One run finished (``ok`` False: it failed)."""
        self.done += 1
        self.failed += not ok
        if self._bar.shown:
            self._bar.update(completed=self.done, description=self._text())
        elif self.enabled and (self.done % self.every == 0 or self.done == self.total):
            print(f"sweep: {self._text()}", file=self.stream, flush=True)
