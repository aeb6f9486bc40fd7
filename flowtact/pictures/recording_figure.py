"""``flowtact plot``: one figure of a recording, each stream drawn as what it is, on a shared time axis.

Vector samples are labelled lines per channel in their units, categorical streams steps named on
the axis, spike events rasters with firing rates, stimulation pulses pulse trains, frames a strip
of thumbnails (see :mod:`flowtact.pictures.panels`). The file is read block by block
(:mod:`flowtact.pictures.bounded_read`), so memory stays bounded whatever its size. ``figure=NAME`` draws a
figure a package registered instead (:mod:`flowtact.pictures.figures`). matplotlib is the optional
``plot`` extra, imported only here, with its Agg canvas (no GUI, no global backend switch).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from flowtact.inputs.safe_text import shown
from flowtact.pictures.bounded_read import StreamSource, label, open_recording
from flowtact.pictures.panels import Panel, binned_rates, draw_frames, draw_panel, plan_panels

__all__ = ["DPI", "binned_rates", "need_matplotlib", "plot_recording", "recording_figure", "time_span"]

WIDTH_IN = 11.0
DPI = 110
#: Tallest figure drawn (inches); panels shrink beyond it.
MAX_HEIGHT_IN = 60.0
#: Most streams drawn in one figure (a recording may hold up to 4096): pick some with ``streams``.
MAX_PLOT_STREAMS = 200


def need_matplotlib() -> tuple[Any, Any]:
    """matplotlib's Figure and Agg canvas classes, or an ImportError naming the extra."""
    try:
        import matplotlib  # noqa: F401  (the extra itself: fails first when it is missing)
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        raise ImportError("plotting recordings needs matplotlib: pip install 'flowtact[plot]'") from None
    return Figure, FigureCanvasAgg


def _select(
    sources: dict[str, StreamSource], path: Path, streams: Sequence[str] | None
) -> dict[str, StreamSource]:
    if streams is None:
        return sources
    missing = [n for n in streams if n not in sources]
    if missing:
        have = shown(", ".join(sources) or "none", limit=500)
        raise KeyError(f"{shown(path)}: no stream '{shown(missing[0])}' (available: {have})")
    return {n: sources[n] for n in streams}


def _check_count(path: Path, n: int) -> None:
    if n > MAX_PLOT_STREAMS:
        raise ValueError(
            f"{shown(path)}: {n:,} streams to plot (at most {MAX_PLOT_STREAMS} in one figure); "
            "choose some with --streams"
        )


def time_span(
    sources: dict[str, StreamSource], t_range: tuple[float | None, float | None] | None
) -> tuple[float, float]:
    """The plotted time range: ``t_range`` with its open ends filled by 0 and the recording's end."""
    ends = [max(s.end_s or 0.0, s.last_t or 0.0) for s in sources.values()]
    t0 = 0.0 if t_range is None or t_range[0] is None else float(t_range[0])
    open_end = t_range is None or t_range[1] is None
    t1 = max(ends, default=0.0) if open_end else float(t_range[1])  # type: ignore[index]
    if not t1 > t0 and open_end:
        t1 = t0 + 1.0
    if not t1 > t0:
        raise ValueError(f"empty time range: from {t0:g} s to {t1:g} s")
    return t0, t1


def _frames_height(p: Panel) -> float:
    shape = tuple(p.source.spec.shape)
    cams = 1 if len(shape) == 2 else int(shape[0]) if len(shape) == 3 and shape[-1] not in (3, 4) else 1
    thumb_w = (WIDTH_IN - 0.6) / 8
    return cams * thumb_w * shape[-2] / shape[-1] + 0.7 if shape[-1] not in (3, 4) else 2.0


def _title(path: Path, root: dict[str, Any], what: str) -> str:
    graph = root.get("graph_name")
    title = label(path.name) + (f" — graph {label(graph)}" if graph else "") + what
    if "summary" not in root:
        title += " (incomplete: the run did not close the recording)"
    return title


def recording_figure(
    source: str | Path,
    streams: Sequence[str] | None = None,
    t_range: tuple[float | None, float | None] | None = None,
    *,
    figure: str | None = None,
) -> Any:
    """The figure (a matplotlib Figure on an Agg canvas) of a recording or of its named streams;
    ``figure``: the registered figure of that name (:mod:`flowtact.pictures.figures`) instead."""
    Figure, FigureCanvasAgg = need_matplotlib()
    draw = None
    if figure is not None:
        from flowtact.pictures.figures import load_figure

        draw = load_figure(figure)  # an unknown name is refused before the file is opened
    path = Path(source)
    if streams is None:  # refuse a figure of thousands of panels before verifying them all
        from flowtact.recording.hdf5 import stream_count

        _check_count(path, stream_count(path))
    f, sources, root = open_recording(path)
    with f:
        sources = _select(sources, path, streams)
        if not sources:
            raise ValueError(f"{shown(path)}: nothing to plot (the recording holds no streams)")
        _check_count(path, len(sources))
        t0, t1 = time_span(sources, t_range)
        if draw is not None:
            fig = draw(Figure, sources, t0, t1)
            FigureCanvasAgg(fig)
            fig.suptitle(_title(path, root, ""), fontsize=8)
            return fig
        panels = plan_panels(sources)
        timed = [p for p in panels if p.kind != "frames"]
        strips = [p for p in panels if p.kind == "frames"]
        heights = [sum(p.height for p in timed)] if timed else []
        heights += [_frames_height(p) for p in strips]
        total = sum(heights) + 0.6
        fig = Figure(figsize=(WIDTH_IN, min(total, MAX_HEIGHT_IN)), dpi=DPI, layout="constrained")
        FigureCanvasAgg(fig)
        subfigs = fig.subfigures(len(heights), 1, height_ratios=heights, squeeze=False)[:, 0]
        if timed:
            axes = subfigs[0].subplots(
                len(timed), 1, sharex=True, squeeze=False, height_ratios=[p.height for p in timed]
            )[:, 0]
            for ax, p in zip(axes, timed, strict=True):
                draw_panel(ax, p, t0, t1)
            axes[-1].set_xlim(t0, t1)
            axes[-1].set_xlabel("time [s]")
        for sub, p in zip(subfigs[1 if timed else 0 :], strips, strict=True):
            draw_frames(sub, p, t0, t1)
        fig.suptitle(_title(path, root, ""), fontsize=10)
    return fig


def plot_recording(
    path: str | Path,
    out: str | Path,
    streams: Iterable[str] | None = None,
    t_range: tuple[float | None, float | None] | None = None,
    *,
    figure: str | None = None,
) -> Path:
    """Plot a recording to an image file (.png, .svg or .pdf, by suffix); return its path."""
    fig = recording_figure(path, list(streams) if streams else None, t_range, figure=figure)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=fig.dpi)  # DPI, or a registered figure's own (print) resolution
    return out
