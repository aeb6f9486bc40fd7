"""What the supervisor tells about numba compiling in its workers, from their heartbeats.

A first run after an install compiles kernels for tens of seconds before a worker is ready: the
run says so (once per worker, then how long it took). That compiling keeps the worker's start-up
window open is the supervisor's own rule (every start-up report restarts it: see supervisor.py). A kernel compiled after the start is a real-time stall the warm-up
missed (flowtact/runtime/warm_up.py): that is said too, never left to show up as latency.
"""

from __future__ import annotations

from collections.abc import Callable

from flowtact.runtime.protocol import Beat, Ready

__all__ = ["CompileNotices"]


class CompileNotices:
    """Per worker: announce compiling, time it, and notice compiling after the start."""

    def __init__(self, warn: Callable[[str], None]) -> None:
        self.warn = warn
        self.said: set[str] = set()
        self.late_said: set[str] = set()

    def on_beat(self, proc: str, what: str, running: bool, beat: Beat) -> None:
        """A heartbeat of worker ``proc`` (``what`` describes it) arrived."""
        current = beat.compiling
        if current is None:
            return
        if not running and proc not in self.said:
            self.said.add(proc)
            node = f" for {beat.node}" if beat.node else ""
            self.warn(
                f"{what}: compiling kernels{node} (first run after an install or upgrade; "
                "numba caches them for the next runs)..."
            )
        elif running and proc not in self.late_said:
            self.late_said.add(proc)
            node = f" in node '{beat.node}'" if beat.node else ""
            self.warn(
                f"{what}: compiling kernel {current}{node} after the start: the run stalls meanwhile "
                "(the warm-up missed this signature; please report it)"
            )

    def on_ready(self, what: str, msg: Ready) -> None:
        """A worker (``what`` describes it) said ready: tell how long its compiling took, if it did."""
        n = msg.compiled
        if n:
            self.warn(f"{what}: {n} kernel{'s' if n > 1 else ''} compiled in {msg.compile_s:.1f} s")
