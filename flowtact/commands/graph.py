"""``flowtact graph GRAPH -o FILE``: draw a graph (pruned parts greyed) as .svg, .png, .pdf or .dot."""

from __future__ import annotations

import argparse
from pathlib import Path

from flowtact.commands import Command
from flowtact.commands.graph_args import add_graph_arguments, load_graph_plan
from flowtact.errors import UsageError

__all__ = ["COMMAND"]


def add_arguments(draw: argparse.ArgumentParser) -> None:
    add_graph_arguments(draw)
    draw.add_argument(
        "-o", "--output", required=True, help="output file: .svg, .png, .pdf, or .dot (Graphviz source)"
    )


def run(args: argparse.Namespace) -> int:
    from flowtact.pictures.graph_figure import FORMATS, draw_compiled

    suffix = Path(args.output).suffix
    if suffix not in FORMATS:  # a usage error: say so before loading anything
        raise UsageError(f"-o {args.output}: cannot draw to '{suffix}'; use {', '.join(FORMATS)}")
    out = draw_compiled(load_graph_plan(args), args.output)
    print(f"wrote {out}")
    return 0


COMMAND = Command(run=run, add_arguments=add_arguments)
