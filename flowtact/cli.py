# PYTHON_ARGCOMPLETE_OK  (shell completion: eval "$(register-python-argcomplete flowtact)")
"""The ``flowtact`` command: run, validate, draw and document graphs; list blocks; plot recordings.

Every command, the plugins' (``flowtact.commands``) included, fails the same way
(:func:`flowtact.console.command.run_command`): ONE line on stderr naming the place (``file:line:col``,
the flag, or the file), control characters escaped, no traceback unless ``--debug``
(``flowtact --debug CMD ...`` or ``FLOWTACT_DEBUG=1``). Exit status:

- 0: done;
- 2: bad usage or bad input, refused before the work starts: an unknown command or flag, a flag
  value out of its documented range (:mod:`flowtact.inputs.limits`), a graph's problems, a file the user
  named that is missing, a folder, unreadable or not what was asked for;
- 1: the command ran and failed: a block failed (its node named), a worker died, memory ran out;
- 130: interrupted.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from flowtact.console.command import EXIT_RUN_ERROR, CommandParser, run_command
from flowtact.errors import GraphFileError, UsageError
from flowtact.graphfile.deployment import MAX_STARTUP_S
from flowtact.inputs.limits import (
    MAX_TICK_S,
    MIN_TICK_S,
    cli_duration_seconds,
    cli_finite_seconds,
    cli_float,
    cli_tick_seconds,
)

__all__ = ["main"]


def _parser() -> argparse.ArgumentParser:
    from flowtact.help.rst_text import inline_text

    p = CommandParser(
        prog="flowtact",
        description=inline_text(__doc__.splitlines()[0]),
        epilog="Each command's own options and examples: flowtact COMMAND --help. Shell completion: "
        'eval "$(register-python-argcomplete flowtact)" (see the README).',
    )
    p.add_argument("--version", action="version", version=f"flowtact {_version()}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def graph_args(sp: argparse.ArgumentParser) -> None:
        graph = sp.add_argument(
            "graph", help="graph file (.yaml), a shipped graph name (touch, slip), or a recording (.h5)"
        )
        graph.completer = _complete_graph  # type: ignore[attr-defined]
        sp.add_argument(
            "--set",
            dest="overrides",
            action="append",
            default=[],
            metavar="NODE.PARAM=VALUE",
            help="override a node parameter (validated like the file); repeatable",
        )
        sp.add_argument(
            "--replay",
            dest="replays",
            action="append",
            default=[],
            metavar="NODE=FILE[:MAP]",
            help="play FILE (.h5 recording, .csv log, .npz) in place of NODE, on NODE's own output ports "
            "(names, records and edges unchanged). A .h5 feeds port P from stream NODE.P; a .csv from "
            "column P, or columns P[0], P[1], ... (or P.0, P_0); MAP overrides: "
            "'sensor=log.csv:r=g1,g2,g3,g4;ref=g0'. Without --duration the run ends at the file's "
            "end; see docs/your-own-data.md. Repeatable",
        )
        add_allow_module(sp)

    run = sub.add_parser(
        "run",
        help="run a graph",
        description="Run a graph: in real time (default) or as fast as possible (--fast), in worker "
        "processes (one per process group) or all in this one (--inproc); record streams to HDF5.",
        epilog=RUN_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    graph_args(run)
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
    run.add_argument("--json", action="store_true", help="print the final summary as JSON")
    run.add_argument(
        "--quiet", action="store_true", help="no live view, progress or summary (errors still print)"
    )

    worker = sub.add_parser("worker", help="run one process group of a graph placed on this host")
    worker.add_argument(
        "connect", help="the supervisor's endpoint, tcp://HOST:PORT (printed by flowtact run)"
    )
    worker.add_argument("--process", required=True, help="the process group to run")
    worker.add_argument("--keys", help="CURVE keys folder (default: $FLOWTACT_KEYS)")
    add_allow_module(worker)  # this host's own permission: the supervisor's does not reach here

    keys = sub.add_parser("keys", help="create the CURVE key pair that hosts of a rig share")
    keys.add_argument("folder", help="folder to write flowtact.key and flowtact.key_secret into")
    keys.add_argument("--force", action="store_true", help="replace an existing key pair")

    val = sub.add_parser("validate", help="check a graph without running it")
    graph_args(val)

    blocks = sub.add_parser("blocks", help="list the block catalogue, or document one block")
    blocks.add_argument("name", nargs="?", help="block name")

    draw = sub.add_parser("graph", help="draw a graph (pruned parts greyed) as .svg, .png, .pdf or .dot")
    graph_args(draw)
    draw.add_argument(
        "-o", "--output", required=True, help="output file: .svg, .png, .pdf, or .dot (Graphviz source)"
    )

    plot = sub.add_parser(
        "plot",
        help="plot a recording: each stream as what it is (lines in units, steps, rasters, pulses, frames)",
        description="Plot a recording on a shared time axis: vector samples as labelled lines per channel "
        "in their units (heat map beyond 12 channels), categorical streams as named steps, spike events "
        "as rasters with firing rates, stimulation pulses as pulse trains, frames as a thumbnail strip. "
        "Reads block by block: memory stays bounded whatever the file size. --paper draws the compact "
        "touch/slip figure instead (force, dF/dt, SA1/FA1 rasters, rates; after Rager et al. Fig. 4).",
    )
    plot.add_argument("recording", help="an .h5 file written by flowtact run --record")
    plot.add_argument("-o", "--output", required=True, help="image file (.png, .svg, .pdf)")
    plot.add_argument("--streams", nargs="*", help="streams to plot (default: all)")
    plot.add_argument("--from", dest="t0", type=cli_finite_seconds, help="start time (s)")
    plot.add_argument("--to", dest="t1", type=cli_finite_seconds, help="end time (s)")
    plot.add_argument(
        "--paper",
        action="store_true",
        help="compact touch/slip figure: force, dF/dt, rasters, rates (one column)",
    )
    info = sub.add_parser("info", help="describe a recording and verify its checksums")
    info.add_argument("recording", help="an .h5 file written by flowtact run --record")
    info.add_argument("--json", action="store_true", help="print the report as JSON")
    bench = sub.add_parser(
        "bench",
        help="run the benchmark suites and write results/*.json, plots and REPORT.md",
        description="Run benchmark suites (all when none is named): warm-up, repeats, median and spread, "
        "ratios to a baseline measured in the same run, the machine and its load. Writes "
        "OUT/results/<suite>.json, OUT/plots/*.png and OUT/REPORT.md.",
    )
    bench.add_argument("suites", nargs="*", metavar="SUITE", help="suites to run (see --list)")
    bench.add_argument("--list", action="store_true", help="list the suites and exit")
    bench.add_argument(
        "--quick",
        action="store_true",
        help="shorter runs, fewer repeats: every suite in about 10 min on an idle 2-core machine "
        "(about 45 without; --list gives each suite's share)",
    )
    bench.add_argument("--peers", action="store_true", help="also measure peers that need extra packages")
    bench.add_argument(
        "--json", action="store_true", help="print the run summary as JSON (progress on stderr)"
    )
    bench.add_argument("--out", default="bench-report", help="output folder (default: ./bench-report)")
    bench.add_argument(
        "--compare",
        metavar="DIR",
        help="an earlier run's output folder: say which ratios this run reproduces within its range",
    )
    from flowtact.sweeps.cli import add_sweep_parser

    add_sweep_parser(sub)
    p.add_argument("--debug", action="store_true", help=DEBUG_HELP)
    for sp in list(sub.choices.values()):  # also after the command: flowtact run --debug GRAPH
        sp.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help=DEBUG_HELP)
    for name, ep in plugin_commands().items():  # commands that installed packages add (flowtact.commands)
        sp = sub.add_parser(name, help=_plugin_help(ep), add_help=False)
        sp.add_argument("args", nargs=argparse.REMAINDER)
    return p


RUN_EXAMPLES = """examples:
  flowtact run touch                                   # a shipped graph by name, in real time
  flowtact run graphs/touch.yaml --fast --duration 3 --record touch.h5
  flowtact run touch.h5 --fast                         # re-run what a recording was made with
  flowtact run touch --replay sensor=touch.h5 --fast   # feed a recorded sensor back in
  flowtact run graphs/slip.yaml --set sa1.n=200 --set sa1_stim.max_units=200 --fast
  flowtact run envelope.yaml --allow-module envelope   # a graph using your own block (envelope.py)"""

