"""``flowtact schema`` against the loader: every shipped graph valid, every bad graph it can express invalid.

The schema is checked with the ``jsonschema`` package (an independent validator) on the document
the loader itself reads (:func:`flowtact.graphfile.safe_yaml.compose`). The malformed-graph corpus
(tests/graphfile/graphs/bad/) is split three ways, and the split is asserted both ways, so this
list cannot go stale: files the YAML parser refuses (no document for a schema to see), files a
schema cannot express (below, each with why), and the rest, which must all fail the schema.
docs/schema.md quotes the counts; a test checks them.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import jsonschema
import pytest
import yaml

from flowtact.catalog.blocks import block_names, load_block
from flowtact.cli import main
from flowtact.errors import SafeYamlError
from flowtact.graphfile.located import Located
from flowtact.graphfile.safe_yaml import compose, read_graph_text
from flowtact.graphfile.schema import graph_schema

ROOT = Path(__file__).parents[2]
BAD = sorted((Path(__file__).parent / "graphs" / "bad").glob("*.yaml"))
SHIPPED = sorted([*(ROOT / "graphs").glob("*.yaml"), *(ROOT / "bench" / "graphs").glob("*.yaml")])

_BUDGET = "a state budget: the block's state_bytes() is code summing several parameters"
_NAN = "NaN: JSON has no NaN, and NaN compares false with every bound"
_STREAMS = "stream agreement between connected ports, decided when the graph is compiled"
_REFERENCE = "a value naming a node defined elsewhere in the file: a schema cannot look it up"
INEXPRESSIBLE = {
    "camera_huge_size": _BUDGET,
    "delay_huge_shape": _BUDGET,
    "nlif_huge_n": _BUDGET,
    "pulses_huge_units": _BUDGET,
    "sensor_huge_rate": _BUDGET + " (rate × sample bytes per tick)",
    "tactip_huge_fps": _BUDGET + " (frames per tick)",
    "nan_duration": _NAN,
    "nan_param": _NAN,
    "nan_tick": _NAN,
    "deadline_nan_budget": _NAN,
    "events_into_samples": _STREAMS,
    "rate_mismatch": _STREAMS,
    "same_rate_declared": _STREAMS,
    "shape_mismatch": _STREAMS,
    "units_mismatch": _STREAMS,
    "unconnected_input": "an input left unconnected: which ports a node's block has is known only by name",
    "cycle_without_delay": "a cycle through the edges: a property of the whole edge list",
    "input_fed_twice": "two edges into one input: uniqueness of a part of a string across list items",
    "deadline_no_path": "a path of edges between two nodes: a property of the whole edge list",
    "record_unknown_node": _REFERENCE,
    "unknown_node_in_edge": _REFERENCE,
    "duplicate_node": "a duplicate key: gone once YAML is parsed (the YAML language server flags it itself)",
    "too_many_ticks": "duration_s / tick_s over the tick limit: arithmetic across two fields",
}
"""Bad graphs that parse but that no JSON Schema could reject, with why."""


def document(path: Path):
    """The document the loader reads from ``path``; SafeYamlError (or a constructor error) if none."""
    root = compose(read_graph_text(path))
    return None if root is None else Located(str(path)).convert(root)


def parsed(path: Path) -> bool:
    """Whether ``path`` is YAML the loader reads into a document (not: syntax, tags, huge integers)."""
    try:
        document(path)
    except (SafeYamlError, yaml.YAMLError):
        return False
    return True


@pytest.fixture(scope="module")
def validator() -> jsonschema.Draft7Validator:
    schema = graph_schema()
    jsonschema.Draft7Validator.check_schema(schema)
    return jsonschema.Draft7Validator(schema)


def split_corpus(validator: jsonschema.Draft7Validator) -> dict[str, list[str]]:
    out: dict[str, list[str]] = {"unparsed": [], "caught": [], "missed": []}
    for path in BAD:
        if not parsed(path):
            out["unparsed"].append(path.stem)
        elif validator.is_valid(document(path)):
            out["missed"].append(path.stem)
        else:
            out["caught"].append(path.stem)
    return out


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: f"{p.parent.name}/{p.stem}")
def test_every_shipped_graph_is_valid(validator, path):
    errors = [
        f"{'/'.join(map(str, e.absolute_path))}: {e.message}" for e in validator.iter_errors(document(path))
    ]
    assert not errors, errors


def test_the_shipped_graphs_are_all_there():
    assert len(SHIPPED) >= 13 and {"touch", "teleop", "braille", "hand", "chain"} <= {p.stem for p in SHIPPED}


def test_every_expressible_bad_graph_fails_and_the_rest_are_listed_with_why(validator):
    split = split_corpus(validator)
    assert sorted(split["missed"]) == sorted(INEXPRESSIBLE), (
        "the schema passes a bad graph not listed as inexpressible, or now catches one that is listed"
    )
    assert len(split["caught"]) >= 35 and len(BAD) == sum(map(len, split.values()))


def test_the_doc_quotes_the_counts(validator):
    split = split_corpus(validator)
    text = (ROOT / "docs" / "schema.md").read_text()
    said = re.search(
        r"of the (\d+) graphs .*?, (\d+) fail the schema.*?(\d+) are not YAML.*?(\d+) break", text, re.S
    )
    assert said, "docs/schema.md lost its counts sentence"
    assert [int(x) for x in said.groups()] == [
        len(BAD),
        len(split["caught"]),
        len(split["unparsed"]),
        len(split["missed"]),
    ]


@pytest.mark.parametrize("name", block_names())
def test_each_parameter_rejects_the_values_its_config_rejects(validator, name):
    """The conformance suite's invalid values (wrong types, broken ranges, even windows) are
    rejected by the parameter's schema too; NaN aside (:data:`INEXPRESSIBLE`), none gets through."""
    cls = load_block(name)
    props = validator.schema["definitions"][f"params_{name}"]["properties"]
    through = [
        (field, value)
        for field, value in cls.config_cls.invalid_values()
        if not (isinstance(value, float) and value != value)
        and jsonschema.Draft7Validator(props[field]).is_valid(value)
    ]
    assert not through, f"{name}: the schema accepts values its config rejects: {through}"


