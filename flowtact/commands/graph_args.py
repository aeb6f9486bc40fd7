"""The arguments that name a graph, shared by the commands that load one (run, validate, graph,
sweep): the graph, ``--set``, ``--replay``, ``--allow-module``; and the plan they load."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import Any

__all__ = ["add_allow_module", "add_graph_arguments", "complete_graph", "load_graph_plan", "parse_replays"]

GRAPH_HELP = "graph file (.yaml), a shipped graph name (touch, slip), or a recording (.h5)"


def add_graph_arguments(sp: argparse.ArgumentParser) -> None:
    """GRAPH, ``--set``, ``--replay`` and ``--allow-module``, as run, validate and graph take them."""
    graph = sp.add_argument("graph", help=GRAPH_HELP)
    graph.completer = complete_graph  # type: ignore[attr-defined]
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


def complete_graph(prefix: str, **_kwargs: Any) -> list[str]:
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


def parse_replays(items: Sequence[str]) -> dict[str, str]:
    """``--replay NODE=FILE[:MAP]`` items as node -> FILE[:MAP]; a located GraphFileError (``--replay:1:I``)
    for a malformed item or a node replayed twice."""
    from flowtact.errors import GraphFileError
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


def load_graph_plan(args: argparse.Namespace) -> Any:
    """The plan the graph arguments (:func:`add_graph_arguments`) describe."""
    from flowtact.running.launch import load_compiled

    _import_beside_graph(args.graph, args.allow_modules)
    return load_compiled(
        args.graph,
        overrides=args.overrides,
        replays=parse_replays(args.replays),
        allow_modules=args.allow_modules,
    )