PLUGIN_GROUP = "flowtact.commands"
DEBUG_HELP = "on failure, print the full Python traceback after the error (also: FLOWTACT_DEBUG=1)"


def plugin_commands() -> dict[str, Any]:
    """Commands declared in the ``flowtact.commands`` entry-point group: name -> ``main(argv) -> int``."""
    from importlib.metadata import entry_points

    return {ep.name: ep for ep in entry_points(group=PLUGIN_GROUP)}


def _plugin_help(ep: Any) -> str:
    """A plugin command's help line: its module's summary (:func:`entry_point_summary`)."""
    return entry_point_summary(ep)


def entry_point_summary(ep: Any) -> str:
    """An entry point's one-line summary for help lists: the first sentence of its module's
    docstring as plain text (reST markup gone, :func:`flowtact.help.rst_text.inline_text`), without a
    leading ``flowtact NAME ...:`` or trailing ``: flowtact NAME`` that repeats the name beside
    it. Cheap: the module is parsed, not imported."""
    import ast
    import importlib.util

    from flowtact.help.rst_text import inline_text

    try:
        spec = importlib.util.find_spec(ep.value.partition(":")[0])
    except (ImportError, ValueError):
        spec = None
    if spec is None or spec.origin is None:
        return "(not importable)"
    try:
        doc = ast.get_docstring(ast.parse(Path(spec.origin).read_text()))
    except (OSError, SyntaxError, ValueError):
        doc = None
    return one_line_summary(inline_text(doc or ep.value))


