"""Point labels that do not overlap: coincident points share one label, and each label goes to the
first spot around its point where it covers no other label, marker or the axes' edge."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["PointLabel", "label_points"]

# (dx, dy) in points from the marker, with the alignment that keeps the text on that side of it
_SPOTS = (
    (4, 3, "left", "bottom"),
    (4, -3, "left", "top"),
    (-4, 3, "right", "bottom"),
    (-4, -3, "right", "top"),
    (0, 7, "center", "bottom"),
    (0, -7, "center", "top"),
    (10, 12, "left", "bottom"),
    (10, -12, "left", "top"),
    (-10, 12, "right", "bottom"),
    (-10, -12, "right", "top"),
)
_DOT_PX = 3.0
_STAR_PX = 9.0
"""Half-widths (display pixels) kept clear around a plain marker and a bold one (the default's star)."""
_MARGIN_PX = 5.0
"""Clearance (display pixels) between a label and another point's marker."""
_SAME_PX = 4.0
"""Markers closer than this (display pixels) share one label, joined with " = "."""


@dataclass(frozen=True)
class PointLabel:
    """A data point and its text; ``bold`` for the one a reader must find (the shipped default)."""

    x: float
    y: float
    text: str
    bold: bool = False


def label_points(ax: Any, labels: Sequence[PointLabel], fontsize: float = 7) -> None:
    """Annotate ``labels`` on ``ax`` (call it once scales and limits are final)."""
    renderer = ax.figure.canvas.get_renderer()
    frame = ax.get_window_extent(renderer)
    groups: list[tuple[np.ndarray, list[PointLabel]]] = []
    for p in sorted(labels, key=lambda p: not p.bold):  # bold labels choose first
        pxy = ax.transData.transform((p.x, p.y))
        if not np.all(np.isfinite(pxy)):
            continue
        for anchor, members in groups:
            if np.hypot(*(anchor - pxy)) < _SAME_PX:
                if p.text not in (m.text for m in members):
                    members.append(p)
                break
        else:
            groups.append((pxy, [p]))
    markers = [(xy, _STAR_PX if any(m.bold for m in ms) else _DOT_PX) for xy, ms in groups]
    placed: list[Any] = []
    for i, (_, members) in enumerate(groups):
        others = [m for j, m in enumerate(markers) if j != i]
        placed.append(_place(ax, renderer, members, placed, others, frame, fontsize))


def _place(ax: Any, renderer: Any, members: list[PointLabel], placed: list, others: list, frame: Any,
           fontsize: float) -> Any:  # fmt: skip
    """Put one label at the first spot that covers no placed label, no other marker (with a margin,
    so a label is never nearer another point than its own) and stays inside the axes."""
    first = members[0]
    text = " = ".join(m.text for m in members)
    bold = any(m.bold for m in members)
    reach = _STAR_PX / _DOT_PX if bold else 1.0  # a bold label starts beyond its star
    best = None
    for dx, dy, ha, va in _SPOTS:
        t = ax.annotate(text, (first.x, first.y), xytext=(dx * reach, dy * reach), textcoords="offset points", ha=ha,
                        va=va, fontsize=fontsize + (1 if bold else 0), weight="bold" if bold else "normal")  # fmt: skip
        bb = t.get_window_extent(renderer)
        cost = sum(_overlap(bb, o) for o in placed) + _outside(bb, frame)
        cost += sum(_overlap(bb, _box(x - r - _MARGIN_PX, y - r - _MARGIN_PX, x + r + _MARGIN_PX, y + r + _MARGIN_PX))
                    for (x, y), r in others)  # fmt: skip
        if best is None or cost < best[0]:
            if best is not None:
                best[1].remove()
            best = (cost, t, bb)
        else:
            t.remove()
        if cost == 0:
            break
    return best[2]


def _box(x0: float, y0: float, x1: float, y1: float) -> Any:
    from matplotlib.transforms import Bbox

    return Bbox.from_extents(x0, y0, x1, y1)


def _overlap(a: Any, b: Any) -> float:
    w = min(a.x1, b.x1) - max(a.x0, b.x0)
    h = min(a.y1, b.y1) - max(a.y0, b.y0)
    return w * h if w > 0 and h > 0 else 0.0


def _outside(bb: Any, frame: Any) -> float:
    """Area of ``bb`` beyond the axes (counted heavily: a label off the plot is lost)."""
    return 10.0 * (bb.width * bb.height - _overlap(bb, frame))
