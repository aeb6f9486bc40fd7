"""``flowtact sweep --plot``: mean spike rate per unit of each population across the swept grid.

Two numeric swept parameters make a heat map per population (one panel per value of the other
swept columns, e.g. the scenario or the recording); one makes a line per other value. Axes carry
the parameters' units, read from their names (``tau_s``) or their documentation (``in 1/sqrt(s)``).
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import re
from pathlib import Path
from typing import Any

from flowtact.errors import SweepSpecError

__all__ = ["check_plot_extra", "param_label", "plot_rates"]

MAX_PANELS = 24
RATE_LABEL = "mean rate per unit (events/s)"


def check_plot_extra() -> None:
    """Raise :class:`SweepSpecError` naming the extra when matplotlib is missing."""
    from flowtact.graphfile.extras import install_hint, module_available

    if not module_available("matplotlib"):
        what, how = install_hint("flowtact", "matplotlib", "plot")
        raise SweepSpecError(f"--plot needs {what}: {how}")


def param_label(name: str, graph: Any = None) -> str:
    """``sa1.tau_s`` -> ``sa1.tau (s)``; a parameter without a unit suffix gets the unit its
    documentation names (``... in 1/sqrt(s)``), if the graph is given and it names one."""
    from flowtact.pictures.units import label_unit, pretty_units

    base, unit = label_unit(name)
    if unit is None and graph is not None:
        node, _, param = name.partition(".")
        nd = graph.nodes.get(node)
        fields = {f.name: f for f in dataclasses.fields(nd.config)} if nd is not None else {}
        doc = fields[param].metadata.get("doc", "") if param in fields else ""
        m = re.search(r"\bin (1/sqrt\(s\)|[A-Za-zµ/]+(?:\([^)]*\))?)(?=[\s:,;)]|$)", doc)
        unit = m.group(1) if m else None
    return f"{base} ({pretty_units(unit).replace('sqrt(s)', '√s')})" if unit else name


def _varying(df: Any) -> list[str]:
    """The parameter and recording columns that take more than one value."""
    cols = list(json.loads(df["key"].iloc[0])["params"])
    cols = [c for c in df.columns if c in cols or c.startswith("recording:")]
    return [c for c in cols if df[c].nunique(dropna=False) > 1]


def _numeric(s: Any) -> bool:
    import pandas as pd

    return pd.api.types.is_numeric_dtype(s) and not pd.api.types.is_bool_dtype(s)


def _facet_text(cols: list[str], values: tuple) -> str:
    return ", ".join(
        f"{Path(str(v)).name if c.startswith('recording:') else v}" for c, v in zip(cols, values, strict=True)
    )


def plot_rates(df: Any, path: str | Path, graph: Any = None) -> Path:
    """Draw the ``rate_hz:`` columns of a sweep table across its grid to ``path`` (.png/.svg/.pdf)."""
    check_plot_extra()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rates = [c for c in df.columns if c.startswith("rate_hz:")]
    if not rates:
        raise SweepSpecError("--plot: the table has no rate_hz columns (add the spikes metric)")
    varying = _varying(df)
    numeric = [c for c in varying if _numeric(df[c])][:2]
    facets = [c for c in varying if c not in numeric]
    combos = sorted({tuple(r) for r in df[facets].itertuples(index=False)}, key=str) if facets else [()]
    if len(numeric) == 2:
        if len(combos) * len(rates) > MAX_PANELS:
            raise SweepSpecError(f"--plot: {len(combos) * len(rates)} panels; at most {MAX_PANELS}")
        fig = _heatmaps(plt, df, rates, numeric, facets, combos, graph)
    else:
        fig = _lines(plt, df, rates, numeric[0] if numeric else None, facets, combos, graph)
    out = Path(path)
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out


def _heatmaps(plt: Any, df: Any, rates: list[str], xy: list[str], facets: list[str], combos: list[tuple],
              graph: Any) -> Any:  # fmt: skip
    import numpy as np

    x, y = xy
    xs, ys = sorted(df[x].unique()), sorted(df[y].unique())
    fig, axes = plt.subplots(len(rates), len(combos), figsize=(1.2 + 3.6 * len(combos), 0.6 + 3.0 * len(rates)),
                             squeeze=False, constrained_layout=True)  # fmt: skip
    for i, rate in enumerate(rates):
        grids = []
        for combo in combos:
            sel = df
            for c, v in zip(facets, combo, strict=True):
                sel = sel[sel[c] == v]
            grid = np.full((len(ys), len(xs)), np.nan)
            for _, r in sel.iterrows():
                if r["status"] == "ok":
                    grid[ys.index(r[y]), xs.index(r[x])] = r[rate]
            grids.append(grid)
        finite = [g[np.isfinite(g)] for g in grids]
        vmax = max((float(f.max()) for f in finite if f.size), default=1.0) or 1.0
        for j, grid in enumerate(grids):
            ax = axes[i][j]
            im = ax.imshow(grid, origin="lower", aspect="auto", cmap="viridis", vmin=0, vmax=vmax)
            for (yi, xi), v in np.ndenumerate(grid):
                text = "failed" if math.isnan(v) else f"{v:.3g}"
                ax.text(xi, yi, text, ha="center", va="center", fontsize=8,
                        color="white" if math.isnan(v) or v < 0.6 * vmax else "black")  # fmt: skip
            ax.set_xticks(range(len(xs)), [f"{v:g}" for v in xs])
            ax.set_yticks(range(len(ys)), [f"{v:g}" for v in ys])
            ax.set_xlabel(param_label(x, graph))
            ax.set_ylabel(param_label(y, graph))
            stream = rate.partition(":")[2]
            ax.set_title(f"{stream}{': ' + _facet_text(facets, combos[j]) if facets else ''}", fontsize=10)
        fig.colorbar(im, ax=list(axes[i]), label=RATE_LABEL, shrink=0.9)
    return fig


def _lines(plt: Any, df: Any, rates: list[str], x: str | None, facets: list[str], combos: list[tuple],
           graph: Any) -> Any:  # fmt: skip
    fig, axes = plt.subplots(1, len(rates), figsize=(1.0 + 4.2 * len(rates), 3.6), squeeze=False,
                             constrained_layout=True)  # fmt: skip
    ok = df[df["status"] == "ok"]
    markers = itertools.cycle("os^Dv")
    for ax, rate in zip(axes[0], rates, strict=True):
        for combo, marker in zip(combos, markers, strict=False):
            sel = ok
            for c, v in zip(facets, combo, strict=True):
                sel = sel[sel[c] == v]
            label = _facet_text(facets, combo) or None
            if x is None:
                ax.bar([label or "run"], [sel[rate].mean()])
            else:
                sel = sel.sort_values(x)
                ax.plot(sel[x], sel[rate], marker=marker, label=label)
        ax.set_title(rate.partition(":")[2], fontsize=10)
        ax.set_ylabel(RATE_LABEL)
        if x is not None:
            ax.set_xlabel(param_label(x, graph))
            if facets:
                ax.legend(fontsize=8, loc="best")
    return fig
