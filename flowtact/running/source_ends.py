"""Runs over played-back files: the files' span is the default duration, and a run that goes past a
file's end says so, once on stderr and in its summary.

After its end a replay emits nothing (no held last value, no zeros): downstream blocks see empty
chunks, event streams keep their watermark moving, and the summary's per-second rates are over the
whole run, which is why the notice names the end.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any

from flowtact.running.compile import CompiledGraph

__all__ = ["EndWatch", "default_duration"]


def default_duration(plan: CompiledGraph, asked: float | None) -> float | None:
    """The run's duration: ``asked`` (``--duration``), else the end of the last played-back file,
    else the graph's ``duration_s``, else None (until interrupted)."""
    if asked is not None:
        return asked
    ends = [e for e in plan.ends.values() if e > 0]
    return max(ends) if ends else plan.graph.duration_s


class EndWatch:
    """Says, once per source, when a run has gone past that source's end (``replay 'sensor' ended at
    3 s; the run continues to 10 s with no input from it``)."""

    def __init__(
        self, plan: CompiledGraph, duration_s: float | None, warn: Callable[[str], None] | None = None
    ) -> None:
        self.plan = plan
        self.duration_s = duration_s
        self.warn = warn or (lambda text: print(f"flowtact: {text}", file=sys.stderr, flush=True))
        self.said: dict[str, str] = {}

    def _notice(self, node: str, end: float) -> str:
        cls = self.plan.graph.nodes[node].cls.name
        until = f"to {self.duration_s:g} s" if self.duration_s is not None else "until stopped"
        return f"{cls} '{node}' ended at {end:g} s; the run continues {until} with no input from it"

    def check(self, now: float) -> None:
        """Warn about every source whose end ``now`` has passed (each only once)."""
        for node, end in self.plan.ends.items():
            if (
                node not in self.said
                and now > end + 1e-9
                and (self.duration_s is None or self.duration_s > end + 1e-9)
            ):
                self.said[node] = self._notice(node, end)
                self.warn(self.said[node])

    def progress(
        self, inner: Callable[[float, float | None], None] | None
    ) -> Callable[[float, float | None], None]:
        """A progress callback that also checks the ends, then calls ``inner``."""

        def call(now: float, total: float | None) -> None:
            self.check(now)
            if inner is not None:
                inner(now, total)

        return call

    def finish(self, summary: Any) -> None:
        """After the run: say what was not said yet; the notices, and the ``record:`` entries left
        out (:attr:`CompiledGraph.record_notes`), go in the summary's notes."""
        self.check(summary.duration_s)
        summary.notes.extend([*self.plan.record_notes, *self.said.values()])
