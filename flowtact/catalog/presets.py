"""Presets: named parameter sets for blocks, owned by the packages whose science they carry.

A package publishes presets through the ``flowtact.presets`` entry-point group: the entry point's
name is the domain and its object a mapping ``block name -> preset name -> parameters``. A graph
(or ``Block(preset=...)``) names one as ``DOMAIN.NAME``, e.g. ``preset: touch.SA1``; parameters
given beside it override the preset's. Generic blocks so never import a paper's numbers.
"""

from __future__ import annotations

import difflib
from collections.abc import Mapping
from functools import cache
from importlib.metadata import entry_points
from typing import Any

from flowtact.errors import ConfigError
from flowtact.params import did_you_mean

__all__ = ["GROUP", "apply_preset", "presets_for"]

GROUP = "flowtact.presets"


@cache
def _all() -> dict[str, Mapping[str, Mapping[str, Mapping[str, Any]]]]:
    return {ep.name: ep.load() for ep in entry_points(group=GROUP)}


def presets_for(block: str) -> dict[str, Mapping[str, Any]]:
    """Every preset of the block registered as ``block``: ``"DOMAIN.NAME"`` -> parameters."""
    return {
        f"{domain}.{name}": params
        for domain, table in _all().items()
        for name, params in table.get(block, {}).items()
    }


def _hint(name: str, known: Mapping[str, Any]) -> str:
    """What a user most likely meant by an unknown preset ``name``, as `` (did you mean …?)``.

    Preset names are ``DOMAIN.NAME`` where NAME may be ``FAMILY.MODEL`` (``touch.SA1.2``): a model
    family is what a misspelling most often means (``SA2``, ``touch.RA``, ``SA1.9``), so the closest
    family is suggested with all its presets, not one model of it picked by string likeness. A bare
    NAME of an existing preset (spelt before presets had domains) gets its full name.
    """
    short = {k.split(".", 1)[1]: k for k in known}
    domains = {k.split(".", 1)[0] for k in known}
    head, _, tail = name.partition(".")
    bare = tail if head in domains and tail else name
    if bare in short:
        return f" (did you mean '{short[bare]}'?)"
    families: dict[str, list[str]] = {}
    for n, full in short.items():
        families.setdefault(n.split(".", 1)[0], []).append(full)
    close = difflib.get_close_matches(bare.split(".", 1)[0], list(families), n=1, cutoff=0.6)
    if not close:
        return did_you_mean(name, known)
    members = sorted(families[close[0]], key=lambda k: (k.count("."), k))
    if len(members) == 1:
        return f" (did you mean '{members[0]}'?)"
    return f" (did you mean one of the {close[0]} presets: {', '.join(members)}?)"


def apply_preset(block: str, params: Mapping[str, Any], owner: str) -> dict[str, Any]:
    """``params`` with its ``preset`` entry replaced by that preset's values (given ones win)."""
    if "preset" not in params:
        return dict(params)
    name = params["preset"]
    known = presets_for(block)
    if not isinstance(name, str) or name not in known:
        hint = _hint(str(name), known) if known else f" (block {block} has no presets)"
        raise ConfigError(
            owner, "preset", f"must name a preset of {block} as DOMAIN.NAME; got {name!r}{hint}"
        )
    rest = {k: v for k, v in params.items() if k != "preset"}
    return {**known[name], **rest}
