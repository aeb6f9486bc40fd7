"""A JSON Schema (draft-07) for graph files, generated from the block registry: ``flowtact schema``.

Editors that speak the YAML language server (VS Code's YAML extension, Neovim, JetBrains) use it
to complete and check a graph file as it is typed: top-level keys, node names, each registered
block with its parameters (type, range, options, default and one-line doc from the block's
``param`` declarations), its presets, whether it may be sharded, and edge and ``record:`` entries
naming ports that some block has. Draft-07 because it is the draft the YAML language server has
supported longest and most completely (``if``/``then`` included).

The schema says what one document can say about itself; the loader
(:func:`flowtact.graphfile.graph.load_graph`) remains the judge. Left to the loader: rules across
fields (a config's ``check()``), state budgets, NaN, which node an edge's port belongs to (a
schema cannot look a value up elsewhere in the document), stream agreement between ports, cycles,
and YAML the parser refuses. tests/graphfile/test_schema.py counts what the schema catches.
"""

from __future__ import annotations

import dataclasses
import re
import sys
import types
import typing
from typing import Any, Literal, get_args, get_origin

from flowtact.block import Block
from flowtact.catalog.blocks import block_names, load_block
from flowtact.catalog.presets import presets_for
from flowtact.errors import UnknownBlockError
from flowtact.graphfile.deployment import DEADLINE_KEYS, NETWORK_KEYS, POLICIES, PROCESS_KEYS, RESTARTS
from flowtact.graphfile.graph import EDGE_KEYS, NODE_KEYS, TOP_KEYS
from flowtact.graphfile.shards import MAX_SHARDS
from flowtact.inputs.limits import MAX_DURATION_S, MAX_QUEUE, MAX_SEED, MAX_TICK_S, MIN_TICK_S
from flowtact.params import Rules

__all__ = ["DRAFT", "SCHEMA_ID", "graph_schema"]

DRAFT = "http://json-schema.org/draft-07/schema#"
SCHEMA_ID = "https://flowtact.invalid/graph.schema.json"
"""The schema's ``$id``: a name, not an address (nothing is fetched from it)."""

NAME = r"[A-Za-z_][A-Za-z0-9_]*"
"""A node or process name (:data:`flowtact.graphfile.graph.NAME_RE`)."""
MODULE_CLASS = r"^[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*:[A-Za-z_][A-Za-z0-9_]*$"
"""A ``module:Class`` block, imported only with ``--allow-module`` (its parameters are not known here)."""
DURATION = r"^\s*[0-9]*\.?[0-9]+(e-?[0-9]+)?\s*(s|ms|us|µs)\s*$"
"""A duration with units (:func:`flowtact.graphfile.deployment.parse_duration`)."""
_LABEL = r"[A-Za-z0-9]([A-Za-z0-9-]{0,61}[A-Za-z0-9])?"
HOST = rf"^({_LABEL}(\.{_LABEL})*\.?|[0-9A-Fa-f:.]+(%[A-Za-z0-9_.-]+)?)$"
"""A host name or an IP address (looser than :func:`flowtact.inputs.limits.host_problem`, never stricter)."""
FINITE = sys.float_info.max
"""A float parameter is finite: bounds of ±max float keep out ``.inf`` (NaN compares with nothing)."""


