"""``flowtact validate GRAPH``: check a graph without running it."""

from __future__ import annotations

import argparse

from flowtact.commands import Command
from flowtact.commands.graph_args import add_graph_arguments, load_graph_plan

__all__ = ["COMMAND"]


def run(args: argparse.Namespace) -> int:
    from flowtact.runtime.placement import place

    plan = load_graph_plan(args)
    groups = place(plan, fast=False).groups  # refuses placements the runtime cannot start
    n_streams = sum(len(plan.demanded[n]) for n in plan.order)
    print(
        f"{plan.graph.path}: ok — {len(plan.graph.nodes)} nodes, {len(plan.order)} active, "
        f"{n_streams} computed streams, {len(groups)} process{'es' if len(groups) != 1 else ''}"
    )
    for note in plan.notes:
        print(f"  {note}")
    return 0


COMMAND = Command(run=run, add_arguments=add_graph_arguments)
