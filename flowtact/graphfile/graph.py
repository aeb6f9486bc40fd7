"""YAML graph files -> a validated :class:`Graph`, with ``file:line:col`` for every error.

Loading is strict and collects every problem before giving up: YAML syntax, unknown keys, blocks,
parameters and ports (each with a did-you-mean hint), wrong parameter values (the block's own
rules), duplicate nodes, malformed edges and record entries. Stream-level checks (dtype, shape,
units, rates, cycles, unconnected inputs) happen when the graph is compiled
(:mod:`flowtact.running.compile`). Parsing uses ``yaml.SafeLoader``: a graph never executes code.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from flowtact.block import Block
from flowtact.catalog.blocks import allowing, load_block, role_block
from flowtact.errors import (
    ConfigError,
    GraphFileError,
    ModuleNotAllowedError,
    SafeYamlError,
    UnknownBlockError,
)
from flowtact.graphfile.deployment import (
    DEFAULT_QUEUE,
    POLICIES,
    Deployment,
    deadline_path_errors,
    parse_deployment,
)
from flowtact.graphfile.located import GraphProblem, Loc, Located
from flowtact.graphfile.nodes import Edge, NodeDef
from flowtact.graphfile.param_paths import graph_folder, path_fields, resolve_path, resolve_value
from flowtact.graphfile.replay_spec import parse_port_map, split_replay
from flowtact.graphfile.safe_yaml import compose, load_value, read_graph_text
from flowtact.inputs.limits import (
    MAX_DURATION_S,
    MAX_QUEUE,
    MAX_SEED,
    MAX_TICK_S,
    MIN_TICK_S,
    positive_seconds,
    run_ticks_problem,
)
from flowtact.params import did_you_mean

__all__ = [
    "Edge",
    "Graph",
    "Loc",
    "NodeDef",
    "load_graph",
    "missing_graph_error",
    "parse_override",
    "resolve_graph_path",
    "shipped_graphs",
]

TOP_KEYS = (
    "name",
    "description",
    "seed",
    "duration_s",
    "tick_s",
    "nodes",
    "edges",
    "record",
    "processes",
    "network",
    "deadlines",
)
NODE_KEYS = ("block", "params", "process", "seed", "doc", "shards")
EDGE_KEYS = ("from", "to", "policy", "queue")
NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
EDGE_RE = re.compile(r"^\s*([^\s.]+)\.([^\s.]+)\s*->\s*([^\s.]+)\.([^\s.]+)\s*$")


@dataclass
class Graph:
    """A loaded, validated graph file."""

    name: str
    path: str
    text: str
    seed: int
    nodes: dict[str, NodeDef]
    edges: list[Edge]
    record: list[tuple[str, str, Loc]]
    duration_s: float | None = None
    tick_s: float | None = None
    description: str = ""
    overrides: dict[str, Any] = field(default_factory=dict)
    deployment: Deployment = field(default_factory=Deployment)
    allow_modules: tuple[str, ...] = ()
    """Modules the user allowed for ``module:Class`` blocks (``--allow-module``): workers and sweep
    rows load the graph's blocks with exactly this permission, never one the file gives itself."""


def shipped_graphs() -> list[str]:
    """Names of the graphs shipped with flowtact (``flowtact run NAME`` finds them)."""
    from importlib.resources import files

    return sorted(p.name[:-5] for p in files("flowtact.graphs").iterdir() if p.name.endswith(".yaml"))


def resolve_graph_path(name: str | Path) -> Path:
    """A graph file path; a bare name such as ``touch`` also finds the graphs shipped with flowtact."""
    p = Path(name)
    if p.exists() or p.suffix or "/" in str(name):
        return p
    from importlib.resources import files

    packaged = files("flowtact.graphs") / f"{name}.yaml"
    return Path(str(packaged)) if packaged.is_file() else p


