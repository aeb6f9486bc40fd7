"""YAML read with the file location of every value, and errors reported at those locations.

Every problem found in a graph file is a :class:`GraphProblem` at ``file:line:col``; loaders collect
them and raise one :class:`GraphFileError`. :class:`Located` keeps, beside the plain values that
``yaml.safe_load`` would give, where each value (and each mapping key) was written.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import yaml

from flowtact.params import did_you_mean

__all__ = ["GraphProblem", "Loc", "Located"]


@dataclass(frozen=True)
class Loc:
    """A place in a graph file (1-based line and column)."""

    path: str
    line: int = 1
    col: int = 1

    def __str__(self) -> str:
        return f"{self.path}:{self.line}:{self.col}"


@dataclass(frozen=True)
class GraphProblem:
    """One problem with a graph, at a place, with an optional hint on what would be right."""

    loc: Loc
    message: str
    hint: str = ""

    def __str__(self) -> str:
        text = f"{self.loc}: {self.message}"
        return f"{text}\n    hint: {self.hint}" if self.hint else text


class Located:
    """Plain values plus a location for each YAML node, keyed by the value's path."""

    def __init__(self, path: str) -> None:
        self.path = path
        self.locs: dict[tuple[Any, ...], Loc] = {}
        self.key_locs: dict[tuple[Any, ...], Loc] = {}
        self.errors: list[GraphProblem] = []

    def loc(self, *keys: Any) -> Loc:
        """Location of the value at ``keys`` (or of its closest parent)."""
        while keys not in self.locs and keys:
            keys = keys[:-1]
        return self.locs.get(keys, Loc(self.path))

    def key_loc(self, *keys: Any) -> Loc:
        """Location of the mapping key that introduces ``keys``."""
        return self.key_locs.get(keys, self.loc(*keys))

    def unknown_keys(
        self, mapping: Iterable[Any], allowed: Sequence[str], where: str, *keys: Any
    ) -> list[GraphProblem]:
        """An error at each key of ``mapping`` (the mapping at ``keys``) that is not ``allowed``,
        suggesting the closest allowed one; ``where`` names the mapping in the message."""
        return [
            GraphProblem(self.key_loc(*keys, k), f"{where}: unknown key '{k}'{did_you_mean(str(k), allowed)}")
            for k in mapping
            if k not in allowed
        ]

    def convert(self, node: yaml.Node, keys: tuple[Any, ...] = ()) -> Any:
        mark = node.start_mark
        self.locs[keys] = Loc(self.path, mark.line + 1, mark.column + 1)
        if isinstance(node, yaml.MappingNode):
            out: dict[Any, Any] = {}
            for k_node, v_node in node.value:
                key = _construct(k_node)
                kmark = k_node.start_mark
                kloc = Loc(self.path, kmark.line + 1, kmark.column + 1)
                if key in out:
                    what = "node" if keys == ("nodes",) else "key"
                    self.errors.append(
                        GraphProblem(
                            kloc,
                            f"duplicate {what} '{key}'",
                            f"first defined at {self.key_locs[(*keys, key)]}",
                        )
                    )
                    continue
                self.key_locs[(*keys, key)] = kloc
                out[key] = self.convert(v_node, (*keys, key))
            return out
        if isinstance(node, yaml.SequenceNode):
            return [self.convert(v, (*keys, i)) for i, v in enumerate(node.value)]
        return _construct(node)


_LOADER = yaml.SafeLoader("")


def _construct(node: yaml.Node) -> Any:
    """The plain value of a scalar node as ``yaml.safe_load`` gives it; a value its constructor
    rejects (an out-of-range date, an integer of 5 000 digits) is a ConstructorError at the node."""
    try:
        return yaml.SafeLoader.construct_object(_LOADER, node, deep=True)  # type: ignore[arg-type]
    except (ValueError, TypeError, OverflowError) as e:
        value = node.value if len(node.value) <= 40 else f"{node.value[:37]}..."
        why = str(e).split(";")[0]  # not Python's advice on sys.set_int_max_str_digits
        raise yaml.constructor.ConstructorError(None, None, f"{value!r}: {why}", node.start_mark) from None
    finally:
        _LOADER.constructed_objects.pop(node, None)  # keep no node alive after the load
        _LOADER.recursive_objects.pop(node, None)
