"""The compact paper-style touch/slip figure (after Rager et al., Fig. 4): force, its derivative,
a spike raster per afferent population and their firing rates, stacked on one time axis.

Registered as figure ``paper`` (entry-point group ``flowtact.figures``): ``flowtact plot REC.h5
--paper -o fig.png`` is ``--figure paper``.

Streams are picked by what they are, not by name alone: the force is ``force.f`` or the first
sample stream in N, its derivative the first in N/s, the afferents every spike event stream
(pulse streams excluded). Reading goes through :mod:`flowtact.pictures.bounded_read` (bounded memory).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from flowtact.pictures.bounded_read import (
    StreamSource,
    binned_event_counts,
    event_points,
    index_range,
    sample_envelope,
)
from flowtact.pictures.panels import MAX_EVENT_TICKS, channel_names, rate_bin_s
from flowtact.pictures.units import pretty_units

__all__ = ["paper_figure", "paper_streams"]

WIDTH_IN = 3.6  # one journal column
DPI = 300  # print resolution
FONT = 7


def paper_streams(
    sources: dict[str, StreamSource],
) -> tuple[StreamSource, StreamSource | None, list[StreamSource]]:
    """The force, its derivative (or None) and the spike streams; ValueError if force or spikes lack."""
    samples = [s for s in sources.values() if not s.spec.events]
    force = sources.get("force.f")
    if force is None or force.spec.events:
        force = next((s for s in samples if s.spec.units == "N" and s.spec.size <= 3), None)
    deriv = next((s for s in samples if s.spec.units == "N/s"), None)
    spikes = [s for s in sources.values() if s.spec.events and s.data.ndim == 1]
    if force is None or not spikes:
        lacking = "a force stream in N" if force is None else "a spike event stream"
        have = ", ".join(f"{n} ({s.spec.describe()})" for n, s in sources.items())
        raise ValueError(
            f"the paper figure needs {lacking} (a touch or slip recording); this one has: {have}"
        )
    return force, deriv, spikes


def _afferent(s: StreamSource) -> str:
    return s.name.split(".", 1)[0].upper()


def _lines(ax: Any, s: StreamSource, t0: float, t1: float, legend: bool) -> None:
    env = sample_envelope(s, *index_range(s, t0, t1))
    for k, name in enumerate(channel_names(s.name, s.spec)):
        ax.plot(env.t, env.y[:, k], linewidth=0.8, label=name, color=f"C{k}")
    if legend and s.spec.size > 1:
        ax.legend(fontsize=FONT - 1, frameon=False, ncols=s.spec.size, loc="upper right", handlelength=1.2)


def _raster(ax: Any, s: StreamSource, t0: float, t1: float) -> None:
    n = max(s.spec.n_units or 1, 1)
    i, j = index_range(s, t0, t1)
    if j - i <= MAX_EVENT_TICKS:
        t, u = event_points(s, i, j)
        ax.plot(
            t, u, linestyle="none", marker="|", markersize=max(1.5, 60.0 / n), color="k", markeredgewidth=0.6
        )
    else:
        counts = binned_event_counts(s, i, j, n, np.linspace(t0, t1, 501))
        ax.imshow(
            counts.T, aspect="auto", extent=(t0, t1, n - 0.5, -0.5), cmap="Greys", interpolation="nearest"
        )
    ax.set_ylim(n - 0.5, -0.5)
    ax.set_yticks([0, n - 1])
    ax.set_ylabel(f"{_afferent(s)}\nunit", fontsize=FONT)


def paper_figure(figure_cls: Any, sources: dict[str, StreamSource], t0: float, t1: float) -> Any:
    """Force, dF/dt, one raster per afferent population, population rates: a column-wide figure."""
    force, deriv, spikes = paper_streams(sources)
    kinds = ["force"] + (["deriv"] if deriv else []) + ["raster"] * len(spikes) + ["rate"]
    heights = {"force": 1.0, "deriv": 1.0, "raster": 0.9, "rate": 1.0}
    ratios = [heights[k] for k in kinds]
    fig = figure_cls(figsize=(WIDTH_IN, sum(ratios) * 1.05 + 0.8), dpi=DPI, layout="constrained")
    axes = fig.subplots(len(kinds), 1, sharex=True, height_ratios=ratios)
    rows = iter(axes)
    ax = next(rows)
    _lines(ax, force, t0, t1, legend=True)
    ax.set_ylabel(f"force\n[{pretty_units(force.spec.units)}]", fontsize=FONT)
    if deriv is not None:
        ax = next(rows)
        _lines(ax, deriv, t0, t1, legend=deriv.spec.labels != force.spec.labels)
        ax.set_ylabel(f"dF/dt\n[{pretty_units(deriv.spec.units)}]", fontsize=FONT)
    for s in spikes:
        _raster(next(rows), s, t0, t1)
    ax = next(rows)
    bin_s = rate_bin_s(t0, t1)
    edges = t0 + bin_s * np.arange(int(np.ceil((t1 - t0) / bin_s - 1e-9)) + 1)
    for k, s in enumerate(spikes):
        n = max(s.spec.n_units or 1, 1)
        counts = binned_event_counts(s, *index_range(s, t0, t1), n, edges)
        ax.stairs(
            counts.mean(axis=1) / bin_s, edges, label=f"{_afferent(s)} (mean of {n})", color=f"C{k + 3}"
        )
    ax.legend(fontsize=FONT - 1, frameon=False, loc="upper right")
    ax.set_ylabel(f"rate [1/s]\n{bin_s * 1000:.3g} ms bins", fontsize=FONT)
    ax.set_ylim(bottom=0)
    ax.set_xlim(t0, t1)
    ax.set_xlabel("time [s]", fontsize=FONT)
    for letter, a in zip("ABCDEFGHIJ", axes, strict=False):
        a.tick_params(labelsize=FONT - 1, length=2)
        a.text(-0.2, 1.0, letter, transform=a.transAxes, fontsize=FONT + 2, fontweight="bold", va="top")
        for side in ("top", "right"):
            a.spines[side].set_visible(False)
    return fig