def missing_graph_error(path: str) -> GraphProblem:
    """A graph file that is not there, with the closest graph file beside it or shipped graph name
    (``flowtact run touhc`` -> did you mean 'touch'?) and the shipped graphs as the hint."""
    import difflib

    p = Path(path)
    shipped = shipped_graphs()
    bare = not p.suffix and "/" not in path
    try:
        beside = sorted(q.name for q in p.parent.glob("*.y*ml"))[:500] if p.parent.is_dir() else []
    except OSError:
        beside = []
    names = shipped if bare else sorted({*beside, *(f"{n}.yaml" for n in shipped)} if beside else beside)
    close = difflib.get_close_matches(p.name, names, n=1, cutoff=0.6)
    guess = ""
    if close:
        guess = f" (did you mean '{close[0] if bare else p.parent / close[0]}'?)"
    return GraphProblem(
        Loc(path),
        f"no such graph file{guess}",
        f"shipped graphs, run by name (flowtact run touch): {', '.join(shipped)}",
    )


def local_module_folder(graph: str | Path, modules: Iterable[str]) -> Path | None:
    """The graph file's real folder when it holds one of ``modules`` (``NAME.py`` or a package
    ``NAME/``), else None: where ``flowtact run GRAPH --allow-module NAME`` finds a block written
    beside the graph. Only modules the user allowed by name are looked for."""
    path = Path(graph)
    if not path.is_file():
        return None
    folder = graph_folder(path)
    for module in modules:
        top = module.partition(".")[0]
        if (folder / f"{top}.py").is_file() or (folder / top / "__init__.py").is_file():
            return folder
    return None


def parse_override(text: str) -> tuple[str, str, Any]:
    """``node.param=value`` -> (node, param, value parsed as a YAML scalar)."""
    m = re.match(r"^\s*([^.=\s]+)\.([^=\s]+)\s*=(.*)$", text)
    if not m:
        raise ValueError(f"--set '{text}': expected node.param=value")
    try:
        value = load_value(m.group(3)) if m.group(3).strip() else None
    except SafeYamlError as e:
        shown = text if len(text) <= 80 else f"{text[:77]}..."
        raise ValueError(f"--set '{shown}': the value is not valid YAML ({e.message})") from None
    return m.group(1), m.group(2), value


def _resolved(
    config_cls: type,
    params: Mapping[str, Any],
    bases: Mapping[str, Path],
    locs: Mapping[str, Loc],
    node: str,
    errors: list[GraphProblem],
) -> dict[str, Any]:
    """``params`` with path fields resolved (:mod:`flowtact.graphfile.param_paths`), each against its own
    base; a name that cannot be resolved (a bad ``pkg:``) is an error at its place, kept as written."""
    fields = path_fields(config_cls)
    out = dict(params)
    for k in fields & set(params):
        try:
            out[k] = resolve_value(params[k], bases[k])
        except ValueError as e:
            errors.append(GraphProblem(locs[k], f"node '{node}': '{k}': {e}"))
    return out


def load_graph(
    source: str | Path,
    *,
    overrides: Iterable[str] = (),
    replays: Mapping[str, str] | None = None,
    text: str | None = None,
    allow_modules: Iterable[str] = (),
) -> Graph:
    """Load and validate a graph file; raise :class:`~flowtact.errors.GraphFileError` listing every problem.

    A ``module:Class`` block is imported only if its module is in ``allow_modules`` (module names
    or package prefixes: ``mypkg`` allows ``mypkg.blocks``; :mod:`flowtact.catalog.blocks`); otherwise it
    is an error at the block's place and nothing is imported.

    ``overrides`` are ``node.param=value`` strings (``--set``), applied before validation, so they
    go through exactly the same checks. ``replays`` maps a node to ``FILE[:PORT=COLUMNS;...]``
    (``--replay sensor=log.csv``): the node is swapped for a replay of that file standing in on the
    node's own output ports (:mod:`flowtact.graphfile.replay_spec`). ``text`` gives the YAML directly
    (``source`` then only names it). Relative file names in parameters (``param(path=True)``) are
    resolved against the graph file's folder, those given by ``--set`` or ``--replay`` against the
    working directory.
    """
    path = str(source)
    located = Located(path)
    try:
        if text is None:
            text = read_graph_text(source)
        root = compose(text)
    except SafeYamlError as e:
        raise GraphFileError([GraphProblem(Loc(path, e.line, e.col), e.message, e.hint)]) from None
    except FileNotFoundError:
        raise GraphFileError([missing_graph_error(path)]) from None
    except OSError as e:
        raise GraphFileError(
            [GraphProblem(Loc(path), f"cannot read graph file: {e.strerror or e}")]
        ) from None
    if root is None:
        raise GraphFileError(
            [GraphProblem(Loc(path), "the graph file is empty", "a graph needs at least 'nodes:'")]
        )
    try:
        doc = located.convert(root)
    except yaml.constructor.ConstructorError as e:
        mark = e.problem_mark
        loc = Loc(path, mark.line + 1, mark.column + 1) if mark else Loc(path)
        raise GraphFileError([GraphProblem(loc, f"unsupported YAML value: {e.problem}")]) from None
    allow = tuple(dict.fromkeys(allow_modules))
    with allowing(allow):
        graph = _build(doc, located, path, text, list(overrides), dict(replays or {}))
    graph.allow_modules = allow
    return graph