def one_line_summary(text: str) -> str:
    """The first sentence of ``text`` (its first paragraph joined), without a ``flowtact ...:``
    prefix or a ``: flowtact ...`` suffix, its first letter lower-cased as argparse's own help is."""
    import re

    para = " ".join(text.strip().split("\n\n", 1)[0].split())
    first = re.split(r"(?<=[a-z0-9)])\. ", para, maxsplit=1)[0].rstrip(".")
    first = re.sub(r"^flowtact [\w-]+[^:]*:\s*", "", first)
    first = re.sub(r":\s*flowtact [\w-]+[^:]*$", "", first)
    if first[:1].isupper() and first[1:2].islower():
        first = first[0].lower() + first[1:]
    return first


def _complete_graph(prefix: str, **_kwargs: Any) -> list[str]:
    """Shell completion of a graph argument: the shipped graph names, and .yaml/.h5 files and
    folders under the prefix (argcomplete's file completer)."""
    from argcomplete.completers import FilesCompleter

    from flowtact.graphfile.graph import shipped_graphs

    names = [n for n in shipped_graphs() if n.startswith(prefix)]
    return names + list(FilesCompleter(allowednames=("yaml", "yml", "h5"))(prefix))


def _module_name(text: str) -> str:
    from flowtact.catalog.blocks import check_module_name

    try:
        return check_module_name(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def add_allow_module(sp: argparse.ArgumentParser) -> None:
    """``--allow-module MODULE`` (repeatable): the modules whose ``module:Class`` blocks a graph
    may import. Only the command line gives this: no file, recording or environment variable."""
    sp.add_argument(
        "--allow-module",
        dest="allow_modules",
        action="append",
        default=[],
        type=_module_name,
        metavar="MODULE",
        help="let the graph's 'module:Class' blocks import MODULE (or modules inside package MODULE); "
        "without it only registered blocks load. Repeatable; see docs/security.md",
    )


def _version() -> str:
    from flowtact import __version__

    return __version__


def _replays(items: Sequence[str]) -> dict[str, str]:
    from flowtact.graphfile.graph import Loc
    from flowtact.graphfile.located import GraphProblem

    out: dict[str, str] = {}
    for i, item in enumerate(items):
        node, sep, path = item.partition("=")
        node = node.strip()
        why = "expected NODE=FILE[:PORT=COLUMN,...;PORT=...]" if not sep or not node or not path else ""
        why = why or (f"node '{node}' is replayed twice" if node in out else "")
        if why:
            raise GraphFileError([GraphProblem(Loc("--replay", 1, i + 1), f"--replay '{item}': {why}")])
        out[node] = path
    return out


def _import_beside_graph(graph: str, modules: Sequence[str]) -> None:
    """Let an allowed module written beside the graph file import (``envelope.py`` for
    ``--allow-module envelope``): the graph's real folder goes at the END of ``sys.path`` (an
    installed module of the same name still wins), and workers inherit it. Nothing happens without
    ``--allow-module``: a graph alone never makes its folder importable."""
    from flowtact.graphfile.graph import local_module_folder

    folder = local_module_folder(graph, modules) if modules else None
    if folder is not None and str(folder) not in sys.path:
        sys.path.append(str(folder))


def _plan(args: argparse.Namespace) -> Any:
    from flowtact.running.launch import load_compiled

    _import_beside_graph(args.graph, args.allow_modules)

    return load_compiled(
        args.graph,
        overrides=args.overrides,
        replays=_replays(args.replays),
        allow_modules=args.allow_modules,
    )


class _Progress:
    """A one-line progress bar on stderr when it is a terminal."""

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled and sys.stderr.isatty()
        self.last = 0.0

    def __call__(self, now: float, total: float | None) -> None:
        if not self.enabled or time.monotonic() - self.last < 0.2:
            return
        self.last = time.monotonic()
        if total:
            done = min(now / total, 1.0)
            bar = "#" * int(30 * done)
            sys.stderr.write(f"\r[{bar:<30}] {100 * done:5.1f}%  {now:.1f}/{total:.1f} s")
        else:
            sys.stderr.write(f"\r{now:.1f} s (Ctrl-C stops)")
        sys.stderr.flush()

    def done(self) -> None:
        if self.enabled and self.last:
            sys.stderr.write("\r" + " " * 60 + "\r")


def _cmd_run(args: argparse.Namespace) -> int:
    from flowtact.running.launch import run_compiled
    from flowtact.runtime.live import LiveView

    plan = _plan(args)
    quiet = args.quiet or args.json
    live = LiveView(enabled=not quiet and not args.inproc)
    progress = _Progress(not quiet and not live.enabled)

    def on_term(_signum: int, _frame: Any) -> None:
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, on_term)
    try:
        with live:
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
            )
    finally:
        progress.done()
    if args.json:
        print(json.dumps(summary.to_dict(), indent=2))
    elif not args.quiet:
        print(summary.format())
        if args.record:
            print(f"  recorded {', '.join(f'{n}.{p}' for n, p in plan.record)} -> {args.record}")
    return 0


