"""Draw a compiled graph: Graphviz DOT text, or an SVG/PNG/PDF laid out by flowtact.pictures.graph_layout.

Pruned nodes and edges that carry nothing are drawn grey and dashed, so a user sees at a glance
what the compiler skipped; delayed (feedback) edges are purple and dashed. No Graphviz installation
is needed (matplotlib, the ``plot`` extra, renders the images; ``.dot`` output needs nothing).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from flowtact.pictures.graph_layout import EdgeIn, Layout, Rect, layout
from flowtact.running.compile import CompiledGraph

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["FORMATS", "draw_compiled", "graph_figure", "to_dot"]

FORMATS = (".svg", ".png", ".pdf", ".dot")

GREY = "#9e9e9e"
INK = "#37474f"
FEEDBACK = "#7b1fa2"
FILL = "#e8f0fe"
RECORDED = "#fff4e5"
PAD_X, PAD_Y = 8.0, 5.0  # text to box border, points
LINE = 1.25  # line height / font size
EDGE_FONT = 7.0
ARROW = (7.0, 3.0)  # arrow head length and half-width, points
DPI = 150


def to_dot(plan: CompiledGraph) -> str:
    """The plan as a Graphviz digraph (pruned parts grey and dashed)."""
    g = plan.graph
    active_edges = {str(e) for e in plan.active_edges}
    lines = [
        f'digraph "{g.name}" {{',
        "  rankdir=LR;",
        '  node [shape=box, style="rounded,filled", fillcolor="#e8f0fe"];',
    ]
    for name, node in g.nodes.items():
        style = (
            ""
            if name in plan.order
            else f', style="rounded,dashed", color="{GREY}", fontcolor="{GREY}", fillcolor=white'
        )
        lines.append(f'  "{name}" [label="{name}\\n({node.block})"{style}];')
    for e in g.edges:
        style = "" if str(e) in active_edges else f', style=dashed, color="{GREY}", fontcolor="{GREY}"'
        if _delayed(plan, e) and str(e) in active_edges:
            style = f', style=dashed, color="{FEEDBACK}", fontcolor="{FEEDBACK}", constraint=false'
        lines.append(f'  "{e.src}" -> "{e.dst}" [label="{_edge_text(plan, e)}"{style}];')
    for n, p in plan.record:
        lines.append(f'  "rec_{n}_{p}" [label="record {n}.{p}", shape=note, fillcolor="#fff4e5"];')
        lines.append(f'  "{n}" -> "rec_{n}_{p}" [style=dotted];')
    lines.append("}")
    return "\n".join(lines) + "\n"


def draw_compiled(plan: CompiledGraph, output: str | Path) -> Path:
    """Write the plan as ``.dot``, ``.svg``, ``.png`` or ``.pdf`` (by the file's suffix)."""
    out = Path(output)
    if out.suffix == ".dot":
        out.write_text(to_dot(plan))
        return out
    if out.suffix not in FORMATS:
        raise ValueError(f"cannot draw to '{out.suffix}': use {', '.join(FORMATS)}")
    fig = graph_figure(plan)
    fig.savefig(out, dpi=DPI)
    return out


def graph_figure(plan: CompiledGraph) -> Figure:
    """The plan drawn on a matplotlib figure sized to its content (one data unit is one point).

    Artists carry ids (``node:NAME``, ``edge:I``, ``arrow:I``, ``label:I`` for the plan's i-th graph
    edge) so tests and SVG readers can find them.
    """
    try:
        from matplotlib.figure import Figure
    except ImportError:
        raise ImportError(
            "drawing images needs matplotlib: pip install 'flowtact[plot]' (or write .dot)"
        ) from None
    measure = _Measure()
    boxes = {n: _box_lines(plan, n) for n in plan.graph.nodes}
    sizes = {n: _box_size(lines, measure) for n, lines in boxes.items()}
    edges = [
        EdgeIn(e.src, e.dst, _label_size(_edge_text(plan, e), measure), _delayed(plan, e))
        for e in plan.graph.edges
    ]
    lay = layout(sizes, edges)
    frame = _Frame.around(plan, lay, measure)
    fig = Figure(figsize=(frame.width / 72, frame.height / 72), dpi=DPI)
    ax = fig.add_axes((0, 0, 1, 1))
    ax.set_xlim(0, frame.width)
    ax.set_ylim(frame.height, 0)
    ax.axis("off")
    _draw_edges(ax, plan, lay, frame.dx, frame.dy)
    _draw_boxes(ax, plan, lay, boxes, frame.dx, frame.dy)
    frame.draw(ax, measure)
    return fig


# -- text -------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Text:
    text: str
    size: float
    weight: str = "normal"
    style: str = "normal"
    color: str = "black"

    def font(self) -> Any:
        from matplotlib.font_manager import FontProperties

        return FontProperties(size=self.size, weight=self.weight, style=self.style)


class _Measure:
    """Text widths in points, from matplotlib's own renderer (so boxes fit what is drawn)."""

    SCALE = 4  # measure at 288 dpi: sub-point precision

    def __init__(self) -> None:
        from matplotlib.backends.backend_agg import RendererAgg

        self._renderer = RendererAgg(1, 1, 72 * self.SCALE)

    def width(self, t: _Text) -> float:
        w, _, _ = self._renderer.get_text_width_height_descent(t.text, t.font(), ismath=False)
        return w / self.SCALE


def _delayed(plan: CompiledGraph, e: Any) -> bool:
    port = plan.graph.nodes[e.dst].cls.inputs.get(e.dst_port)
    return bool(port is not None and port.delay)


def _edge_text(plan: CompiledGraph, e: Any) -> str:
    return f"{e.src_port}→{e.dst_port}" + (" (delayed)" if _delayed(plan, e) else "")


def _box_lines(plan: CompiledGraph, n: str) -> list[_Text]:
    on = n in plan.order
    lines = [
        _Text(n, 9.0, weight="bold", color="black" if on else GREY),
        _Text(plan.graph.nodes[n].block, 7.5, color=INK if on else GREY),
    ]
    group = _groups(plan).get(n)
    if group:
        lines.append(_Text(f"process {group}", 6.5, style="italic", color=INK))
    return lines


def _groups(plan: CompiledGraph) -> dict[str, str]:
    """The process group of each active node, when the graph runs in more than one."""
    from flowtact.runtime.placement import default_groups  # the rule the runtime places by

    groups = default_groups(plan)
    return groups if len(set(groups.values())) > 1 else {}


def _box_size(lines: list[_Text], measure: _Measure) -> tuple[float, float]:
    return (
        max(measure.width(t) for t in lines) + 2 * PAD_X,
        sum(t.size * LINE for t in lines) + 2 * PAD_Y,
    )


def _label_size(text: str, measure: _Measure) -> tuple[float, float]:
    return measure.width(_Text(text, EDGE_FONT)) + 4.0, EDGE_FONT * LINE + 2.0


# -- drawing ----------------------------------------------------------------------------------


def _moved(r: Rect, dx: float, dy: float) -> Rect:
    return Rect(r.x + dx, r.y + dy, r.w, r.h)


def _draw_boxes(
    ax: Any, plan: CompiledGraph, lay: Layout, boxes: dict[str, list[_Text]], dx: float, dy: float
) -> None:
    from matplotlib.patches import FancyBboxPatch

    recorded = {n for n, _ in plan.record}
    for n, lines in boxes.items():
        r, on = _moved(lay.boxes[n], dx, dy), n in plan.order
        ax.add_patch(
            FancyBboxPatch(
                (r.x, r.y),
                r.w,
                r.h,
                boxstyle="round,pad=0,rounding_size=4",
                facecolor=(RECORDED if n in recorded else FILL) if on else "white",
                edgecolor=INK if on else GREY,
                linestyle="-" if on else (0, (3, 2)),
                linewidth=1.0,
                zorder=2,
                gid=f"node:{n}",
            )
        )
        y = r.cy - sum(t.size * LINE for t in lines) / 2  # a box may be taller than its text
        for k, t in enumerate(lines):
            h = t.size * LINE
            ax.text(
                r.cx,
                y + h / 2,
                t.text,
                fontproperties=t.font(),
                color=t.color,
                ha="center",
                va="center_baseline",
                zorder=3,
                parse_math=False,
                gid=f"nodetext:{n}:{k}",
            )
            y += h


def _draw_edges(ax: Any, plan: CompiledGraph, lay: Layout, dx: float, dy: float) -> None:
    from matplotlib.patches import PathPatch, Polygon
    from matplotlib.path import Path as MPath

    active = {str(e) for e in plan.active_edges}
    for i, e in enumerate(plan.graph.edges):
        on, delayed = str(e) in active, _delayed(plan, e)
        color = (FEEDBACK if delayed else INK) if on else GREY
        dash = (0, (5, 3)) if delayed or not on else "-"
        segs = [tuple((x + dx, y + dy) for x, y in s) for s in lay.routes[i]]
        verts = [segs[0][0]] + [p for s in segs for p in s[1:]]
        codes = [MPath.MOVETO] + [MPath.CURVE4] * (len(verts) - 1)
        tip, before = segs[-1][3], segs[-1][2]
        tip, base, wing = _arrow(tip, before)
        verts[-1] = base  # the line stops where the head begins, so dashes do not poke through it
        ax.add_patch(
            PathPatch(
                MPath(verts, codes),
                fill=False,
                edgecolor=color,
                linestyle=dash,
                linewidth=1.0,
                zorder=1,
                gid=f"edge:{i}",
            )
        )
        ax.add_patch(
            Polygon([tip, *wing], closed=True, facecolor=color, edgecolor=color, zorder=1.5, gid=f"arrow:{i}")
        )
        r = _moved(lay.labels[i], dx, dy)
        ax.text(
            r.cx,
            r.cy,
            _edge_text(plan, e),
            fontsize=EDGE_FONT,
            color=color,
            ha="center",
            va="center_baseline",
            zorder=3,
            parse_math=False,
            bbox={"boxstyle": "square,pad=0.1", "facecolor": "white", "edgecolor": "none"},
            gid=f"label:{i}",
        )


def _arrow(tip: tuple[float, float], before: tuple[float, float]) -> tuple[Any, Any, list[Any]]:
    """An arrow head ending at ``tip``, pointing away from ``before``: (tip, base centre, wings)."""
    ux, uy = tip[0] - before[0], tip[1] - before[1]
    norm = (ux * ux + uy * uy) ** 0.5 or 1.0
    ux, uy = ux / norm, uy / norm
    length, half = ARROW
    base = (tip[0] - ux * length, tip[1] - uy * length)
    return tip, base, [(base[0] - uy * half, base[1] + ux * half), (base[0] + uy * half, base[1] - ux * half)]


# -- title and legend -------------------------------------------------------------------------


@dataclass
class _Frame:
    """The canvas around the layout: a title and description above, a legend below."""

    header: list[_Text]
    legend: list[tuple[str, _Text]]
    width: float
    height: float
    dx: float
    dy: float
    top: float
    legend_y: float

    @classmethod
    def around(cls, plan: CompiledGraph, lay: Layout, measure: _Measure) -> _Frame:
        g = plan.graph
        wrap_at = max(lay.width - 20, 320.0)
        header = [_Text(g.name, 11.0, weight="bold")]
        header += [_Text(s, 8.0, color=INK) for s in _wrap(g.description, wrap_at, measure)]
        legend = _legend_items(plan)
        legend_w = sum(22 + measure.width(t) + 14 for _, t in legend)
        header_w = max(measure.width(t) for t in header)
        width = max(lay.width, header_w + 20, legend_w + 20)
        top = 8.0
        header_h = sum(t.size * LINE for t in header) + 4
        legend_h = 14.0 if legend else 0.0
        return cls(
            header=header,
            legend=legend,
            width=width,
            height=top + header_h + lay.height + legend_h + 6,
            dx=(width - lay.width) / 2,
            dy=top + header_h,
            top=top,
            legend_y=top + header_h + lay.height + legend_h / 2,
        )

    def draw(self, ax: Any, measure: _Measure) -> None:
        from matplotlib.lines import Line2D
        from matplotlib.patches import FancyBboxPatch

        y = self.top
        for t in self.header:
            h = t.size * LINE
            ax.text(
                self.width / 2,
                y + h / 2,
                t.text,
                fontproperties=t.font(),
                color=t.color,
                ha="center",
                va="center_baseline",
                parse_math=False,
                gid="title",
            )
            y += h
        total = sum(22 + measure.width(t) + 14 for _, t in self.legend) - 14
        x, y = (self.width - total) / 2, self.legend_y
        for glyph, t in self.legend:
            if glyph == "line":
                ax.add_line(Line2D([x, x + 18], [y, y], color=t.color, linestyle=(0, (5, 3)), linewidth=1.0))
            else:
                ax.add_patch(
                    FancyBboxPatch(
                        (x + 2, y - 5),
                        14,
                        10,
                        boxstyle="round,pad=0,rounding_size=2",
                        facecolor="white" if glyph == "pruned" else RECORDED,
                        edgecolor=GREY if glyph == "pruned" else INK,
                        linestyle=(0, (3, 2)) if glyph == "pruned" else "-",
                    )
                )
            ax.text(
                x + 22, y, t.text, fontproperties=t.font(), color=t.color, va="center_baseline", gid="legend"
            )
            x += 22 + measure.width(t) + 14


def _legend_items(plan: CompiledGraph) -> list[tuple[str, _Text]]:
    g, items = plan.graph, []
    if plan.pruned or len(plan.active_edges) < len(g.edges):
        items.append(("pruned", _Text("pruned: not computed", 7.5, color=INK)))
    if plan.record:
        items.append(("recorded", _Text("recorded", 7.5, color=INK)))
    if any(_delayed(plan, e) for e in g.edges):
        items.append(("line", _Text("delayed input: feedback, one tick late", 7.5, color=FEEDBACK)))
    return items


def _wrap(text: str, width: float, measure: _Measure) -> list[str]:
    lines: list[str] = []
    for word in text.split():
        if lines and measure.width(_Text(f"{lines[-1]} {word}", 8.0)) <= width:
            lines[-1] += f" {word}"
        else:
            lines.append(word)
    return lines