def _apply_replays(
    doc: dict[str, Any], y: Located, replays: Mapping[str, str], errors: list[GraphProblem]
) -> None:
    """Swap each replayed node for a replay of a file on the node's own output ports, in place.

    ``replays`` maps a node to ``FILE[:PORT=COLUMNS;...]`` (:mod:`flowtact.graphfile.replay_spec`); a relative
    FILE is from the working directory. The node keeps its name, ports, process and seed, so edges
    and ``record:`` are untouched; its inputs are dropped (a replay has none). Problems are located
    at ``--replay:1:N`` (the N-th ``--replay``), and so is everything later said about the node.
    """
    nodes = doc.get("nodes")
    planned: dict[str, tuple[Loc, str, str, str]] = {}
    for i, (name, text) in enumerate(replays.items()):
        loc = Loc("--replay", 1, i + 1)
        where = f"--replay {name}={text}"
        ndoc = nodes.get(name) if isinstance(nodes, dict) else None
        if not isinstance(ndoc, dict):
            known = map(str, nodes if isinstance(nodes, dict) else {})
            errors.append(GraphProblem(loc, f"{where}: unknown node '{name}'{did_you_mean(name, known)}"))
            continue
        try:
            cls = load_block(str(ndoc.get("block")))
        except UnknownBlockError:
            errors.append(GraphProblem(loc, f"{where}: node '{name}' has no valid block to stand in for"))
            continue
        path, mapping = split_replay(text)
        head, colon, tail = path.rpartition(":")
        if colon and Path(head).suffix and not Path(path).is_file():
            mapping = tail  # FILE:MAP with a map missing its '=': say so, not "no such file"
        try:
            ports = parse_port_map(mapping)
        except ValueError as e:
            errors.append(
                GraphProblem(loc, f"{where}: {e}", "map ports as FILE:PORT=COLUMN[,COLUMN...];PORT=...")
            )
            continue
        bad = [p for p in ports if p not in cls.outputs]
        if not path or bad:
            why = (
                "no file given"
                if not path
                else f"'{bad[0]}' is not an output of {cls.name}{did_you_mean(bad[0], cls.outputs)}"
            )
            errors.append(
                GraphProblem(loc, f"{where}: {why}", f"outputs of {cls.name}: {', '.join(cls.outputs)}")
            )
            continue
        try:
            resolved = resolve_path(path, Path.cwd())
        except ValueError as e:
            errors.append(GraphProblem(loc, f"{where}: {e}"))
            continue
        planned[name] = (loc, str(ndoc["block"]), resolved, mapping)
    if not planned:
        return
    _drop_edges_into(doc, y, set(planned))
    consumed = {(m.group(1), m.group(2)) for m in map(_edge_match, doc.get("edges") or []) if m}
    recorded = {str(r).partition(".")[0].strip() for r in doc.get("record") or [] if isinstance(r, str)}
    try:
        replay = role_block("replay")  # the library's block that plays a file (flowtact.roles)
    except UnknownBlockError as e:
        errors.extend(GraphProblem(loc, f"--replay {name}: {e}") for name, (loc, *_) in planned.items())
        return
    for name, (loc, block, path, mapping) in planned.items():
        need = sorted(p for n, p in consumed if n == name)
        if not need and name not in recorded:
            errors.append(
                GraphProblem(
                    loc, f"--replay {name}={replays[name]}: nothing consumes or records node '{name}'"
                )
            )
            continue
        old = nodes[name]
        params = {"path": path, "ports": mapping, "need": need}
        nodes[name] = {"block": replay.stand_in(block), "params": params}  # type: ignore[attr-defined]
        nodes[name].update({k: old[k] for k in ("process", "seed") if k in old})
        for table in (y.locs, y.key_locs):  # the node is now written on the command line
            for key in [k for k in table if k[:2] == ("nodes", name) and len(k) > 2]:
                del table[key]
            table[("nodes", name)] = loc


