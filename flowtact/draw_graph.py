"""Draw a compiled graph: Graphviz DOT text, or an SVG/PNG laid out in layers with matplotlib.

Pruned nodes and edges that carry nothing are drawn grey and dashed, so a user sees at a glance
what the compiler skipped. No Graphviz installation is needed (matplotlib, the ``plot`` extra,
renders the images; ``.dot`` output needs nothing).
"""

from __future__ import annotations

from pathlib import Path

from flowtact.compile import Plan

__all__ = ["draw_plan", "layers", "to_dot"]

GREY = "#9e9e9e"


def to_dot(plan: Plan) -> str:
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
        lines.append(f'  "{e.src}" -> "{e.dst}" [label="{e.src_port}→{e.dst_port}"{style}];')
    for n, p in plan.record:
        lines.append(f'  "rec_{n}_{p}" [label="record {n}.{p}", shape=note, fillcolor="#fff4e5"];')
        lines.append(f'  "{n}" -> "rec_{n}_{p}" [style=dotted];')
    lines.append("}")
    return "\n".join(lines) + "\n"


def layers(plan: Plan) -> dict[str, int]:
    """Column of each node: the length of the longest path reaching it from a source."""
    g = plan.graph
    depth = {n: 0 for n in g.nodes}
    for _ in range(len(g.nodes)):
        changed = False
        for e in g.edges:
            if g.nodes[e.dst].cls.inputs[e.dst_port].delay:
                continue
            if depth[e.dst] < depth[e.src] + 1:
                depth[e.dst] = depth[e.src] + 1
                changed = True
        if not changed:
            break
    return depth


def draw_plan(plan: Plan, output: str | Path) -> Path:
    """Write the plan as ``.dot``, ``.svg`` or ``.png`` (by the file's suffix)."""
    out = Path(output)
    if out.suffix == ".dot":
        out.write_text(to_dot(plan))
        return out
    if out.suffix not in (".svg", ".png", ".pdf"):
        raise ValueError(f"cannot draw to '{out.suffix}': use .svg, .png, .pdf or .dot")
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        from matplotlib.patches import FancyArrowPatch, FancyBboxPatch
    except ImportError:
        raise ImportError(
            "drawing images needs matplotlib: pip install 'flowtact[plot]' (or write .dot)"
        ) from None

    g = plan.graph
    depth = layers(plan)
    columns: dict[int, list[str]] = {}
    for n in g.nodes:
        columns.setdefault(depth[n], []).append(n)
    pos = {}
    for col, names in columns.items():
        for row, n in enumerate(names):
            pos[n] = (col * 3.2, -(row - (len(names) - 1) / 2) * 1.6)
    width = max(columns) * 3.2 + 3 if columns else 3
    height = max(len(v) for v in columns.values()) * 1.6 + 1.5 if columns else 2
    fig, ax = plt.subplots(figsize=(max(width, 4), max(height, 2.5)))
    active_edges = {str(e) for e in plan.active_edges}
    for e in g.edges:
        on = str(e) in active_edges
        (x0, y0), (x1, y1) = pos[e.src], pos[e.dst]
        arrow = FancyArrowPatch(
            (x0 + 1.1, y0),
            (x1 - 1.1, y1),
            arrowstyle="-|>",
            mutation_scale=12,
            color="#37474f" if on else GREY,
            linestyle="-" if on else "--",
            connectionstyle="arc3,rad=0.25" if x1 <= x0 else "arc3,rad=0.0",
        )
        ax.add_patch(arrow)
        ax.text(
            (x0 + x1) / 2,
            (y0 + y1) / 2 + 0.15,
            f"{e.src_port}→{e.dst_port}",
            fontsize=7,
            ha="center",
            color="#37474f" if on else GREY,
        )
    recorded = {n for n, _ in plan.record}
    for n, (x, y) in pos.items():
        on = n in plan.order
        box = FancyBboxPatch(
            (x - 1.1, y - 0.45),
            2.2,
            0.9,
            boxstyle="round,pad=0.05",
            facecolor=("#fff4e5" if n in recorded else "#e8f0fe") if on else "white",
            edgecolor="#37474f" if on else GREY,
            linestyle="-" if on else "--",
        )
        ax.add_patch(box)
        ax.text(
            x, y + 0.12, n, ha="center", va="center", fontsize=9, weight="bold", color="black" if on else GREY
        )
        ax.text(
            x,
            y - 0.2,
            g.nodes[n].block,
            ha="center",
            va="center",
            fontsize=7,
            color="#37474f" if on else GREY,
        )
    ax.set_title(f"{g.name} — grey: not computed (pruned); orange: recorded", fontsize=9)
    ax.set_xlim(-1.5, width - 1.5)
    ys = [y for _, y in pos.values()] or [0]
    ax.set_ylim(min(ys) - 1, max(ys) + 1)
    ax.set_aspect("equal")
    ax.axis("off")
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out