def graph_schema(left_out: dict[str, str] | None = None) -> dict[str, Any]:
    """The JSON Schema of a graph file, for every block registered in ``flowtact.blocks``.

    A registered block that cannot be imported (a broken or half-installed package) is left out,
    its name and why put in ``left_out``: the schema of every other block is still worth having.
    """
    classes: dict[str, type[Block]] = {}
    for name in block_names():
        try:
            classes[name] = load_block(name)
        except (UnknownBlockError, ImportError) as e:
            if left_out is not None:
                left_out[name] = str(e).splitlines()[0] if str(e) else type(e).__name__
    outputs = sorted({p for cls in classes.values() for p in cls.outputs})
    inputs = sorted({p for cls in classes.values() for p in cls.inputs})
    out_end = rf"{NAME}\.({'|'.join(map(re.escape, outputs))})"
    in_end = rf"{NAME}\.({'|'.join(map(re.escape, inputs))})"
    definitions: dict[str, Any] = {f"params_{n}": params_schema(cls) for n, cls in classes.items()}
    definitions.update(
        node=_node_schema(classes),
        edge=_edge_schema(out_end, in_end),
        duration={
            "anyOf": [
                {"type": "number", "exclusiveMinimum": 0, "maximum": FINITE},
                {"type": "string", "pattern": DURATION},
            ],
            "description": "seconds, or a number with units: 4ms, 500us, 0.5s",
        },
    )
    top: dict[str, Any] = {
        "name": {"type": "string", "description": "the graph's name (default: the file's name)"},
        "description": {"description": "one line saying what the graph does"},
        "seed": {
            "type": "integer",
            "minimum": 0,
            "maximum": MAX_SEED,
            "default": 0,
            "description": "the graph's seed; every node's own seed derives from it and the node's name",
        },
        "duration_s": {
            "type": "number",
            "exclusiveMinimum": 0,
            "maximum": MAX_DURATION_S,
            "description": "graph seconds a run lasts unless --duration says otherwise",
        },
        "tick_s": {
            "type": "number",
            "minimum": MIN_TICK_S,
            "maximum": MAX_TICK_S,
            "description": "the clock's tick in seconds (default 1 s with --fast, 5 ms in real time)",
        },
        "nodes": {
            "type": "object",
            "propertyNames": {"pattern": f"^{NAME}$"},
            "additionalProperties": {"$ref": "#/definitions/node"},
            "description": "node name -> {block: ..., params: {...}}",
        },
        "edges": {
            "type": ["array", "null"],
            "items": {"$ref": "#/definitions/edge"},
            "description": "'node.output -> node.input' streams",
        },
        "record": {
            "type": ["array", "null"],
            "items": {"type": "string", "pattern": rf"^\s*{out_end}\s*$"},
            "description": "'node.output' streams to record (flowtact run --record FILE.h5)",
        },
        "processes": _processes_schema(),
        "network": _network_schema(),
        "deadlines": _deadlines_schema(),
    }
    assert set(top) == set(TOP_KEYS), "the schema misses a top-level key the loader accepts"
    for key, prop in top.items():
        prop.setdefault("title", key)
    return {
        "$schema": DRAFT,
        "$id": SCHEMA_ID,
        "title": "flowtact graph file",
        "description": "A flowtact graph: nodes running registered blocks, the edges between "
        "their ports, what to record and how the graph is spread over processes.",
        "type": "object",
        "properties": top,
        "required": ["nodes"],
        "additionalProperties": False,
        "definitions": definitions,
    }


def _node_schema(classes: dict[str, type[Block]]) -> dict[str, Any]:
    """A node: ``block`` one of the registry's (or ``module:Class``), then that block's parameters."""
    names = sorted(classes)
    node_props: dict[str, Any] = {
        "block": {
            "anyOf": [
                {"enum": names},
                {"type": "string", "pattern": MODULE_CLASS},
            ],
            "description": "the block to run (`flowtact blocks` lists them), or module:Class with --allow-module",
        },
        "params": {"type": ["object", "null"], "description": "the block's parameters"},
        "process": {
            "anyOf": [
                {"type": "null"},
                {"type": "string", "pattern": f"^{NAME}$"},
                {"type": "array", "items": {"type": "string", "pattern": f"^{NAME}$"}},
            ],
            "description": "the worker process group it runs in (a list, one per shard, with shards:)",
        },
        "seed": {"type": ["integer", "null"], "minimum": 0, "description": "this node's own seed"},
        "doc": {"description": "a note about the node"},
        "shards": {
            "type": ["integer", "null"],
            "minimum": 1,
            "maximum": MAX_SHARDS,
            "description": "split its independent units across this many processes (shardable blocks)",
        },
    }
    assert set(node_props) == set(NODE_KEYS), "the schema misses a node key the loader accepts"
    for key, prop in node_props.items():
        prop.setdefault("title", key)
    rules: list[dict[str, Any]] = [
        {  # a process list only with shards
            "if": {"not": {"required": ["shards"]}},
            "then": {"properties": {"process": {"type": ["string", "null"]}}},
        }
    ]
    for name, cls in sorted(classes.items()):
        then: dict[str, Any] = {"properties": {"params": {"$ref": f"#/definitions/params_{name}"}}}
        if _required(cls):
            then["required"] = ["params"]
        if not cls.shardable:
            then["not"] = {"required": ["shards"], "properties": {"shards": {"type": "integer"}}}
        rules.append({"if": {"properties": {"block": {"const": name}}, "required": ["block"]}, "then": then})
    return {
        "type": "object",
        "properties": node_props,
        "required": ["block"],
        "additionalProperties": False,
        "allOf": rules,
    }