def _edge_match(item: Any) -> re.Match[str] | None:
    """An edge (string or ``{from:, to:}`` mapping) as an :data:`EDGE_RE` match, if well formed."""
    if isinstance(item, dict):
        item = f"{item.get('from')} -> {item.get('to')}"
    return EDGE_RE.match(item) if isinstance(item, str) else None


def _drop_edges_into(doc: dict[str, Any], y: Located, nodes: set[str]) -> None:
    """Remove the edges into ``nodes``, keeping every other edge's YAML location."""
    edges = doc.get("edges")
    if not isinstance(edges, list):
        return
    kept = [i for i, e in enumerate(edges) if not ((m := _edge_match(e)) and m.group(3) in nodes)]
    doc["edges"] = [edges[i] for i in kept]
    for table in (y.locs, y.key_locs):
        moved = {k: v for k, v in table.items() if k[:1] == ("edges",) and len(k) > 1}
        for k in moved:
            del table[k]
        for new, old in enumerate(kept):
            table.update({("edges", new, *k[2:]): v for k, v in moved.items() if k[1] == old})


def _build(
    doc: Any, y: Located, path: str, text: str, overrides: list[str], replays: dict[str, str]
) -> Graph:
    errors = y.errors
    if not isinstance(doc, dict):
        raise GraphFileError(
            [GraphProblem(y.loc(), "a graph file must be a mapping with 'nodes:' and 'edges:'")]
        )
    if replays:
        _apply_replays(doc, y, replays, errors)
    for key in doc:
        if key not in TOP_KEYS:
            errors.append(
                GraphProblem(
                    y.key_loc(key), f"unknown top-level key '{key}'{did_you_mean(str(key), TOP_KEYS)}"
                )
            )
    seed, duration, tick = _run_settings(doc, y, errors)
    name = doc.get("name", Path(path).stem)
    if not isinstance(name, str):
        errors.append(GraphProblem(y.loc("name"), f"'name' must be a string; got {name!r}"))
        name = Path(path).stem

    node_docs = doc.get("nodes")
    if node_docs is None:
        errors.append(GraphProblem(y.loc(), "the graph has no 'nodes:' section"))
        node_docs = {}
    elif not isinstance(node_docs, dict):
        errors.append(
            GraphProblem(
                y.loc("nodes"), "'nodes' must be a mapping of node name -> {block: ..., params: ...}"
            )
        )
        node_docs = {}

    set_params, set_errors = _overrides(overrides, node_docs)
    errors.extend(set_errors)

    nodes: dict[str, NodeDef] = {}
    classes: dict[str, type[Block]] = {}
    for nname, ndoc in node_docs.items():
        node = _node(str(nname), ndoc, y, set_params.get(str(nname), {}), errors, classes)
        if node is not None:
            nodes[node.name] = node

    edges = _edges(doc.get("edges", []), y, node_docs, classes, errors)
    record = _record(doc.get("record", []), y, node_docs, classes, errors)
    deployment = parse_deployment(doc, y, node_docs)
    errors.extend(deadline_path_errors(deployment.deadlines, edges))
    if not errors:
        nodes, edges = _split_shards(nodes, edges, record, seed, y, errors)
        deployment.deadlines = _shard_deadlines(deployment.deadlines, nodes)
    if errors:
        raise GraphFileError(sorted(errors, key=lambda e: (e.loc.path != path, e.loc.line, e.loc.col)))
    return Graph(
        name=name,
        path=path,
        text=text,
        seed=seed,
        nodes=nodes,
        edges=edges,
        record=record,
        duration_s=float(duration) if duration is not None else None,
        tick_s=float(tick) if tick is not None else None,
        description=str(doc.get("description", "")),
        overrides={o: parse_override(o)[2] for o in overrides},
        deployment=deployment,
    )


def _shard_deadlines(deadlines: list[Any], nodes: dict[str, NodeDef]) -> list[Any]:
    """:func:`flowtact.graphfile.shards.shard_deadlines` (imported here only when shards are used)."""
    if not any("__s" in n for n in nodes):
        return deadlines
    from flowtact.graphfile.shards import shard_deadlines

    return shard_deadlines(deadlines, nodes)