def _cmd_worker(args: argparse.Namespace) -> int:
    from flowtact.runtime.worker import main as worker_main

    argv = [args.connect, "--process", args.process]
    if args.keys:
        argv += ["--keys", args.keys]
    for module in args.allow_modules:
        argv += ["--allow-module", module]
    return worker_main(argv)


def _cmd_keys(args: argparse.Namespace) -> int:
    from flowtact.runtime.security import generate_keys

    folder = generate_keys(args.folder, force=args.force)
    print(f"wrote {folder}/flowtact.key and flowtact.key_secret: copy the folder to every host of the rig")
    print("and name it in the graph (network: {keys: FOLDER}) or in $FLOWTACT_KEYS")
    return 0


def _cmd_validate(args: argparse.Namespace) -> int:
    from flowtact.runtime.placement import place

    plan = _plan(args)
    groups = place(plan, fast=False).groups  # refuses placements the runtime cannot start
    n_streams = sum(len(plan.demanded[n]) for n in plan.order)
    print(
        f"{plan.graph.path}: ok — {len(plan.graph.nodes)} nodes, {len(plan.order)} active, "
        f"{n_streams} computed streams, {len(groups)} process{'es' if len(groups) != 1 else ''}"
    )
    for note in plan.notes:
        print(f"  {note}")
    return 0


def _cmd_blocks(args: argparse.Namespace) -> int:
    from flowtact.catalog.blocks import block_names, load_block

    if not args.name:
        for name in block_names():
            doc = (load_block(name).__doc__ or "").strip().splitlines()
            print(f"{name:<16} {doc[0] if doc else ''}")
        return 0
    from flowtact.errors import UnknownBlockError

    try:
        cls = load_block(args.name, [args.name.partition(":")[0]])  # named on the command line: allowed
    except UnknownBlockError as e:  # a usage error: the name given is not a block
        raise UsageError(str(e)) from e
    from flowtact.help.describe import describe_block

    print(describe_block(cls))
    return 0


def _cmd_graph(args: argparse.Namespace) -> int:
    from flowtact.pictures.graph_figure import FORMATS, draw_compiled

    suffix = Path(args.output).suffix
    if suffix not in FORMATS:  # a usage error: say so before loading anything
        raise UsageError(f"-o {args.output}: cannot draw to '{suffix}'; use {', '.join(FORMATS)}")
    out = draw_compiled(_plan(args), args.output)
    print(f"wrote {out}")
    return 0


