"""``flowtact schema [-o FILE]``: write the JSON Schema of graph files, for editors to complete and check them.

Generated from the installed blocks (their parameters, presets and ports), so it follows whatever
packages are installed; docs/schema.md shows how VS Code's YAML extension uses it.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from flowtact.commands import Command
from flowtact.errors import UsageError

__all__ = ["COMMAND"]


def add_arguments(sp: argparse.ArgumentParser) -> None:
    sp.add_argument(
        "-o", "--output", metavar="FILE.json", help="write the schema to this file (default: standard output)"
    )


def run(args: argparse.Namespace) -> int:
    from flowtact.graphfile.schema import graph_schema

    left_out: dict[str, str] = {}
    text = json.dumps(graph_schema(left_out), indent=2, ensure_ascii=False, allow_nan=False) + "\n"
    for name, why in left_out.items():
        print(f"flowtact schema: left out block '{name}', which does not load: {why}", file=sys.stderr)
    if args.output is None:
        sys.stdout.write(text)
        return 0
    out = Path(args.output)
    try:
        out.write_text(text, encoding="utf-8")
    except OSError as e:
        raise UsageError(f"-o {args.output}: cannot write: {e.strerror or e}") from None
    print(f"wrote {out}")
    return 0


COMMAND = Command(
    run=run,
    add_arguments=add_arguments,
    epilog="examples:\n  flowtact schema -o flowtact-graph.schema.json   # then see docs/schema.md",
)