def _split_shards(
    nodes: dict[str, NodeDef],
    edges: list[Edge],
    record: list[tuple[str, str, Loc]],
    seed: int,
    y: Located,
    errors: list[GraphProblem],
) -> tuple[dict[str, NodeDef], list[Edge]]:
    """Every node with ``shards: K`` (K > 1) split into K shard nodes and a merge named as the node
    (:mod:`flowtact.graphfile.shards`); bad ``shards:`` values are reported where they are written."""
    from flowtact.graphfile.seeds import node_seed
    from flowtact.graphfile.shards import check_shards, expand_shards, plan_bounds

    split = {}
    for name, node in nodes.items():
        if node.shards is None:
            continue
        got, errs = check_shards(node, node.shards, y.loc("nodes", name, "shards"))
        errors.extend(errs)
        if got is not None:
            split[name] = got
    bounds, why = plan_bounds(split, edges)
    for name, reason in why.items():
        errors.append(GraphProblem(y.loc("nodes", name, "shards"), f"node '{name}': {reason}"))
    for name, node in nodes.items():
        if name in split and name not in bounds and isinstance(node.process, list):
            node.process = node.process[0]  # shards: 1
    if errors or not bounds:
        return nodes, edges
    recorded = {(n, p) for n, p, _ in record}
    return expand_shards(nodes, edges, recorded, bounds, lambda n: node_seed(seed, n))


def _run_settings(doc: Mapping[str, Any], y: Located, errors: list[GraphProblem]) -> tuple[int, Any, Any]:
    """The graph's ``seed``, ``duration_s`` and ``tick_s``, each checked against its documented
    bound (:mod:`flowtact.inputs.limits`); a bad one is reported and replaced by its default."""
    seed = doc.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        errors.append(GraphProblem(y.loc("seed"), f"'seed' must be a non-negative integer; got {seed!r}"))
        seed = 0
    elif seed > MAX_SEED:
        errors.append(GraphProblem(y.loc("seed"), f"'seed' must be at most 2**63 - 1; got {seed!r}"))
        seed = 0
    duration = doc.get("duration_s")
    if duration is not None and positive_seconds(duration) is None:
        errors.append(
            GraphProblem(y.loc("duration_s"), f"'duration_s' must be a finite number > 0; got {duration!r}")
        )
        duration = None
    elif duration is not None and duration > MAX_DURATION_S:
        errors.append(
            GraphProblem(
                y.loc("duration_s"), f"'duration_s' must be at most {MAX_DURATION_S:g} s; got {duration!r}"
            )
        )
        duration = None
    tick = doc.get("tick_s")
    if tick is not None and not (positive_seconds(tick) or math.inf) <= MAX_TICK_S:
        errors.append(
            GraphProblem(
                y.loc("tick_s"),
                f"'tick_s' must be a number of seconds > 0 and <= {MAX_TICK_S:g}; got {tick!r}",
            )
        )
        tick = None
    elif tick is not None and tick < MIN_TICK_S:
        errors.append(
            GraphProblem(y.loc("tick_s"), f"'tick_s' must be at least {MIN_TICK_S:g} s; got {tick!r}")
        )
        tick = None
    too_long = run_ticks_problem(duration, tick) if duration is not None and tick is not None else None
    if too_long:
        errors.append(GraphProblem(y.loc("duration_s"), f"'duration_s' at 'tick_s': {too_long}"))
    return seed, duration, tick


def _overrides(
    overrides: list[str], node_docs: Mapping[str, Any]
) -> tuple[dict[str, dict[str, tuple[Any, Loc]]], list[GraphProblem]]:
    out: dict[str, dict[str, tuple[Any, Loc]]] = {}
    errors = []
    for i, text in enumerate(overrides):
        loc = Loc("--set", 1, i + 1)
        try:
            node, param, value = parse_override(text)
        except ValueError as e:
            errors.append(GraphProblem(loc, str(e)))
            continue
        if node not in node_docs:
            errors.append(
                GraphProblem(
                    loc, f"--set '{text}': unknown node '{node}'{did_you_mean(node, map(str, node_docs))}"
                )
            )
            continue
        out.setdefault(node, {})[param] = (value, loc)
    return out, errors


