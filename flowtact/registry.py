"""The block catalogue: block classes found through the ``flowtact.blocks`` entry-point group.

Any installed package can add blocks by declaring entry points in that group; a graph may also
name a class directly as ``package.module:Class``.
"""

from __future__ import annotations

import importlib
from functools import cache
from importlib.metadata import entry_points

from flowtact.block import Block
from flowtact.errors import FlowtactError
from flowtact.params import did_you_mean

__all__ = ["UnknownBlockError", "block_names", "load_block"]

GROUP = "flowtact.blocks"


class UnknownBlockError(FlowtactError, LookupError):
    """No block of that name is registered (the message suggests the closest one)."""


@cache
def _entry_points() -> dict[str, object]:
    return {ep.name: ep for ep in entry_points(group=GROUP)}


def block_names() -> list[str]:
    """Every registered block name, sorted."""
    return sorted(_entry_points())


def load_block(name: str) -> type[Block]:
    """The block class registered as ``name``, or imported from ``module:Class``."""
    if ":" in name:
        module, _, attr = name.partition(":")
        try:
            cls = getattr(importlib.import_module(module), attr)
        except (ImportError, AttributeError) as e:
            raise UnknownBlockError(f"cannot import block '{name}': {e}") from None
    else:
        ep = _entry_points().get(name)
        if ep is None:
            raise UnknownBlockError(f"unknown block '{name}'{did_you_mean(name, _entry_points())}")
        cls = ep.load()  # type: ignore[attr-defined]
    if not (isinstance(cls, type) and issubclass(cls, Block)):
        raise UnknownBlockError(f"'{name}' is not a flowtact Block")
    return cls
