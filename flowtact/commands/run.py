"""``flowtact run GRAPH``: run a graph.

In real time (default) or as fast as possible (``--fast``), in worker processes (one per process
group) or all in this one (``--inproc``); record streams to HDF5.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import json
import signal
import sys
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from flowtact.commands import Command
from flowtact.commands.graph_args import add_graph_arguments, load_graph_plan
from flowtact.errors import UsageError
from flowtact.graphfile.deployment import MAX_STARTUP_S
from flowtact.inputs.limits import (
    MAX_TICK_S,
    MIN_TICK_S,
    cli_duration_seconds,
    cli_float,
    cli_int,
    cli_tick_seconds,
)

if TYPE_CHECKING:
    from flowtact.console.terminal_bar import TerminalBar

__all__ = ["COMMAND", "RUN_EXAMPLES", "run_progress"]

RUN_EXAMPLES = """examples:
  flowtact run touch                                   # a shipped graph by name, in real time
  flowtact run graphs/touch.yaml --fast --duration 3 --record touch.h5
  flowtact run touch.h5 --fast                         # re-run what a recording was made with
  flowtact run touch --replay sensor=touch.h5 --fast   # feed a recorded sensor back in
  flowtact run graphs/slip.yaml --set sa1.n=200 --set sa1_stim.max_units=200 --fast
  flowtact run envelope.yaml --allow-module envelope   # a graph using your own block (envelope.py)
  flowtact run touch --view sensor.force sa1.spikes    # watch streams live in a browser (docs/view.md)"""


def add_arguments(run: argparse.ArgumentParser) -> None:
    add_graph_arguments(run)
    run.add_argument(
        "--duration",
        type=cli_duration_seconds,
        metavar="S",
        help="graph seconds to run (default: the end of the --replay'd files, else the graph's duration_s)",
    )
    run.add_argument(
        "--fast", action="store_true", help="run as fast as possible (virtual clock), not in real time"
    )
    run.add_argument("--record", metavar="FILE.h5", help="record the graph's record: streams to HDF5")
    run.add_argument(
        "--tick",
        type=cli_tick_seconds,
        metavar="S",
        help=f"clock tick, {MIN_TICK_S:g} to {MAX_TICK_S:g} s (default 1 s with --fast, 5 ms real time); "
        "a run takes at most 1e9 ticks",
    )
    run.add_argument(
        "--startup-s",
        type=cli_float(0.0, MAX_STARTUP_S, "s", lo_open=True),
        metavar="S",
        help="how long a worker process may start up without progress (importing, compiling, warming "
        "up, opening devices are progress) before the run gives up on it; replaces every process "
        "group's startup_s (default 60 s, 120 s on another host)",
    )
    run.add_argument(
        "--inproc",
        action="store_true",
        help="run every node in this process (default: one worker process per process group)",
    )
    run.add_argument(
        "--view",
        nargs="*",
        metavar="STREAM",
        help="draw streams live in a browser: serve a page on 127.0.0.1 and print its address (with "
        "a token); STREAM is NODE.PORT, recorded or not (none named: the graph's record: streams); "
        "needs the view extra (docs/view.md)",
    )
    run.add_argument(
        "--view-port",
        type=cli_int(1, 65535),
        default=0,
        metavar="PORT",
        help="the --view page's port on 127.0.0.1 (default: a free one)",
    )
    run.add_argument("--json", action="store_true", help="print the final summary as JSON")
    run.add_argument(
        "--quiet", action="store_true", help="no live view, progress or summary (errors still print)"
    )


def run(args: argparse.Namespace) -> int:
    from flowtact.console.terminal_bar import TerminalBar
    from flowtact.running.launch import run_compiled
    from flowtact.runtime.clock import process_started_at
    from flowtact.runtime.live import LiveView

    plan = load_graph_plan(args)
    quiet = args.quiet or args.json
    live = LiveView(enabled=not quiet and not args.inproc)
    bar = TerminalBar("run", None, show=not quiet and not live.enabled, count=False)
    progress = run_progress(bar)

    def on_term(_signum: int, _frame: Any) -> None:
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, on_term)
    view = open_view(plan, args)
    try:
        with view or contextlib.nullcontext(), live:
            summary = run_compiled(
                plan,
                duration_s=args.duration,
                fast=args.fast,
                inproc=args.inproc,
                record=args.record,
                tick_s=args.tick,
                progress=progress,
                live=live if live.enabled else None,
                argv=["flowtact", *sys.argv[1:]],
                startup_s=args.startup_s,
                launched_at=process_started_at(),
                view=view,
            )
    finally:
        bar.close()
    if args.json:
        print(json.dumps(summary.to_dict(), indent=2))
    elif not args.quiet:
        print(summary.format())
        if args.record:
            print(f"  recorded {', '.join(f'{n}.{p}' for n, p in plan.record)} -> {args.record}")
    return 0


def open_view(plan: Any, args: argparse.Namespace) -> Any:
    """The run's :class:`~flowtact.view.session.ViewSession` (``--view``), or None."""
    if args.view is None:
        if args.view_port:
            raise UsageError("--view-port: only with --view")
        return None
    if importlib.util.find_spec("aiohttp") is None:
        raise UsageError("--view needs aiohttp: pip install 'flowtact[view]'")
    from flowtact.view.session import ViewSession

    return ViewSession(plan, args.view, port=args.view_port)


def run_progress(bar: TerminalBar) -> Callable[[float, float | None], None]:
    """The run's ``progress(now, total)`` on ``bar``: graph seconds done of the run's (Ctrl-C stops
    a run without an end), at most 5 updates a second."""
    last = [-1.0]

    def progress(now: float, total: float | None) -> None:
        if not bar.shown or time.monotonic() - last[0] < 0.2:
            return
        last[0] = time.monotonic()
        text = f"{now:.1f}/{total:.1f} s" if total else f"{now:.1f} s (Ctrl-C stops)"
        bar.update(total=total or None, completed=min(now, total) if total else now, description=text)

    return progress


COMMAND = Command(
    run=run,
    add_arguments=add_arguments,
    description="Run a graph: in real time (default) or as fast as possible (--fast), in worker "
    "processes (one per process group) or all in this one (--inproc); record streams to HDF5.",
    epilog=RUN_EXAMPLES,
)