def _node(
    name: str,
    ndoc: Any,
    y: Located,
    sets: Mapping[str, tuple[Any, Loc]],
    errors: list[GraphProblem],
    classes: dict[str, type[Block]],
) -> NodeDef | None:
    loc = y.key_loc("nodes", name)
    if not NAME_RE.match(name):
        errors.append(
            GraphProblem(loc, f"node name '{name}' must be an identifier (letters, digits, _), no dots")
        )
        return None
    if not isinstance(ndoc, dict):
        errors.append(
            GraphProblem(
                y.loc("nodes", name),
                f"node '{name}' must be a mapping like {{block: savgol, params: {{...}}}}",
            )
        )
        return None
    errors.extend(y.unknown_keys(ndoc, NODE_KEYS, f"node '{name}'", "nodes", name))
    block_name = ndoc.get("block")
    if not isinstance(block_name, str):
        errors.append(
            GraphProblem(
                loc,
                f"node '{name}' has no 'block:' (the block type to run)",
                "see `flowtact blocks` for the catalogue",
            )
        )
        return None
    try:
        cls = load_block(block_name)
    except UnknownBlockError as e:
        hint = "" if isinstance(e, ModuleNotAllowedError) else "see `flowtact blocks` for the catalogue"
        errors.append(GraphProblem(y.loc("nodes", name, "block"), f"node '{name}': {e}", hint))
        return None
    classes[name] = cls
    params = ndoc.get("params", {}) or {}
    if not isinstance(params, dict):
        errors.append(
            GraphProblem(y.loc("nodes", name, "params"), f"node '{name}': 'params' must be a mapping")
        )
        return None
    param_locs = {k: y.loc("nodes", name, "params", k) for k in params}
    folder = graph_folder(y.path)  # paths: beside the graph file (its real folder)
    params = _resolved(cls.config_cls, params, {k: folder for k in params}, param_locs, name, errors)
    for k, (value, sloc) in sets.items():
        param_locs[k] = sloc  # --set: from here
        params.update(_resolved(cls.config_cls, {k: value}, {k: Path.cwd()}, param_locs, name, errors))
    process = ndoc.get("process")
    groups = process if isinstance(process, list) and "shards" in ndoc else [process]
    if process is not None and not all(isinstance(g, str) and NAME_RE.match(g) for g in groups):
        errors.append(
            GraphProblem(
                y.loc("nodes", name, "process"),
                f"node '{name}': 'process' must be an identifier"
                + (" or a list of them, one per shard" if "shards" in ndoc else "")
                + f"; got {process!r}",
            )
        )
    seed = ndoc.get("seed")
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int) or seed < 0):
        errors.append(
            GraphProblem(
                y.loc("nodes", name, "seed"), f"node '{name}': 'seed' must be a non-negative integer"
            )
        )
        seed = None
    try:
        config = cls.configure(params, owner=f"{name} ({cls.name})")
    except ConfigError as e:
        if e.field in param_locs:
            ploc = param_locs[e.field]
        elif e.field and e.unknown is None:
            ploc = y.loc("nodes", name, "params") if "params" in ndoc else loc
        else:
            key = e.unknown
            ploc = (
                y.key_loc("nodes", name, "params", key)
                if key in (ndoc.get("params") or {})
                else param_locs.get(key, loc)
            )
        errors.append(GraphProblem(ploc, str(e), f"`flowtact blocks {cls.name}` documents every parameter"))
        return None
    return NodeDef(
        name=name,
        block=block_name,
        cls=cls,
        params=params,
        config=config,
        loc=loc,
        process=process,
        seed=seed,
        param_locs=param_locs,
        shards=ndoc.get("shards"),
    )


def _endpoint_errors(
    node: str,
    port: str,
    side: str,
    loc: Loc,
    node_docs: Mapping[str, Any],
    classes: Mapping[str, type[Block]],
) -> GraphProblem | None:
    if node not in node_docs:
        return GraphProblem(loc, f"unknown node '{node}'{did_you_mean(node, map(str, node_docs))}")
    if node not in classes:
        return None  # the node's block is unknown: already reported
    cls = classes[node]
    ports = cls.outputs if side == "output" else cls.inputs
    if port not in ports:
        suggestion = did_you_mean(port, ports)
        hint = f"{side}s of {cls.name}: {', '.join(ports) or 'none'}" if "(valid" not in suggestion else ""
        return GraphProblem(
            loc, f"block '{cls.name}' (node '{node}') has no {side} '{port}'{suggestion}", hint
        )
    return None


