"""Graph files read and parsed under hard limits, so hostile input is refused at its place, fast.

A graph file is small. Reading takes at most :data:`MAX_GRAPH_BYTES` (a bounded read, so
``/dev/zero``, a FIFO or a 50 MB file are refused at once), the text must be UTF-8 without NUL
or other control characters, and the YAML is composed by :class:`LimitedLoader`, a
``yaml.SafeLoader`` whose composer counts nesting depth and the nodes the document holds once
every alias is expanded (billion laughs), and refuses recursive aliases and complex (collection)
mapping keys. Every error, of every YAML error class, becomes a :class:`SafeYamlError` with a
1-based line and column.
"""

from __future__ import annotations

import os
import re
import stat
from pathlib import Path
from typing import Any

import yaml

from flowtact.errors import SafeYamlError

__all__ = [
    "MAX_DEPTH",
    "MAX_GRAPH_BYTES",
    "MAX_NODES",
    "LimitedLoader",
    "check_text",
    "compose",
    "load_value",
    "read_graph_text",
]

MAX_GRAPH_BYTES = 1 << 20
"""Largest graph file read (1 MiB). The shipped graphs are under 5 KiB."""
MAX_DEPTH = 64
"""Deepest nesting of YAML collections (a graph needs about 6 levels)."""
MAX_NODES = 50_000
"""Most YAML nodes a document may hold with every alias expanded (scalars and collections)."""

# the characters YAML 1.1 forbids in a stream (as yaml.reader.Reader.NON_PRINTABLE)
_NON_PRINTABLE = re.compile("[^\x09\x0a\x0d\x20-\x7e\x85\xa0-\ud7ff\ue000-\ufffd\U00010000-\U0010ffff]")


def read_graph_text(path: str | Path) -> str:
    """The text of a graph file: a regular file of at most :data:`MAX_GRAPH_BYTES` bytes of
    UTF-8 YAML characters; raise :class:`SafeYamlError` (or ``OSError`` if it cannot be read)."""
    st = os.stat(path)  # before opening: opening a FIFO would block until someone writes to it
    if not stat.S_ISREG(st.st_mode):
        raise SafeYamlError("not a regular file (a graph is a YAML file)")
    if st.st_size > MAX_GRAPH_BYTES:
        raise SafeYamlError(_too_large())
    with open(path, "rb") as f:
        data = f.read(MAX_GRAPH_BYTES + 1)  # bounded even if the file grows meanwhile
    if len(data) > MAX_GRAPH_BYTES:
        raise SafeYamlError(_too_large())
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        line, col = _byte_place(data, e.start)
        raise SafeYamlError(
            f"not UTF-8 text: byte 0x{data[e.start]:02x} cannot be decoded", line, col, "save it as UTF-8"
        ) from None
    check_text(text)
    return text


def _too_large() -> str:
    return f"graph file larger than {MAX_GRAPH_BYTES >> 20} MiB"


def _byte_place(data: bytes, offset: int) -> tuple[int, int]:
    """1-based line and column (in characters) of byte ``offset``."""
    start = data.rfind(b"\n", 0, offset) + 1
    col = len(data[start:offset].decode("utf-8", errors="replace")) + 1
    return data.count(b"\n", 0, offset) + 1, col


def _char_place(text: str, index: int) -> tuple[int, int]:
    """1-based line and column of character ``index``."""
    return text.count("\n", 0, index) + 1, index - (text.rfind("\n", 0, index) + 1) + 1


def check_text(text: str) -> None:
    """Refuse text longer than the limit or holding a NUL or another character YAML forbids."""
    if len(text) > MAX_GRAPH_BYTES:
        raise SafeYamlError(_too_large())
    m = _NON_PRINTABLE.search(text)
    if m:
        line, col = _char_place(text, m.start())
        what = "a NUL byte" if m.group() == "\0" else f"control character U+{ord(m.group()):04X}"
        raise SafeYamlError(f"{what} is not allowed in a graph file", line, col)


_PLAIN_COLLECTIONS = ("tag:yaml.org,2002:map", "tag:yaml.org,2002:seq")


class LimitedLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` whose composer enforces :data:`MAX_DEPTH` and :data:`MAX_NODES`,
    refuses recursive aliases and collection keys, and keeps nothing but safe YAML tags."""

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self._depth = 0
        self._nodes = 0
        self._sizes: dict[int, int] = {}  # id(node) -> nodes it holds with aliases expanded
        self._open: set[str] = set()  # anchors of collections still being composed

    def _count(self, n: int, mark: Any) -> None:
        self._nodes += n
        if self._nodes > MAX_NODES:
            raise yaml.composer.ComposerError(
                None,
                None,
                f"the document expands to more than {MAX_NODES} values (aliases expanded); "
                "a graph needs far fewer",
                mark,
            )

    def compose_node(self, parent: Any, index: Any) -> Any:
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            if event.anchor in self._open:
                self.get_event()
                raise yaml.composer.ComposerError(
                    None, None, f"recursive alias '*{event.anchor}' (it refers to itself)", event.start_mark
                )
            node = super().compose_node(parent, index)
            self._count(self._sizes.get(id(node), 1), event.start_mark)
            return node
        event = self.peek_event()
        if event.anchor is not None and event.anchor in self.anchors:
            first = self.anchors[event.anchor].start_mark
            raise yaml.composer.ComposerError(
                None,
                None,
                f"duplicate anchor '&{event.anchor}' (first defined at line {first.line + 1})",
                event.start_mark,
            )
        if self._depth >= MAX_DEPTH:
            raise yaml.composer.ComposerError(
                None, None, f"nested more than {MAX_DEPTH} levels deep", event.start_mark
            )
        anchor = event.anchor if isinstance(event, yaml.CollectionStartEvent) else None
        if anchor is not None:
            self._open.add(anchor)
        self._depth += 1
        before = self._nodes
        self._count(1, event.start_mark)
        try:
            node = super().compose_node(parent, index)
        finally:
            self._depth -= 1
            self._open.discard(anchor)
        if isinstance(node, yaml.CollectionNode) and node.tag not in _PLAIN_COLLECTIONS:
            raise yaml.composer.ComposerError(
                None, None, f"unsupported YAML tag {node.tag!r} (a graph holds plain values)", node.start_mark
            )
        if event.anchor is not None:
            self._sizes[id(node)] = self._nodes - before
        return node

    def compose_mapping_node(self, anchor: Any) -> Any:
        node = super().compose_mapping_node(anchor)
        for key, _ in node.value:
            if not isinstance(key, yaml.ScalarNode):
                raise yaml.composer.ComposerError(
                    None, None, "a mapping key must be a plain value, not a list or mapping", key.start_mark
                )
        return node


def compose(text: str) -> yaml.Node | None:
    """The YAML node tree of ``text`` under the limits; raise :class:`SafeYamlError` located."""
    check_text(text)
    try:
        loader = LimitedLoader(text)
        try:
            return loader.get_single_node()
        finally:
            loader.dispose()
    except yaml.MarkedYAMLError as e:
        mark = e.problem_mark or e.context_mark
        line, col = (mark.line + 1, mark.column + 1) if mark else (1, 1)
        what = e.problem or e.context or "malformed YAML"
        if e.problem and e.context:
            what = f"{e.problem} ({e.context})"
        if e.context and e.context.startswith("expected a single document"):
            what = "a graph file holds one YAML document, but another one starts here"
        if isinstance(e, (yaml.scanner.ScannerError, yaml.parser.ParserError)):
            raise SafeYamlError(
                f"YAML syntax error: {what}", line, col, "check indentation, colons and brackets near here"
            ) from None
        raise SafeYamlError(what, line, col) from None
    except yaml.reader.ReaderError as e:
        line, col = _char_place(text, e.position)
        raise SafeYamlError(f"YAML: {e.reason}", line, col) from None
    except yaml.YAMLError as e:
        raise SafeYamlError(f"YAML: {e}") from None
    except RecursionError:  # the depth limit should make this unreachable; refuse rather than crash
        raise SafeYamlError(f"nested more than {MAX_DEPTH} levels deep") from None


def load_value(text: str) -> Any:
    """A plain value (``--set node.param=VALUE``) as ``yaml.safe_load`` gives it, under the same
    limits as a graph file; raise :class:`SafeYamlError` with the problem."""
    root = compose(text)
    if root is None:
        return None
    loader = LimitedLoader("")
    try:
        return loader.construct_document(root)
    except yaml.MarkedYAMLError as e:
        mark = e.problem_mark
        raise SafeYamlError(f"unsupported YAML value: {e.problem}", mark.line + 1, mark.column + 1) from None
    except (ValueError, TypeError, OverflowError) as e:
        raise SafeYamlError(f"unsupported YAML value: {e}") from None
