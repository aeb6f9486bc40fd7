"""``flowtact keys FOLDER``: create the CURVE key pair that hosts of a rig share."""

from __future__ import annotations

import argparse

from flowtact.commands import Command

__all__ = ["COMMAND"]


def add_arguments(keys: argparse.ArgumentParser) -> None:
    keys.add_argument("folder", help="folder to write flowtact.key and flowtact.key_secret into")
    keys.add_argument("--force", action="store_true", help="replace an existing key pair")


def run(args: argparse.Namespace) -> int:
    from flowtact.runtime.links.zeromq.security import generate_keys

    folder = generate_keys(args.folder, force=args.force)
    print(f"wrote {folder}/flowtact.key and flowtact.key_secret: copy the folder to every host of the rig")
    print("and name it in the graph (network: {keys: FOLDER}) or in $FLOWTACT_KEYS")
    return 0


COMMAND = Command(run=run, add_arguments=add_arguments)
