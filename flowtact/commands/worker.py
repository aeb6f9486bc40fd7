"""``flowtact worker ENDPOINT --process NAME``: run one process group of a graph placed on this host."""

from __future__ import annotations

import argparse

from flowtact.commands import Command
from flowtact.commands.graph_args import add_allow_module

__all__ = ["COMMAND"]


def add_arguments(worker: argparse.ArgumentParser) -> None:
    worker.add_argument(
        "connect", help="the supervisor's endpoint, tcp://HOST:PORT (printed by flowtact run)"
    )
    worker.add_argument("--process", required=True, help="the process group to run")
    worker.add_argument("--keys", help="CURVE keys folder (default: $FLOWTACT_KEYS)")
    add_allow_module(worker)  # this host's own permission: the supervisor's does not reach here


def run(args: argparse.Namespace) -> int:
    from flowtact.runtime.worker import main as worker_main

    argv = [args.connect, "--process", args.process]
    if args.keys:
        argv += ["--keys", args.keys]
    for module in args.allow_modules:
        argv += ["--allow-module", module]
    return worker_main(argv)


COMMAND = Command(run=run, add_arguments=add_arguments)
