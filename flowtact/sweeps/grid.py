"""The rows of a sweep: a Cartesian product of ``--set-grid`` axes, table rows and replayed recordings.

A row is a set of parameter values (``node.param`` -> value, parsed by the loader ``--set`` uses)
and, per replayed node, one recording; its :attr:`Row.key` names it stably for resume and seeding.
"""

from __future__ import annotations

import csv
import glob
import itertools
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from flowtact.errors import SafeYamlError, SweepSpecError
from flowtact.graphfile.graph import parse_override
from flowtact.graphfile.replay_spec import split_replay
from flowtact.graphfile.safe_yaml import load_value, read_graph_text

__all__ = [
    "Axis",
    "Row",
    "expand_replays",
    "override_text",
    "parse_grid",
    "read_table",
    "rows",
]

MAX_ROWS = 1_000_000
"""A sweep larger than this is refused before anything runs (a typo in a grid, not an experiment)."""


@dataclass(frozen=True)
class Axis:
    """One ``--set-grid`` axis: ``node.param`` and the values it takes."""

    name: str
    values: tuple[Any, ...]


@dataclass(frozen=True)
class Row:
    """One run of a sweep: parameter values and the recording each replayed node plays."""

    params: dict[str, Any] = field(default_factory=dict)
    recordings: dict[str, str] = field(default_factory=dict)

    @property
    def key(self) -> str:
        """Canonical text of the parameters and recordings: the same row always has the same key."""
        return json.dumps(
            {"params": self.params, "recordings": self.recordings}, sort_keys=True, separators=(",", ":"),
            default=str,
        )  # fmt: skip

    def overrides(self) -> list[str]:
        """The row's parameters as ``--set`` strings."""
        return [f"{name}={override_text(v)}" for name, v in self.params.items()]


def override_text(value: Any) -> str:
    """A parsed value back as YAML flow text that the ``--set`` loader reads to the same value."""
    if isinstance(value, float) and math.isfinite(value):
        return repr(value)
    return yaml.safe_dump(value, default_flow_style=True, width=math.inf).removesuffix("\n...\n").strip()


def parse_grid(items: Sequence[str]) -> list[Axis]:
    """``node.param=v1,v2,...`` strings -> axes; values are read as one YAML flow list (``[v1, v2]``),
    so quoting and nested lists work as in ``--set``."""
    axes: list[Axis] = []
    for item in items:
        text = item.strip()
        node_param, sep, values = text.partition("=")
        if not sep or not values.strip():
            raise SweepSpecError(f"--set-grid '{item}': expected node.param=v1,v2,...")
        try:
            node, param, parsed = parse_override(f"{node_param}=[{values}]")
        except ValueError as e:
            raise SweepSpecError(f"--set-grid '{item}': {str(e).partition(': ')[2] or e}") from None
        if not isinstance(parsed, list) or not parsed:
            raise SweepSpecError(f"--set-grid '{item}': expected node.param=v1,v2,...")
        name = f"{node}.{param}"
        if any(a.name == name for a in axes):
            raise SweepSpecError(f"--set-grid '{item}': {name} is swept twice")
        if len(set(map(override_text, parsed))) != len(parsed):
            raise SweepSpecError(f"--set-grid '{item}': a value is listed twice")
        axes.append(Axis(name, tuple(parsed)))
    return axes


def _check_name(name: str, where: str) -> str:
    node, dot, param = str(name).strip().partition(".")
    if not dot or not node or not param or "=" in name:
        raise SweepSpecError(f"{where}: column '{name}' is not node.param")
    return f"{node}.{param}"


def read_table(path: str | Path) -> list[dict[str, Any]]:
    """Rows of ``node.param`` values from a YAML list of mappings or a CSV file with a header
    (each CSV cell read by the ``--set`` loader, so ``0.01`` is a number and ``touch`` text; an
    empty cell leaves that parameter as the graph has it)."""
    p = Path(path)
    try:
        text = read_graph_text(p)  # the graph file's limits: size, depth, aliases
    except (OSError, SafeYamlError) as e:
        raise SweepSpecError(
            f"--table {p}: {getattr(e, 'message', None) or getattr(e, 'strerror', e)}"
        ) from None
    if p.suffix.lower() == ".csv":
        reader = csv.DictReader(text.splitlines())
        if not reader.fieldnames:
            raise SweepSpecError(f"--table {p}: no header row")
        out = []
        for i, rec in enumerate(reader, start=2):
            if None in rec or any(v is None for v in rec.values()):
                raise SweepSpecError(f"--table {p}:{i}: the row does not have one cell per column")
            try:
                out.append(
                    {_check_name(k, f"--table {p}"): load_value(v) for k, v in rec.items() if v.strip()}
                )
            except SafeYamlError as e:
                raise SweepSpecError(f"--table {p}:{i}: {e.message}") from None
        rows_ = out
    elif p.suffix.lower() in (".yaml", ".yml"):
        try:
            doc = load_value(text)
        except SafeYamlError as e:
            raise SweepSpecError(f"--table {p}:{e.line}:{e.col}: {e.message}") from None
        if not isinstance(doc, list) or not all(isinstance(r, dict) for r in doc):
            raise SweepSpecError(f"--table {p}: expected a list of mappings of node.param: value")
        rows_ = [{_check_name(k, f"--table {p}"): v for k, v in r.items()} for r in doc]
    else:
        raise SweepSpecError(f"--table {p}: expected a .yaml, .yml or .csv file")
    if not rows_:
        raise SweepSpecError(f"--table {p}: the table has no rows")
    return rows_


def expand_replays(replays: Mapping[str, str]) -> dict[str, list[str]]:
    """``{node: "GLOB[:MAP]"}`` -> ``{node: [each matching file[:MAP], sorted]}``; a pattern that
    matches nothing is an error naming it."""
    out: dict[str, list[str]] = {}
    for node, text in replays.items():
        pattern, port_map = split_replay(text)
        matches = sorted(glob.glob(str(Path(pattern).expanduser()), recursive=True))
        matches = [m for m in matches if Path(m).is_file()]
        if not matches:
            raise SweepSpecError(f"--replay {node}={text}: no file matches '{pattern}'")
        out[node] = [f"{m}:{port_map}" if port_map else m for m in matches]
    return out


def rows(
    axes: Sequence[Axis] = (),
    table: Sequence[Mapping[str, Any]] = (),
    replays: Mapping[str, Sequence[str]] | None = None,
) -> list[Row]:
    """Every combination of table row × grid point × recording per replayed node, in a stable order."""
    replays = replays or {}
    table_rows: list[Mapping[str, Any]] = list(table) or [{}]
    grid_names = {a.name for a in axes}
    for r in table_rows:
        if both := sorted(grid_names & set(r)):
            raise SweepSpecError(f"{both[0]} is in both --table and --set-grid")
    n = len(table_rows) * math.prod(len(a.values) for a in axes) * math.prod(map(len, replays.values()))
    if n > MAX_ROWS:
        raise SweepSpecError(f"the sweep has {n:,} runs; at most {MAX_ROWS:,} are allowed")
    out = []
    for trow in table_rows:
        for point in itertools.product(*(a.values for a in axes)):
            params = {**trow, **{a.name: v for a, v in zip(axes, point, strict=True)}}
            for recs in itertools.product(*replays.values()):
                out.append(Row(dict(params), dict(zip(replays, recs, strict=True))))
    seen: set[str] = set()
    for r in out:
        if r.key in seen:
            raise SweepSpecError(f"the sweep lists the same run twice: {r.key}")
        seen.add(r.key)
    return out