def _required(cls: type[Block]) -> list[str]:
    """The parameters a block's config has no default for."""
    return [
        f.name
        for f in dataclasses.fields(cls.config_cls)  # type: ignore[arg-type]
        if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
    ]


def params_schema(cls: type[Block]) -> dict[str, Any]:
    """One block's ``params:``: each config field with its type, rules, default and doc; its presets.

    A required field may come from a preset: with ``preset: P`` only what P leaves out is required.
    """
    hints = typing.get_type_hints(cls.config_cls)
    types_ = {i.name: i.type for i in cls.config_cls.fields_info()}
    props: dict[str, Any] = {}
    for f in dataclasses.fields(cls.config_cls):  # type: ignore[arg-type]
        rules = f.metadata.get("rules", Rules())
        prop = type_schema(hints[f.name], rules)
        doc = f.metadata.get("doc", "")
        said = rules.text()
        prop["title"] = f"{cls.name}.{f.name}: {types_[f.name]}"  # the editor's hover heading
        prop["description"] = f"{doc} ({said})" if said else doc
        if f.default is not dataclasses.MISSING:
            prop["default"] = _plain(f.default)
        props[f.name] = prop
    required = _required(cls)
    presets = presets_for(cls.name)
    out: dict[str, Any] = {
        "type": "object" if required else ["object", "null"],
        "description": (cls.__doc__ or cls.name).strip().splitlines()[0],
        "additionalProperties": False,
    }
    if presets:
        props["preset"] = {
            "title": f"{cls.name}.preset",
            "enum": sorted(presets),
            "description": "a published parameter set (DOMAIN.NAME); parameters given beside it win",
        }
        cases: list[dict[str, Any]] = [
            {"if": {"not": {"required": ["preset"]}}, "then": {"required": required}}
        ]
        for pname, values in sorted(presets.items()):
            left = [r for r in required if r not in values]
            cases.append(
                {
                    "if": {"properties": {"preset": {"const": pname}}, "required": ["preset"]},
                    "then": {"required": left},
                }
            )
        cases = [c for c in cases if c["then"]["required"]]
        if cases:
            out["allOf"] = cases
    elif required:
        out["required"] = required
    out["properties"] = props
    return out


def type_schema(hint: Any, rules: Rules | None = None) -> dict[str, Any]:
    """The schema of a config field's type (:func:`flowtact.params._coerce`'s rules): numeric rules
    on every number inside, length rules on the outermost list."""
    rules = rules or Rules()
    origin = get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        return {"anyOf": [type_schema(a, rules) for a in get_args(hint)]}
    if origin is Literal:
        return {"enum": list(get_args(hint))}
    if origin is tuple:
        item_rules = dataclasses.replace(rules, min_len=None, max_len=None)
        out: dict[str, Any] = {"type": "array", "items": type_schema(get_args(hint)[0], item_rules)}
        if rules.min_len is not None:
            out["minItems"] = rules.min_len
        if rules.max_len is not None:
            out["maxItems"] = rules.max_len
        return out
    if hint is type(None):
        return {"type": "null"}
    if hint is bool:
        return {"type": "boolean"}
    if hint is str:
        return {"type": "string"}
    if hint is int or hint is float:
        return _number(hint, rules)
    return {}  # Any


