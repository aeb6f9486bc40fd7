"""``flowtact plot``: one figure of a recording on a shared time axis (after Rager et al., Fig. 4).

A panel per sample stream (a line per channel, labelled, in the stream's units; frames are shown
as their mean intensity), and for every event stream a spike raster (one row per unit) followed by
a panel of firing rates in 20 ms bins (a line per unit up to 8 units, else the population mean
per unit). matplotlib is the optional ``plot`` extra and is imported only here, with its Agg
canvas (no GUI, no global backend switch).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from flowtact.record import RecordedStream, Recording, read_recording

__all__ = ["RATE_BIN_S", "binned_rates", "plot_recording", "recording_figure"]

#: Width of the firing-rate bins (the paper's figures use 20 ms).
RATE_BIN_S = 0.02
#: Lines longer than this are drawn as a min/max envelope of this many points.
MAX_POINTS = 20_000
#: Event streams with more units than this get one population-mean rate line.
MAX_RATE_LINES = 8
WIDTH_IN = 10.0
DPI = 110


@dataclass(frozen=True)
class _Panel:
    kind: str  # "samples", "frames", "raster" or "rate"
    name: str
    stream: RecordedStream
    height: float


def _need_matplotlib() -> tuple[Any, Any]:
    try:
        import matplotlib  # noqa: F401  (the extra itself: fails first when it is missing)
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        raise ImportError("plotting recordings needs matplotlib: pip install 'flowtact[plot]'") from None
    return Figure, FigureCanvasAgg


def binned_rates(
    t: np.ndarray, unit: np.ndarray, n_units: int, t0: float, t1: float, bin_s: float = RATE_BIN_S
) -> tuple[np.ndarray, np.ndarray]:
    """Firing rate of each unit (spikes/s) in bins of ``bin_s`` from ``t0``: (bin starts, (bins, units))."""
    n_bins = max(int(np.ceil((t1 - t0) / bin_s - 1e-9)), 1)
    edges = t0 + bin_s * np.arange(n_bins + 1)
    keep = (t >= t0) & (t < edges[-1]) & (unit >= 0) & (unit < n_units)
    b = np.clip(np.searchsorted(edges, t[keep], side="right") - 1, 0, n_bins - 1)
    counts = np.zeros((n_bins, n_units))
    np.add.at(counts, (b, unit[keep].astype(np.int64)), 1.0)
    return edges[:-1], counts / bin_s


def _envelope(t: np.ndarray, y: np.ndarray, max_points: int = MAX_POINTS) -> tuple[np.ndarray, np.ndarray]:
    """At most ``max_points`` points keeping each bucket's min and max (spikes stay visible)."""
    n = len(t)
    if n <= max_points:
        return t, y
    size = int(np.ceil(n / (max_points // 2)))
    m = n // size
    yb = y[: m * size].reshape(m, size, *y.shape[1:])
    tb = t[: m * size : size]
    lo, hi = yb.min(axis=1), yb.max(axis=1)
    tt = np.repeat(tb, 2)
    yy = np.empty((2 * m, *y.shape[1:]), y.dtype)
    yy[0::2], yy[1::2] = lo, hi
    return tt, yy


def _crop(s: RecordedStream, t0: float, t1: float) -> tuple[np.ndarray, np.ndarray]:
    i, j = np.searchsorted(s.t, [t0, t1], side="left")
    j = min(j + 1, len(s.t))  # one sample past the end keeps lines to the edge
    return s.t[i:j], s.data[i:j]


def event_units(data: np.ndarray) -> np.ndarray:
    """The unit of each event: the data itself, or the first column of multi-column events (pulses)."""
    return data if data.ndim == 1 else data[:, 0]


def _units(units: str) -> str:
    return "" if units in ("", "1") else f" [{units}]"


def _panels(rec: Recording) -> list[_Panel]:
    out = []
    for name, s in rec.streams.items():
        if s.spec.events:
            n = max(s.spec.n_units or 1, 1)
            out.append(_Panel("raster", name, s, float(np.clip(0.9 + 0.05 * n, 1.1, 3.5))))
            out.append(_Panel("rate", name, s, 1.4))
        else:
            out.append(_Panel("frames" if s.data.ndim > 2 else "samples", name, s, 1.8))
    return out


def recording_figure(
    source: str | Path | Recording,
    streams: Sequence[str] | None = None,
    t_range: tuple[float | None, float | None] | None = None,
) -> Any:
    """The figure (a matplotlib Figure on an Agg canvas) of a recording or of its named streams."""
    Figure, FigureCanvasAgg = _need_matplotlib()
    rec = source if isinstance(source, Recording) else read_recording(source, streams)
    if isinstance(source, Recording) and streams is not None:
        missing = [n for n in streams if n not in rec.streams]
        if missing:
            raise KeyError(f"no stream {missing[0]!r} (available: {', '.join(rec.streams)})")
        rec = Recording(rec.path, {n: rec.streams[n] for n in streams}, rec.provenance, rec.summary)
    panels = _panels(rec)
    if not panels:
        raise ValueError(f"{rec.path}: nothing to plot (the recording holds no streams)")

    ends = [max(s.end_s or 0.0, float(s.t[-1]) if len(s.t) else 0.0) for s in rec.streams.values()]
    t0 = 0.0 if t_range is None or t_range[0] is None else float(t_range[0])
    t1 = max(ends) if t_range is None or t_range[1] is None else float(t_range[1])
    if not t1 > t0:
        t1 = t0 + 1.0 if t_range is None or t_range[1] is None else t1
        if not t1 > t0:
            raise ValueError(f"empty time range: from {t0:g} s to {t1:g} s")

    heights = [p.height for p in panels]
    fig = Figure(figsize=(WIDTH_IN, min(sum(heights) + 1.0, 40.0)), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(panels), 1, sharex=True, squeeze=False, gridspec_kw={"height_ratios": heights})[
        :, 0
    ]
    for ax, p in zip(axes, panels, strict=True):
        _draw(ax, p, t0, t1)
        ax.grid(True, alpha=0.25, linewidth=0.5)
        ax.tick_params(labelsize=8)
    axes[-1].set_xlim(t0, t1)
    axes[-1].set_xlabel("time [s]")
    graph = rec.provenance.get("graph_name")
    title = Path(rec.path).name + (f" — graph {graph}" if graph else "")
    if not rec.complete:
        title += " (incomplete: the run did not close the recording)"
    fig.suptitle(title, fontsize=10)
    return fig


def _draw(ax: Any, p: _Panel, t0: float, t1: float) -> None:
    s, spec = p.stream, p.stream.spec
    if p.kind in ("samples", "frames"):
        t, y = _crop(s, t0, t1)
        y = y.astype(np.float64, copy=False)
        if p.kind == "frames":
            y = y.reshape(len(y), -1).mean(axis=1)
            ax.set_title(f"{p.name}: mean intensity per frame", loc="left", fontsize=9)
        else:
            ax.set_title(f"{p.name}{_units(spec.units)}", loc="left", fontsize=9)
        y2 = y.reshape(len(y), -1)
        tt, yy = _envelope(t, y2)
        k = y2.shape[1]
        labels = list(spec.labels) if spec.labels and len(spec.labels) == k else [str(i) for i in range(k)]
        for i in range(k):
            ax.plot(tt, yy[:, i], linewidth=0.9 if k <= 8 else 0.5, label=labels[i])
        if 1 < k <= 8 or (spec.labels and k <= 8):
            ax.legend(loc="upper right", fontsize=7, ncols=min(k, 4), frameon=False)
        ax.set_ylabel(spec.units if spec.units not in ("", "1") else "value", fontsize=8)
    elif p.kind == "raster":
        n = max(spec.n_units or 1, 1)
        keep = (s.t >= t0) & (s.t < t1)
        ax.plot(
            s.t[keep],
            event_units(s.data)[keep],
            linestyle="none",
            marker="|",
            markersize=float(np.clip(100.0 / n, 2.0, 10.0)),
            color="k",
        )
        ax.set_ylim(n - 0.5, -0.5)
        ax.set_ylabel("unit", fontsize=8)
        if spec.labels and s.data.ndim == 1 and len(spec.labels) == n and n <= 24:
            ax.set_yticks(range(n), list(spec.labels))
        elif n <= 8:
            ax.set_yticks(range(n))
        ax.set_title(f"{p.name}: spikes ({int(keep.sum())} in view, {n} units)", loc="left", fontsize=9)
    else:
        n = max(spec.n_units or 1, 1)
        starts, rates = binned_rates(s.t, event_units(s.data), n, t0, t1)
        x = np.append(starts, starts[-1] + RATE_BIN_S)
        if n <= MAX_RATE_LINES:
            labels = (
                list(spec.labels)
                if spec.labels and s.data.ndim == 1 and len(spec.labels) == n
                else [f"unit {i}" for i in range(n)]
            )
            for i in range(n):
                ax.stairs(rates[:, i], x, label=labels[i], linewidth=1.0)
            if n > 1:
                ax.legend(loc="upper right", fontsize=7, ncols=min(n, 4), frameon=False)
        else:
            ax.stairs(rates.mean(axis=1), x, label=f"mean of {n} units", linewidth=1.0, color="C3")
            ax.legend(loc="upper right", fontsize=7, frameon=False)
        ax.set_ylabel("spikes/s", fontsize=8)
        ax.set_ylim(bottom=0)
        ax.set_title(f"{p.name}: firing rate, {RATE_BIN_S * 1000:g} ms bins", loc="left", fontsize=9)


def plot_recording(
    path: str | Path,
    out: str | Path,
    streams: Iterable[str] | None = None,
    t_range: tuple[float | None, float | None] | None = None,
) -> Path:
    """Plot a recording to an image file (.png, .svg or .pdf, by suffix); return its path."""
    fig = recording_figure(path, list(streams) if streams else None, t_range)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=DPI)
    return out
