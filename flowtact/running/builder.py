"""A graph file written in Python: :class:`GraphBuilder` builds the very document a YAML graph holds.

There is one graph model. The builder only assembles the mapping a graph file would contain
(``nodes``, ``edges``, ``record``, ``processes``, ...), and :meth:`GraphBuilder.load` hands it, as
YAML text, to the same loader as ``flowtact run FILE`` (:func:`flowtact.graphfile.graph.load_graph`),
so every rule, message and default is the file's. :meth:`GraphBuilder.to_yaml` writes it out as a
graph file that ``flowtact run`` accepts unchanged; :meth:`GraphBuilder.from_file` starts from one.

.. code-block:: python

    g = GraphBuilder("mine", seed=1, duration_s=1.0)
    g.node("sensor", "aunp_sensor", scenario="touch", rate_hz=1000)
    g.node("force", "gauge_force")
    g.edge("sensor.r -> force.r").record("force.f")
"""

from __future__ import annotations

import copy
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, Self

import yaml

from flowtact.graphfile.graph import EDGE_RE, Graph, load_graph, resolve_graph_path

__all__ = ["GraphBuilder"]


class GraphBuilder:
    """A graph file's document, built node by node; methods return the builder, so calls chain.

    ``name``, ``seed``, ``duration_s``, ``tick_s`` and ``description`` are the graph file's
    top-level keys of the same names (left out when None).
    """

    def __init__(
        self,
        name: str = "python",
        *,
        seed: int | None = None,
        duration_s: float | None = None,
        tick_s: float | None = None,
        description: str | None = None,
    ) -> None:
        self.doc: dict[str, Any] = {"name": name}
        for key, value in (
            ("description", description),
            ("seed", seed),
            ("duration_s", duration_s),
            ("tick_s", tick_s),
        ):
            if value is not None:
                self.doc[key] = value
        self.doc.update(nodes={}, edges=[], record=[])
        self.folder: Path = Path.cwd()
        """Where relative file names in parameters are found: the working directory, or the
        folder of the file :meth:`from_file` read (as for the graph file itself)."""

    @classmethod
    def from_file(cls, source: str | Path) -> GraphBuilder:
        """A builder holding a graph file's document (a path or a shipped graph's name, ``touch``),
        to change before running it; YAML the loader refuses raises its located error."""
        from flowtact.errors import GraphFileError, SafeYamlError
        from flowtact.graphfile.located import GraphProblem, Loc, Located
        from flowtact.graphfile.safe_yaml import compose, read_graph_text

        path = resolve_graph_path(source)
        try:
            root = compose(read_graph_text(path))
        except SafeYamlError as e:
            raise GraphFileError([GraphProblem(Loc(str(path), e.line, e.col), e.message, e.hint)]) from None
        doc = Located(str(path)).convert(root) if root is not None else None
        if not isinstance(doc, dict):
            raise GraphFileError(
                [GraphProblem(Loc(str(path)), "a graph file must be a mapping with 'nodes:'")]
            )
        out = cls()
        out.doc = doc
        for key in ("nodes", "edges", "record"):
            if out.doc.get(key) is None:
                out.doc[key] = {} if key == "nodes" else []
        out.folder = path.resolve().parent
        return out

    @property
    def name(self) -> str:
        return str(self.doc.get("name", "python"))

    def node(
        self,
        name: str,
        block: str,
        params: Mapping[str, Any] | None = None,
        *,
        process: str | list[str] | None = None,
        seed: int | None = None,
        shards: int | None = None,
        doc: str | None = None,
        **more: Any,
    ) -> Self:
        """Add (or replace) node ``name`` running ``block`` with these parameters (``params`` and
        keyword arguments together; a parameter named like a keyword here goes in ``params``)."""
        entry: dict[str, Any] = {"block": block}
        given = {**(params or {}), **more}
        if given:
            entry["params"] = given
        for key, value in (("process", process), ("seed", seed), ("shards", shards), ("doc", doc)):
            if value is not None:
                entry[key] = value
        self.doc["nodes"][name] = entry
        return self

    def set(self, node: str, **params: Any) -> Self:
        """Change some parameters of an existing node (the others keep their values)."""
        entry = self.doc["nodes"].get(node)
        if not isinstance(entry, dict):
            known = ", ".join(map(str, self.doc["nodes"])) or "none"
            raise KeyError(f"no node '{node}' in graph '{self.name}' (nodes: {known})")
        entry["params"] = {**(entry.get("params") or {}), **params}
        return self

    def edge(
        self, src: str, dst: str | None = None, *, policy: str | None = None, queue: int | None = None
    ) -> Self:
        """Add an edge: ``edge("a.y -> b.x")`` or ``edge("a.y", "b.x")``; ``policy`` and ``queue``
        as an edge's in a graph file (crossing processes)."""
        if dst is None:
            m = EDGE_RE.match(src)
            if m is None:
                raise ValueError(f"edge {src!r}: write it as 'node.port -> node.port'")
            src, dst = f"{m.group(1)}.{m.group(2)}", f"{m.group(3)}.{m.group(4)}"
        if policy is None and queue is None:
            self.doc["edges"].append(f"{src} -> {dst}")
        else:
            flow: dict[str, Any] = {"from": src, "to": dst}
            flow.update({k: v for k, v in (("policy", policy), ("queue", queue)) if v is not None})
            self.doc["edges"].append(flow)
        return self

    def record(self, *streams: str) -> Self:
        """Record these ``node.port`` streams (what :func:`flowtact.run` hands back)."""
        for s in streams:
            if s not in self.doc["record"]:
                self.doc["record"].append(s)
        return self

    def process(self, name: str, **settings: Any) -> Self:
        """Settings of process group ``name`` (``restart``, ``max_restarts``, ``stall_s``, ...), as
        under the graph file's ``processes:``."""
        self.doc.setdefault("processes", {})[name] = dict(settings)
        return self

    def document(self) -> dict[str, Any]:
        """A copy of the document: what the graph file would hold."""
        return copy.deepcopy(self.doc)

    def to_yaml(self) -> str:
        """The graph as a YAML graph file (``flowtact run`` runs it as it is)."""
        return yaml.safe_dump(self.document(), sort_keys=False, allow_unicode=True)

    def save(self, path: str | Path) -> Path:
        """Write :meth:`to_yaml` to ``path``; relative file names in parameters then resolve
        against that file's folder, as for any graph file."""
        out = Path(path)
        out.write_text(self.to_yaml(), encoding="utf-8")
        return out

    def load(
        self,
        *,
        overrides: Iterable[str] = (),
        replays: Mapping[str, str] | None = None,
        allow_modules: Iterable[str] = (),
    ) -> Graph:
        """The validated graph (:func:`~flowtact.graphfile.graph.load_graph` on :meth:`to_yaml`);
        a bad graph raises :class:`~flowtact.errors.GraphFileError` listing every problem, located
        in :meth:`to_yaml`'s text under the name ``<python graph NAME>``."""
        label = f"<python graph {self.name}>"
        return load_graph(
            label if self.folder == Path.cwd() else self.folder / label,
            text=self.to_yaml(),
            overrides=overrides,
            replays=replays,
            allow_modules=allow_modules,
        )

    def __repr__(self) -> str:
        return (
            f"GraphBuilder({self.name!r}: {len(self.doc['nodes'])} nodes, "
            f"{len(self.doc['edges'])} edges, record {self.doc['record']})"
        )
