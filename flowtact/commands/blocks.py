"""``flowtact blocks [NAME]``: list the block catalogue, or document one block."""

from __future__ import annotations

import argparse

from flowtact.commands import Command
from flowtact.errors import UsageError

__all__ = ["COMMAND"]


def add_arguments(blocks: argparse.ArgumentParser) -> None:
    blocks.add_argument("name", nargs="?", help="block name")


def run(args: argparse.Namespace) -> int:
    from flowtact.catalog.blocks import block_names, load_block
    from flowtact.errors import UnknownBlockError

    if not args.name:
        for name in block_names():
            doc = (load_block(name).__doc__ or "").strip().splitlines()
            print(f"{name:<16} {doc[0] if doc else ''}")
        return 0
    try:
        cls = load_block(args.name, [args.name.partition(":")[0]])  # named on the command line: allowed
    except UnknownBlockError as e:  # a usage error: the name given is not a block
        raise UsageError(str(e)) from e
    from flowtact.help.describe import describe_block

    print(describe_block(cls))
    return 0


COMMAND = Command(run=run, add_arguments=add_arguments)