def _edges(
    raw: Any,
    y: Located,
    node_docs: Mapping[str, Any],
    classes: Mapping[str, type[Block]],
    errors: list[GraphProblem],
) -> list[Edge]:
    if raw is None:
        return []
    if not isinstance(raw, list):
        errors.append(
            GraphProblem(y.loc("edges"), "'edges' must be a list of 'node.port -> node.port' strings")
        )
        return []
    edges = []
    seen_inputs: dict[tuple[str, str], Edge] = {}
    for i, item in enumerate(raw):
        loc = y.loc("edges", i)
        if isinstance(item, dict):
            errors.extend(y.unknown_keys(item, EDGE_KEYS, "edge", "edges", i))
            policy, queue = _edge_flow(item, y, i, errors)
            item = f"{item.get('from')} -> {item.get('to')}"
        else:
            policy, queue = "block", DEFAULT_QUEUE
        m = EDGE_RE.match(item) if isinstance(item, str) else None
        if not m:
            errors.append(
                GraphProblem(loc, f"malformed edge {item!r}", "write edges as 'node.port -> node.port'")
            )
            continue
        edge = Edge(m.group(1), m.group(2), m.group(3), m.group(4), loc, policy, queue)
        bad = [
            _endpoint_errors(edge.src, edge.src_port, "output", loc, node_docs, classes),
            _endpoint_errors(edge.dst, edge.dst_port, "input", loc, node_docs, classes),
        ]
        found = [b for b in bad if b is not None]
        if found:
            errors.extend(found)
            continue
        if edge.src not in classes or edge.dst not in classes:
            continue
        key = (edge.dst, edge.dst_port)
        if key in seen_inputs:
            errors.append(
                GraphProblem(
                    loc,
                    f"input '{edge.dst}.{edge.dst_port}' is already fed by "
                    f"'{seen_inputs[key]}' (at {seen_inputs[key].loc})",
                    "an input takes one stream; use a block that combines streams",
                )
            )
            continue
        seen_inputs[key] = edge
        edges.append(edge)
    return edges


def _edge_flow(item: dict[str, Any], y: Located, i: int, errors: list[GraphProblem]) -> tuple[str, int]:
    """An edge mapping's ``policy`` and ``queue``, checked."""
    policy = item.get("policy", "block")
    if policy not in POLICIES:
        errors.append(
            GraphProblem(
                y.loc("edges", i, "policy"),
                f"edge policy must be one of {', '.join(POLICIES)}; got {policy!r}",
                "block: lossless with back-pressure; latest: drop the oldest messages (real time)",
            )
        )
        policy = "block"
    queue = item.get("queue", DEFAULT_QUEUE)
    if isinstance(queue, bool) or not isinstance(queue, int) or not 1 <= queue <= MAX_QUEUE:
        errors.append(
            GraphProblem(
                y.loc("edges", i, "queue"),
                f"edge queue must be an integer from 1 to {MAX_QUEUE}; got {queue!r}",
            )
        )
        queue = DEFAULT_QUEUE
    return policy, queue


def _record(
    raw: Any,
    y: Located,
    node_docs: Mapping[str, Any],
    classes: Mapping[str, type[Block]],
    errors: list[GraphProblem],
) -> list[tuple[str, str, Loc]]:
    if raw is None:
        return []
    if not isinstance(raw, list):
        errors.append(GraphProblem(y.loc("record"), "'record' must be a list of 'node.port' streams"))
        return []
    out = []
    for i, item in enumerate(raw):
        loc = y.loc("record", i)
        m = re.match(r"^\s*([^\s.]+)\.([^\s.]+)\s*$", item) if isinstance(item, str) else None
        if not m:
            errors.append(
                GraphProblem(loc, f"cannot record {item!r}", "record entries are 'node.port' output streams")
            )
            continue
        err = _endpoint_errors(m.group(1), m.group(2), "output", loc, node_docs, classes)
        if err:
            errors.append(GraphProblem(err.loc, f"cannot record '{item}': {err.message}", err.hint))
            continue
        out.append((m.group(1), m.group(2), loc))
    return out
