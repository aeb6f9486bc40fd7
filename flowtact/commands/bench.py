"""``flowtact bench [SUITE ...]``: run the benchmark suites and write results/*.json, plots and REPORT.md."""

from __future__ import annotations

import argparse
from pathlib import Path

from flowtact.commands import Command

__all__ = ["COMMAND"]


def add_arguments(bench: argparse.ArgumentParser) -> None:
    bench.add_argument("suites", nargs="*", metavar="SUITE", help="suites to run (see --list)")
    bench.add_argument("--list", action="store_true", help="list the suites and exit")
    bench.add_argument(
        "--quick",
        action="store_true",
        help="shorter runs, fewer repeats: every suite in about 11 min on an idle 2-core machine "
        "(about 47 without; --list gives each suite's share)",
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


def run(args: argparse.Namespace) -> int:
    from flowtact.benchmark.runner import list_suites, run_suites

    if args.list:
        return list_suites()
    compare = Path(args.compare) if args.compare else None
    return run_suites(args.suites, args.quick, args.peers, Path(args.out), as_json=args.json, compare=compare)


COMMAND = Command(
    run=run,
    add_arguments=add_arguments,
    description="Run benchmark suites (all when none is named): warm-up, repeats, median and spread, "
    "ratios to a baseline measured in the same run, the machine and its load. Writes "
    "OUT/results/<suite>.json, OUT/plots/*.png and OUT/REPORT.md.",
)
