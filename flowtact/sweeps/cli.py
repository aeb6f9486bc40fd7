"""``flowtact sweep GRAPH``: run a graph over parameter grids and recordings: one table row per run.

The command line of :func:`flowtact.sweeps.api.sweep`, registered as every command is
(:data:`COMMAND`, entry-point group ``flowtact.commands``).

Usage problems (a bad ``--set-grid``, a pattern matching nothing, an unknown metric, a missing
extra) print one line and exit 2; runs that failed are rows of the table and make the exit status
1; Ctrl-C keeps the finished rows in ``--out`` and exits 130. An ``--out`` that cannot be written,
or a table there that another setup made (another graph, ``--set``, ``--duration``, metrics), is
refused before the first run.
"""

from __future__ import annotations

import argparse
import signal
import sys
from typing import Any

from flowtact.commands import Command
from flowtact.commands.graph_args import GRAPH_HELP, add_allow_module, parse_replays
from flowtact.inputs.limits import cli_duration_seconds, cli_positive_seconds

__all__ = ["COMMAND", "add_arguments", "run_sweep_command"]

EXAMPLE = (
    "flowtact sweep touch --set-grid sa1.tau_s=0.005,0.01 --set-grid sa1.sigma=1,1.5 --out rates.parquet"
)


def add_arguments(sp: argparse.ArgumentParser) -> None:
    """The ``sweep`` command's arguments."""
    sp.add_argument("graph", help=GRAPH_HELP)
    sp.add_argument("--set", dest="overrides", action="append", default=[], metavar="NODE.PARAM=VALUE",
                    help="a fixed override for every run (as in flowtact run); repeatable")  # fmt: skip
    add_allow_module(sp)
    sp.add_argument("--set-grid", dest="grid", action="append", default=[], metavar="NODE.PARAM=V1,V2,...",
                    help="values to sweep (read like --set values); several: their Cartesian product")  # fmt: skip
    sp.add_argument(
        "--table", metavar="FILE", help="rows of node.param values (.yaml list of mappings, .csv)"
    )
    sp.add_argument("--replay", dest="replays", action="append", default=[], metavar="NODE=GLOB[:MAP]",
                    help="one run per file matching GLOB played in place of NODE (as flowtact run --replay)")  # fmt: skip
    sp.add_argument("--metrics", default=None, metavar="NAME,...",
                    help="built-ins spikes, rmse, runtime (default: spikes,runtime) and module:function "
                    "user metrics (fn(streams) -> dict of scalars)")  # fmt: skip
    sp.add_argument("--rmse", action="append", default=[], metavar="STREAM=REFERENCE",
                    help="RMSE of a recorded stream against a recorded reference stream; repeatable")  # fmt: skip
    sp.add_argument("--out", metavar="FILE.parquet",
                    help="the result table (resumed when it exists and the same setup made it: rows with "
                    "status ok are kept)")  # fmt: skip
    sp.add_argument("--fresh", action="store_true", help="start --out over instead of resuming it")
    sp.add_argument("--row-timeout", type=cli_positive_seconds, metavar="SECONDS",
                    help="a run still going after this is a failed row (default: 600 s + 10 s per graph second)")  # fmt: skip
    sp.add_argument("--executor", choices=("local", "dask"), default="local", help="default: local processes")
    sp.add_argument("--scheduler", metavar="ADDRESS", help="a dask scheduler (default: a local cluster)")
    sp.add_argument(
        "--workers", type=_positive_int, metavar="N", help="worker processes (default: CPU count)"
    )
    sp.add_argument("--duration", type=cli_duration_seconds, metavar="SECONDS", help="graph seconds per run")
    sp.add_argument(
        "--plot", metavar="FILE.png", help="also plot spike rates across the grid (needs the plot extra)"
    )
    sp.add_argument("--quiet", action="store_true", help="no progress and no table on stdout")


def _positive_int(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        n = 0
    if not 1 <= n <= 4096:
        raise argparse.ArgumentTypeError(f"expected a whole number of workers from 1 to 4096; got '{text}'")
    return n


def run_sweep_command(args: argparse.Namespace) -> int:
    """Run the sweep the arguments describe; return the exit status."""
    from flowtact.errors import SweepSpecError

    def on_term(_signum: int, _frame: Any) -> None:
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, on_term)
    try:
        from flowtact.sweeps.api import need_extras, sweep

        need_extras()
        if args.plot:
            from flowtact.sweeps.plot import check_plot_extra

            check_plot_extra()
        df = sweep(args.graph, grid=args.grid, table=args.table, replay=parse_replays(args.replays),
                   overrides=args.overrides, metrics=args.metrics, rmse=args.rmse, executor=args.executor,
                   workers=args.workers, scheduler=args.scheduler, out=args.out, duration_s=args.duration,
                   progress=not args.quiet, row_timeout_s=args.row_timeout, fresh=args.fresh,
                   allow_modules=args.allow_modules)  # fmt: skip
    except SweepSpecError as e:
        print(f"flowtact sweep: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        kept = f"; finished runs are in {args.out}" if args.out else ""
        print(f"flowtact sweep: interrupted{kept}", file=sys.stderr)
        return 130
    return _report(df, args)


def _report(df: Any, args: argparse.Namespace) -> int:
    failed = df[df["status"] != "ok"]
    if not args.quiet and not args.out:
        shown = df.drop(columns=[c for c in ("key", "provenance", "notes", "graph") if c in df.columns])
        print(shown.to_string(index=False))
    if args.plot:
        from flowtact.errors import GraphFileError
        from flowtact.running.launch import load_compiled
        from flowtact.sweeps.plot import plot_rates

        try:
            plan = load_compiled(args.graph, overrides=args.overrides, allow_modules=args.allow_modules)
            graph = plan.graph  # parameter docs: axis units
        except GraphFileError:
            graph = None
        plot_rates(df, args.plot, graph)
    kept = df.attrs.get("kept", 0)
    where = f" -> {args.out}" if args.out else ""
    plot = f", rates plotted to {args.plot}" if args.plot else ""
    print(f"flowtact sweep: {len(df)} run{'s' if len(df) != 1 else ''} ({df.attrs.get('executed', 0)} run now, {kept} kept from before): "
          f"{len(df) - len(failed)} ok, {len(failed)} failed{where}{plot}", file=sys.stderr)  # fmt: skip
    for _, r in failed.head(10).iterrows():
        print(f"  failed: {_row_label(r)}: {r['error']}", file=sys.stderr)
    if len(failed) > 10:
        print(f"  ... and {len(failed) - 10} more (see the status and error columns)", file=sys.stderr)
    return 1 if len(failed) else 0


def _row_label(r: Any) -> str:
    """The row's parameters and recordings, short: ``sa1.tau_s=0.01 recording:sensor=a.h5``."""
    import json

    key = json.loads(r["key"])
    parts = [f"{k}={v}" for k, v in key["params"].items()] + [
        f"{k}={v}" for k, v in key["recordings"].items()
    ]
    return " ".join(parts) or "(the one run)"


COMMAND = Command(
    run=run_sweep_command,
    add_arguments=add_arguments,
    description="Run GRAPH (--fast, in-process) once per row of a parameter grid × table × replayed "
    "recordings, on local processes or Dask, and write one row per run (parameters, recording, "
    f"metrics, provenance hash, status, error, seed, run time). Example: {EXAMPLE}",
)