def _number(hint: type, rules: Rules) -> dict[str, Any]:
    out: dict[str, Any] = {"type": "integer" if hint is int else "number"}
    if rules.ge is not None:
        out["minimum"] = rules.ge
    if rules.gt is not None:
        out["exclusiveMinimum"] = rules.gt
    if rules.le is not None:
        out["maximum"] = rules.le
    if rules.lt is not None:
        out["exclusiveMaximum"] = rules.lt
    if hint is float:  # finite
        if rules.ge is None and rules.gt is None:
            out["minimum"] = -FINITE
        if rules.le is None and rules.lt is None:
            out["maximum"] = FINITE
    if rules.odd and hint is int:
        out["not"] = {"multipleOf": 2}
    return out


def _edge_schema(out_end: str, in_end: str) -> dict[str, Any]:
    """An edge: ``'a.out -> b.in'``, or ``{from: a.out, to: b.in, policy:, queue:}``."""
    flow = {
        "type": "object",
        "properties": {
            "from": {"type": "string", "pattern": rf"^\s*{out_end}\s*$", "description": "node.output"},
            "to": {"type": "string", "pattern": rf"^\s*{in_end}\s*$", "description": "node.input"},
            "policy": {
                "enum": list(POLICIES),
                "default": "block",
                "description": "across processes: block (lossless, back-pressure) or latest (drop the oldest)",
            },
            "queue": {
                "type": "integer",
                "minimum": 1,
                "maximum": MAX_QUEUE,
                "description": "the edge's queue bound in messages, across processes",
            },
        },
        "required": ["from", "to"],
        "additionalProperties": False,
    }
    assert set(flow["properties"]) == set(EDGE_KEYS)
    return {
        "anyOf": [
            {"type": "string", "pattern": rf"^\s*{out_end}\s*->\s*{in_end}\s*$"},
            flow,
        ],
        "description": "'node.output -> node.input'",
    }


def _processes_schema() -> dict[str, Any]:
    group = {
        "type": ["object", "null"],
        "properties": {
            "restart": {"enum": list(RESTARTS), "default": "never", "description": "restart policy"},
            "max_restarts": {"type": "integer", "minimum": 0, "default": 3},
            "host": {
                "type": "string",
                "pattern": HOST,
                "description": "run there (started by flowtact worker)",
            },
            "stall_s": {"$ref": "#/definitions/duration"},
            "startup_s": {"$ref": "#/definitions/duration"},
            "stop_grace_s": {"$ref": "#/definitions/duration"},
        },
        "additionalProperties": False,
    }
    assert set(group["properties"]) == set(PROCESS_KEYS)
    return {
        "type": ["object", "null"],
        "propertyNames": {"pattern": f"^{NAME}$"},
        "additionalProperties": group,
        "description": "process group -> restart policy, host and supervision windows",
    }


def _network_schema() -> dict[str, Any]:
    props = {
        "listen": {"type": "string", "pattern": rf"^(\*|{HOST[1:-1]})$", "default": "127.0.0.1"},
        "port": {"type": "integer", "minimum": 0, "maximum": 65535, "default": 5550},
        "keys": {"description": "the folder of CURVE keys (flowtact keys)"},
    }
    assert set(props) == set(NETWORK_KEYS)
    return {
        "type": ["object", "null"],
        "properties": props,
        "additionalProperties": False,
        "description": "off-host transport: the supervisor's listen address, port and CURVE keys",
    }


def _deadlines_schema() -> dict[str, Any]:
    props = {
        "from": {"type": "string", "pattern": f"^{NAME}$", "description": "a source node"},
        "to": {"type": "string", "pattern": f"^{NAME}$", "description": "a node downstream of it"},
        "budget": {"$ref": "#/definitions/duration"},
    }
    assert set(props) == set(DEADLINE_KEYS)
    return {
        "type": ["array", "null"],
        "items": {
            "type": "object",
            "properties": props,
            "required": ["from", "to", "budget"],
            "additionalProperties": False,
        },
        "description": "latency budgets along paths: {from: sensor, to: stim, budget: 4ms}",
    }


def _plain(v: Any) -> Any:
    """A default as JSON: tuples become lists."""
    return [_plain(x) for x in v] if isinstance(v, tuple) else v
