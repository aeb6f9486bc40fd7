"""Links: what carries a stream's chunks from a producing node to a consuming one.

The engine (:mod:`flowtact.runtime.engine`) writes the tick schedule once; a link is all it knows
of the way between two nodes. A link is made per edge for the consumer's input, with the inbox the
engine takes that input's due chunks from, and offers:

- ``put(chunk)``: hand on a chunk produced this tick (an attribute, so the hot loop pays one call);
- ``holds``: whether it acts when the tick ends (a delay port's edge keeps what it is given until
  then; a lossless stream to another process closes the tick);
- ``tick_done()``: the tick ended: what it holds is now due (moved into the inbox);
- ``pull(k)``: take what is due by tick ``k`` from elsewhere (another process) into the inbox;
  called before the consumer is gathered, only for a link whose ``pulls`` is true (never for a
  local one: the in-process engine calls no ``pull``);
- ``end()``: the stream ends (the final flush): from now on what it is given is due at once;
- ``done()``: its producer has flushed: nothing more comes (a stream to another process says END);
- ``drop()``: the run was interrupted: what it holds never arrives.

Kinds are found by name in :data:`LINKS` (as Brian2 finds its devices): the built-ins ``local``
(an in-process list) and ``zmq`` (a ZeroMQ socket pair, wire framing) are named here and
imported on first use; another kind (shared memory, LSL,
a browser feed) is one module that subclasses :class:`Link` with :func:`register_link`.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import ClassVar

from flowtact.chunk import Chunk, StreamSpec

__all__ = ["LINKS", "Link", "link_kind", "register_link"]


class Link:
    """One edge's way from a producer to a consumer's inbox (see the module docstring)."""

    kind: ClassVar[str] = ""
    holds: bool = False
    pulls: ClassVar[bool] = False
    put: Callable[[Chunk], None]

    def __init__(self, spec: StreamSpec, inbox: list[Chunk], *, delayed: bool = False) -> None:
        self.spec = spec
        self.inbox = inbox
        self.delayed = delayed

    def tick_done(self) -> None:
        """The tick ended: what this link holds becomes due."""

    def pull(self, k: int) -> None:
        """Move what is due by tick ``k`` into the inbox (a link whose chunks come from elsewhere)."""

    def end(self) -> None:
        """End of stream: what is put from now on is due at once."""

    def done(self) -> None:
        """Its producer has flushed: nothing more comes."""

    def drop(self) -> None:
        """The run was interrupted: forget what is held."""


LINKS: dict[str, type[Link]] = {}
"""Link kinds by name, filled by :func:`register_link` (built-ins on first use, see :func:`link_kind`)."""

_BUILT_IN = {"local": "flowtact.runtime.links.local", "zmq": "flowtact.runtime.links.zeromq.link"}


def register_link(name: str) -> Callable[[type[Link]], type[Link]]:
    """Class decorator: make a :class:`Link` subclass the link kind ``name``."""

    def add(cls: type[Link]) -> type[Link]:
        cls.kind = name
        LINKS[name] = cls
        return cls

    return add


def link_kind(name: str) -> type[Link]:
    """The link class registered as ``name`` (a built-in is imported on first use)."""
    if name not in LINKS and name in _BUILT_IN:
        importlib.import_module(_BUILT_IN[name])
    try:
        return LINKS[name]
    except KeyError:
        raise ValueError(
            f"unknown link kind {name!r} (known: {', '.join(sorted({*LINKS, *_BUILT_IN}))})"
        ) from None