@pytest.mark.parametrize("name", block_names())
def test_each_blocks_defaults_and_example_are_valid(validator, name):
    from flowtact.verify.conformance import example_of

    cls = load_block(name)
    schema = validator.schema["definitions"][f"params_{name}"]
    sub = jsonschema.Draft7Validator(schema)
    params = dict(example_of(cls).params)
    defaults = {k: v for k, v in cls.configure(params).to_dict().items()}
    for given in (params, defaults):
        errors = [e.message for e in sub.iter_errors(json.loads(json.dumps(given)))]
        assert not errors, f"{name}: {errors}"


def test_presets_fill_required_parameters(monkeypatch):
    """A preset given, only what it leaves out is required; without one, all required are."""
    from dataclasses import dataclass

    import flowtact.api as ft
    from flowtact.graphfile import schema as schema_module

    @dataclass(frozen=True)
    class Cfg(ft.Config):
        gain: float = ft.param(doc="gain", gt=0)
        n: int = ft.param(doc="units", ge=1)

    class Toy(ft.Block):
        config_cls = Cfg

    presets = {"lab.big": {"gain": 2.0, "n": 100}, "lab.gain": {"gain": 3.0}}
    monkeypatch.setattr(schema_module, "presets_for", lambda name: presets if name == "toy" else {})
    check = jsonschema.Draft7Validator(schema_module.params_schema(Toy)).is_valid
    assert (
        check({"gain": 1.0, "n": 3})
        and check({"preset": "lab.big"})
        and check({"preset": "lab.gain", "n": 2})
    )
    assert not check({"gain": 1.0})  # n missing, no preset
    assert not check({"preset": "lab.gain"})  # the preset leaves n out
    assert not check({"preset": "lab.nope", "gain": 1.0, "n": 2})
    assert not check({"gain": 0, "n": 2})  # gt=0


def test_a_preset_is_one_of_the_blocks(validator):
    node = {"nodes": {"a": {"block": "weighted_sum", "params": {"preset": "touch.SA1"}}}}
    assert validator.is_valid(node)
    node["nodes"]["a"]["params"] = {"preset": "touch.SA9"}
    assert not validator.is_valid(node)


def test_shards_only_on_a_shardable_block(validator):
    ok = {"nodes": {"a": {"block": "nlif", "params": {"preset": "touch.SA1", "n": 4}, "shards": 2}}}
    assert validator.is_valid(ok)
    bad = {"nodes": {"a": {"block": "savgol", "shards": 2}}}
    assert not validator.is_valid(bad)


def test_the_command_writes_the_schema(tmp_path, capsys):
    out = tmp_path / "graph.schema.json"
    assert main(["schema", "-o", str(out)]) == 0
    assert capsys.readouterr().out == f"wrote {out}\n"
    assert json.loads(out.read_text()) == json.loads(json.dumps(graph_schema()))
    assert main(["schema"]) == 0
    assert json.loads(capsys.readouterr().out)["$schema"] == "http://json-schema.org/draft-07/schema#"


def test_an_unwritable_output_is_a_usage_error(tmp_path, capsys):
    assert main(["schema", "-o", str(tmp_path / "no" / "such" / "x.json")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "-o " in err and "Traceback" not in err


def test_a_block_that_does_not_load_is_left_out_and_named(tmp_path, capsys, monkeypatch):
    from flowtact.graphfile import schema as schema_module

    monkeypatch.setattr(schema_module, "block_names", lambda: ["savgol", "broken_one"])
    assert main(["schema", "-o", str(tmp_path / "s.json")]) == 0
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "left out block 'broken_one'" in err[0] and "unknown block" in err[0]
    written = json.loads((tmp_path / "s.json").read_text())
    assert written["properties"]["nodes"]["additionalProperties"] == {"$ref": "#/definitions/node"}
    assert [k for k in written["definitions"] if k.startswith("params_")] == ["params_savgol"]