def _cmd_plot(args: argparse.Namespace) -> int:
    from flowtact.errors import NotARecording, RecordingRefused
    from flowtact.pictures.recording_figure import plot_recording

    t_range = None if args.t0 is None and args.t1 is None else (args.t0, args.t1)
    try:
        out = plot_recording(
            args.recording, args.output, streams=args.streams, t_range=t_range, paper=args.paper
        )
    except KeyError as e:  # an unknown --streams name: a usage error
        raise UsageError(str(e.args[0])) from e
    except (RecordingRefused, NotARecording) as e:  # bad input, refused before reading: exit 2
        raise UsageError(str(e)) from e
    print(f"wrote {out}")
    return 0


def _cmd_info(args: argparse.Namespace) -> int:
    from flowtact.errors import NotARecording, RecordingRefused
    from flowtact.recording.info import format_info, inspect_recording

    try:
        info = inspect_recording(args.recording)
    except (RecordingRefused, NotARecording) as e:  # bad input, refused before reading: exit 2
        raise UsageError(str(e)) from e
    print(json.dumps(info.to_dict(), indent=2) if args.json else format_info(info))
    return 0 if info.ok else EXIT_RUN_ERROR


def _cmd_bench(args: argparse.Namespace) -> int:
    from flowtact.benchmark.runner import list_suites, run_suites

    if args.list:
        return list_suites()
    compare = Path(args.compare) if args.compare else None
    return run_suites(args.suites, args.quick, args.peers, Path(args.out), as_json=args.json, compare=compare)


def _cmd_sweep(args: argparse.Namespace) -> int:
    from flowtact.sweeps.cli import run_sweep_command

    return run_sweep_command(args)


COMMANDS = {
    "run": _cmd_run,
    "validate": _cmd_validate,
    "blocks": _cmd_blocks,
    "graph": _cmd_graph,
    "plot": _cmd_plot,
    "info": _cmd_info,
    "bench": _cmd_bench,
    "worker": _cmd_worker,
    "keys": _cmd_keys,
    "sweep": _cmd_sweep,
}


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``flowtact`` command: its exit status (see the module notes)."""
    from flowtact.console.debug import ENV, debug_enabled

    as_program = argv is None  # the process's own command line: its exit status is ours to keep
    argv = list(sys.argv[1:] if argv is None else argv)
    plugins = plugin_commands()
    debug = argv[:1] == ["--debug"] and len(argv) > 1 and argv[1] in plugins
    argv = argv[1:] if debug else argv
    if argv and argv[0] in plugins and argv[0] not in COMMANDS:  # a plugin parses its own arguments
        before = os.environ.get(ENV)
        if debug:
            os.environ[ENV] = "1"  # flowtact --debug PLUGIN ...: the plugin reads it
        try:
            return _decided(
                run_command(lambda: _plugin(plugins[argv[0]], argv[1:]), prog=f"flowtact {argv[0]}"),
                as_program,
            )
        finally:  # main() called in process leaves the environment as it found it
            if debug and before is None:
                del os.environ[ENV]
            elif debug:
                os.environ[ENV] = before  # type: ignore[assignment]
    parser = _parser()
    if as_program and "_ARGCOMPLETE" in os.environ:  # the shell asks for completions: answer, exit
        import argcomplete

        argcomplete.autocomplete(parser)
    args = parser.parse_args(argv)
    if args.command == "plot" and args.t0 is not None and args.t1 is not None and not args.t0 < args.t1:
        parser.error(f"plot: --from ({args.t0:g}) must be before --to ({args.t1:g})")
    return _decided(
        run_command(lambda: COMMANDS[args.command](args), debug=debug_enabled(args.debug)), as_program
    )


def _decided(status: int, as_program: bool) -> int:
    """``status``, final: as the program, a Ctrl-C arriving from here on (while the interpreter
    exits: threads joined, files closed) is ignored, so a finished run's 0 does not become -2
    (killed by SIGINT) after its full summary. Called in-process (``main([...])``), nothing changes."""
    if as_program and threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    return status


def _plugin(ep: Any, argv: list[str]) -> int:
    """Load a plugin command and run its ``main(argv)`` (under :func:`run_command`, as the built-ins)."""
    return int(ep.load()(argv) or 0)


if __name__ == "__main__":
    sys.exit(main())
