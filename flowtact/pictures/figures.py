"""Figures other packages register for ``flowtact plot --figure NAME`` (entry-point group
``flowtact.figures``): a domain's paper figure lives with its domain, the framework knows only
the group. A figure is a callable ``draw(figure_cls, sources, t0, t1) -> Figure``: ``figure_cls``
matplotlib's Figure class, ``sources`` the recording's streams by name
(:class:`flowtact.pictures.bounded_read.StreamSource`, read in bounded memory), ``t0``–``t1`` the
time span shown; a ValueError says what the recording lacks."""

from __future__ import annotations

import difflib
from collections.abc import Callable
from typing import Any

from flowtact.errors import UsageError

__all__ = ["GROUP", "figure_entry_points", "load_figure"]

GROUP = "flowtact.figures"

Draw = Callable[[Any, dict[str, Any], float, float], Any]


def figure_entry_points() -> dict[str, Any]:
    """The registered figures: name -> entry point (not loaded)."""
    from importlib.metadata import entry_points

    return {ep.name: ep for ep in sorted(entry_points(group=GROUP), key=lambda ep: ep.name)}


def load_figure(name: str) -> Draw:
    """The figure registered as ``name``; a UsageError (``--figure NAME: ...``, with a did-you-mean
    and the registered names) when there is none."""
    eps = figure_entry_points()
    if name not in eps:
        close = difflib.get_close_matches(name, list(eps), n=1)
        guess = f" (did you mean '{close[0]}'?)" if close else ""
        have = ", ".join(eps) or "none installed"
        raise UsageError(f"--figure {name}: no such figure{guess}; registered figures: {have}")
    return eps[name].load()
