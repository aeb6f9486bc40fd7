"""``flowtact lsl list``: the Lab Streaming Layer streams this machine sees (name, type, channels...)."""

from __future__ import annotations

import argparse

from flowtact.commands import Command
from flowtact.errors import UsageError

__all__ = ["COMMAND"]

HEADER = "name\ttype\tsource_id\tchannels\tformat\trate\tunits\thost"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="action", required=True, metavar="ACTION")
    ls = sub.add_parser(
        "list", help="list the LSL streams visible from here (LSLAPICFG decides how far: docs/lsl.md)"
    )
    ls.add_argument(
        "--timeout",
        type=float,
        default=1.0,
        metavar="S",
        help="seconds to wait for streams to answer (default 1)",
    )


def check(args: argparse.Namespace) -> str | None:
    if args.action == "list" and not 0 < args.timeout <= 600:
        return f"--timeout: must be in (0, 600] seconds; got {args.timeout:g}"
    return None


def run(args: argparse.Namespace) -> int:
    from flowtact.graphfile.extras import install_hint, module_available

    if not module_available("pylsl"):
        what, how = install_hint(__name__, "pylsl", "lsl")
        raise UsageError(f"flowtact lsl needs {what}: {how}")
    from flowtact.blocks.devices.lsl_streams import list_streams

    streams = list_streams(args.timeout)
    print(HEADER)
    for m in streams:
        print(m.line())
    print(f"{len(streams)} stream{'s' if len(streams) != 1 else ''}")
    return 0


COMMAND = Command(run=run, add_arguments=add_arguments, check=check)
