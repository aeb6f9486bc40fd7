"""``nlif``'s ``models:`` parameter: one preset per unit, turned into per-unit parameter values.

A domain publishes ``nlif`` presets (``flowtact.presets``); ``models: [SA1.0, RA.3, …]`` names one per
unit (``DOMAIN.NAME``, or ``NAME`` when one domain has it). Parameters that ``nlif`` takes per unit
(τ, v_leak, gain, σ, threshold, post-spike weights) become lists; every other parameter must be the
same in all the named presets (or be given explicitly), since one population has one of each.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from flowtact.catalog.presets import presets_for

__all__ = ["PER_UNIT", "per_unit_models", "resolve_model"]

#: The parameters a population may hold per unit.
PER_UNIT = ("tau_s", "v_leak", "gain", "sigma", "threshold", "h_weights")


def resolve_model(name: str, known: Mapping[str, Mapping[str, Any]]) -> str | None:
    """The ``DOMAIN.NAME`` key of preset ``name`` (given with or without its domain), or None."""
    if name in known:
        return name
    hits = [key for key in known if key.split(".", 1)[1] == name]
    return hits[0] if len(hits) == 1 else None


def per_unit_models(config: Any, models: tuple[str, ...], given: Mapping[str, Any]) -> dict[str, Any]:
    """Parameter values from the presets ``models`` (one per unit): per-unit keys as lists, shared
    keys as one value; keys set in ``given`` (not None) are skipped. Raises the config's error."""
    known = presets_for("nlif")
    params = []
    for i, name in enumerate(models):
        key = resolve_model(name, known)
        if key is None:
            raise config.error("models", f"item {i}: {name!r} is not an nlif preset")
        params.append(known[key])
    out: dict[str, Any] = {}
    keys = sorted({k for p in params for k in p})
    for key in keys:
        if given.get(key) is not None:
            continue
        values = [p.get(key) for p in params]
        if key in PER_UNIT:
            if any(v is None for v in values):
                raise config.error("models", f"{key!r} is set by some models and not others")
            out[key] = [tuple(v) if isinstance(v, (list, tuple)) else v for v in values]
        elif any(v != values[0] for v in values):
            raise config.error(
                "models", f"{key!r} differs between the models ({values[0]!r}, …): give it explicitly"
            )
        else:
            out[key] = values[0]
    if "h_weights" in out and len({len(w) for w in out["h_weights"]}) != 1:
        raise config.error("models", "the models' h_weights have different lengths")
    return out
