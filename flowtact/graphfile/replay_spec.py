"""The ``--replay NODE=FILE[:PORT=COLUMNS;...]`` syntax: which file stands in for a node, and which
of the file's columns (streams, arrays) feed which of the node's output ports.

``sensor=log.csv`` maps by name (a column ``ref`` feeds port ``ref``; columns ``r[0]``, ``r[1]``, ...
feed port ``r``); ``sensor=log.csv:r=g1,g2,g3,g4;ref=gref`` maps explicitly. The block that plays
the file (the ``replay`` family) reads the same port-map text, so one parser serves both.
"""

from __future__ import annotations

import re

__all__ = ["format_port_map", "parse_port_map", "split_replay"]

_PORT_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


def split_replay(text: str) -> tuple[str, str]:
    """``FILE[:MAP]`` -> (file, map text); the map is what follows the last ``:`` if it holds ``=``."""
    head, sep, tail = text.rpartition(":")
    if sep and "=" in tail:
        return head, tail
    return text, ""


def parse_port_map(text: str) -> dict[str, tuple[str, ...]]:
    """``"r=r0,r1,r2;ref=ref"`` -> ``{"r": ("r0", "r1", "r2"), "ref": ("ref",)}``.

    Raises ValueError saying what is wrong with which item (an item without ``=``, a port that is
    not an identifier, an empty column name, a port given twice).
    """
    out: dict[str, tuple[str, ...]] = {}
    for item in (s.strip() for s in text.split(";")):
        if not item:
            continue
        port, sep, cols = (s.strip() for s in item.partition("="))
        if not sep:
            raise ValueError(f"'{item}' is not PORT=COLUMN[,COLUMN...]")
        if not _PORT_RE.match(port):
            raise ValueError(f"'{port}' in '{item}' is not a port name")
        columns = tuple(c.strip() for c in cols.split(","))
        if not all(columns):
            raise ValueError(f"'{item}' has an empty column name (columns are separated by ',')")
        if port in out:
            raise ValueError(f"port '{port}' is mapped twice")
        out[port] = columns
    return out


def format_port_map(ports: dict[str, tuple[str, ...]]) -> str:
    """The inverse of :func:`parse_port_map`."""
    return ";".join(f"{p}={','.join(cols)}" for p, cols in ports.items())
