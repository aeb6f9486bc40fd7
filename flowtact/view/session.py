"""``--view``: the streams a run shows in the browser, the plan that ships them, the server's life.

A viewed stream need not be recorded to the file: it is added to the plan's ``record:`` list (the
graph recompiled, so a stream nothing consumed is computed) for the runtime only, while the file
keeps the graph's own list (:func:`flowtact.running.launch.run_compiled`).
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any

from flowtact.errors import UsageError
from flowtact.graphfile.located import Loc
from flowtact.inputs.safe_text import shown
from flowtact.running.compile import CompiledGraph, compile_graph

__all__ = ["ViewSession", "chosen_streams"]

Stream = tuple[str, str]


def chosen_streams(plan: CompiledGraph, names: Sequence[str]) -> list[Stream]:
    """The streams ``--view NAME ...`` names (none: the graph's recorded ones), each checked:
    :class:`~flowtact.errors.UsageError` naming the first that is no output of the graph."""
    if not names:
        if not plan.record:
            raise UsageError(
                "--view: the graph records no stream; name the streams to view (--view NODE.PORT ...)"
            )
        return list(plan.record)
    out: list[Stream] = []
    for name in names:
        node, dot, port = name.partition(".")
        if not dot or (node, port) not in plan.specs:
            ports = [p for (n, p) in plan.specs if n == node]
            if not dot:
                have = "expected NODE.PORT" + (f", e.g. {node}.{ports[0]}" if ports else "")
            elif node in plan.graph.nodes:
                have = f"'{node}' has outputs {', '.join(ports) or 'none'}"
            else:
                have = f"no node '{shown(node, limit=80)}'"
            raise UsageError(f"--view {shown(name, limit=120)}: not a stream of the graph ({have})")
        if (node, port) not in out:
            out.append((node, port))
    return out


class ViewSession:
    """The view of one run: its streams, buffers and server (the server starts at the first write)."""

    def __init__(
        self,
        plan: CompiledGraph,
        names: Sequence[str],
        port: int = 0,
        say: Callable[[str], None] | None = None,
    ) -> None:
        from flowtact.view.buffers import ViewBuffers

        self.streams = chosen_streams(plan, names)
        self.port = port
        self.say = say or (lambda text: print(text, file=sys.stderr, flush=True))
        self.buffers = ViewBuffers({f"{n}.{p}": plan.specs[(n, p)] for n, p in self.streams})
        self.graph = plan.graph.name
        self.server: Any = None
        self._listen().close()  # a port in use is a usage error now, before the run starts

    def _listen(self) -> Any:
        """The listening socket; made again at :meth:`start` (after the forks: a forked worker must
        not hold a copy of it)."""
        from flowtact.view.server import listen

        try:
            return listen(self.port)
        except OSError as e:
            raise UsageError(
                f"--view-port {self.port}: cannot listen on 127.0.0.1:{self.port} ({e.strerror or e})"
            ) from None

    def plan_for(self, plan: CompiledGraph) -> CompiledGraph:
        """``plan`` with the viewed streams recorded too (recompiled when it lacked any)."""
        extra = [s for s in self.streams if s not in plan.record]
        if not extra:
            return plan
        g = plan.graph
        graph = replace(g, record=[*g.record, *((n, p, Loc("--view")) for n, p in extra)])
        out = compile_graph(graph)
        missing = [f"{n}.{p}" for n, p in extra if (n, p) not in out.record]
        if missing:
            raise UsageError(f"--view {missing[0]}: the stream carries no data in this run")
        return out

    def sink(self, inner: Any, recorded: Sequence[str]) -> Any:
        """The sink the executor writes to: ``recorded`` streams to ``inner``, viewed ones here."""
        from flowtact.view.tee import TeeSink

        return TeeSink(inner, recorded, self.buffers, on_first=self.start)

    def start(self) -> None:
        """Start serving and print the page's address (called once workers are forked)."""
        from flowtact.view.server import ViewServer

        if self.server is not None:
            return
        try:
            sock = self._listen()
        except UsageError as e:  # taken since the check: rare; the run goes on without the view
            self.say(f"flowtact: no view: {e}")
            return
        self.server = ViewServer(self.buffers, self.graph, sock)
        self.server.start()
        self.say(f"flowtact: view at {self.server.url}")

    def close(self, reason: str = "the run ended") -> None:
        """Tell the browsers the run ended, stop serving (the page stays, saying so)."""
        if self.server is not None:
            self.server.stop(reason)

    def __enter__(self) -> ViewSession:
        return self

    def __exit__(self, exc_type: Any, exc: BaseException | None, tb: Any) -> None:
        if exc is None:
            self.close()
        elif isinstance(exc, KeyboardInterrupt):
            self.close("the run was stopped (Ctrl-C)")
        else:
            self.close(f"the run failed: {exc}")
