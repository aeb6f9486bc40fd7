"""PNG output of the suites: their own drawings and the run-time-against-error plots (matplotlib, imported lazily)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from flowtact.benchmark.labels import PointLabel, label_points
from flowtact.benchmark.suite import Plot, Tradeoff

__all__ = ["draw_tradeoff", "save_plot"]


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_plot(plot: Plot, path: Path) -> None:
    """Run ``plot.draw`` on a fresh Figure and write it to ``path`` (PNG); errors land in ``plot.error``."""
    try:
        plt = _pyplot()
    except ImportError as e:
        plot.error = f"not drawn: matplotlib is not installed ({e.name}); pip install 'flowtact[plot]'"
        return
    fig = plt.figure(figsize=(7.5, 4.5))
    try:
        plot.draw(fig)
        fig.tight_layout()
        path.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, dpi=110)
        plot.path = str(path)
    finally:
        plt.close(fig)
        plot.draw = None


def draw_tradeoff(t: Tradeoff) -> Plot:
    """The :class:`Plot` of a run-time-against-error study: one marker per setting and series,
    each point labelled with its setting, the shipped default as a large star."""

    def draw(fig: Any) -> None:
        ax = fig.add_subplot(1, 1, 1)
        series = list(dict.fromkeys(p.series for p in t.points))
        for i, name in enumerate(series):
            pts = [p for p in t.points if p.series == name]
            ax.plot([p.time for p in pts], [p.error for p in pts], "o", color=f"C{i}", label=name, ms=5)
        for p in (p for p in t.points if p.default):
            ax.plot([p.time], [p.error], "*", ms=16, mfc="none", mec="k", mew=1.5)
        from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

        xs, ys = [p.time for p in t.points], [p.error for p in t.points]
        for on, vals, axis, scale in (
            (t.log_time, xs, ax.xaxis, ax.set_xscale),
            (t.log_error, ys, ax.yaxis, ax.set_yscale),
        ):
            if on and min(vals) > 0 and max(vals) / min(vals) >= 10:  # a log axis only over a decade or more
                scale("log")
                axis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
                axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
                axis.set_minor_formatter(NullFormatter())
        ax.set_xlabel(t.time_label)
        ax.set_ylabel(t.error_label)
        ax.set_title(t.title, fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
        fig.tight_layout()  # labels are placed against the final layout
        label_points(ax, [PointLabel(p.time, p.error, _default_label(p.setting) if p.default else p.setting,
                                     bold=p.default) for p in t.points])  # fmt: skip

    marked = [p.setting for p in t.points if p.default]
    caption = f"{t.title}: run time against error, one point per setting" + (
        f"; the star marks the shipped default ({', '.join(marked)})" if marked else ""
    )
    return Plot(t.name, caption, draw)


def _default_label(setting: str) -> str:
    """The shipped default's label, saying so once."""
    return setting if "shipped" in setting else f"{setting} (shipped default)"
