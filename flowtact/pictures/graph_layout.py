"""Left-to-right layered layout of a dataflow graph: boxes, edge labels and edge routes, in points.

A compact Sugiyama layout: feedback edges reversed, longest-path layers, barycentre crossing
reduction, order-preserving least-squares rows. Each edge's label is a node of the layered graph, so
labels never overprint boxes or each other by construction. Pure geometry (y grows downward): the
caller measures its texts, this module imports no drawing library.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from itertools import pairwise

__all__ = ["EdgeIn", "Layout", "Rect", "layout", "segment_points"]

Point = tuple[float, float]
Segment = tuple[Point, Point, Point, Point]
"""A cubic Bézier: start, two control points, end."""

MARGIN = 10.0
NODE_SEP = 16.0  # vertical space between two boxes in a column
LANE_SEP = 6.0  # vertical space next to an edge lane or label
STUB = 8.0  # straight run of an edge beside a box or a label (keeps arrow heads horizontal)
MIN_CURVE = 14.0  # width of the curve that takes an edge from one column to the next
MAX_CURVE = 110.0
PORT_SPACING = 9.0  # vertical distance between edges attached to the same side of a box
LOOP_RISE = 14.0  # height of a self-loop above its box
SWEEPS = 24
IN, OUT = 0, 1  # the sides of a box: edges come in on the left, go out on the right


@dataclass(frozen=True)
class Rect:
    """An axis-aligned rectangle: top-left corner, width and height (y grows downward)."""

    x: float
    y: float
    w: float
    h: float

    @property
    def right(self) -> float:
        return self.x + self.w

    @property
    def bottom(self) -> float:
        return self.y + self.h

    @property
    def cx(self) -> float:
        return self.x + self.w / 2

    @property
    def cy(self) -> float:
        return self.y + self.h / 2

    def overlaps(self, other: Rect, margin: float = 0.0) -> bool:
        """Do the two rectangles share interior (after shrinking each side by ``margin``)?"""
        return (
            self.x + margin < other.right - margin
            and other.x + margin < self.right - margin
            and self.y + margin < other.bottom - margin
            and other.y + margin < self.bottom - margin
        )

    def contains(self, p: Point, margin: float = 0.0) -> bool:
        """Is ``p`` strictly inside, at least ``margin`` from every side?"""
        return self.x + margin < p[0] < self.right - margin and self.y + margin < p[1] < self.bottom - margin


@dataclass(frozen=True)
class EdgeIn:
    """An edge to lay out: producer, consumer, its label's size, and whether its input is delayed."""

    src: str
    dst: str
    label: tuple[float, float]
    delayed: bool = False


@dataclass
class Layout:
    """Where everything goes. ``routes[i]`` runs from edge i's producer to its consumer."""

    boxes: dict[str, Rect]
    labels: list[Rect]
    routes: list[list[Segment]]
    backward: list[bool]
    """Edges drawn right to left: the feedback edges that had to be reversed to layer the graph."""
    width: float
    height: float


def segment_points(seg: Segment, n: int = 16) -> list[Point]:
    """``n + 1`` points along a cubic Bézier segment, ends included."""
    (x0, y0), (x1, y1), (x2, y2), (x3, y3) = seg
    pts = []
    for i in range(n + 1):
        t = i / n
        a, b, c, d = (1 - t) ** 3, 3 * t * (1 - t) ** 2, 3 * t * t * (1 - t), t**3
        pts.append((a * x0 + b * x1 + c * x2 + d * x3, a * y0 + b * y1 + c * y2 + d * y3))
    return pts


def layout(sizes: Mapping[str, tuple[float, float]], edges: Sequence[EdgeIn]) -> Layout:
    """Lay out boxes of the given ``(width, height)`` and the edges between them, left to right."""
    names = list(sizes)
    flows = [e for e in edges if e.src != e.dst]
    oriented, backward = _orient(names, [(e.src, e.dst) for e in flows], [e.delayed for e in flows])
    rank = _ranks(names, oriented)
    g = _LayeredGraph(sizes, edges, rank, oriented, backward)
    g.order_layers()
    g.assign_rows()
    g.assign_columns()
    return g.finish()


def _orient(
    names: list[str], pairs: list[tuple[str, str]], delayed: list[bool]
) -> tuple[list[tuple[str, str]], list[bool]]:
    """Each edge in layering direction, and whether that is against its flow.

    Undelayed edges go in first, so a feedback loop is cut at its delayed edge, the one that really
    closes it; an edge is reversed only when it would close a cycle.
    """
    succ: dict[str, set[str]] = {n: set() for n in names}

    def reaches(a: str, b: str) -> bool:
        seen, stack = {a}, [a]
        while stack:
            for m in succ[stack.pop()]:
                if m == b:
                    return True
                if m not in seen:
                    seen.add(m)
                    stack.append(m)
        return False

    out: list[tuple[str, str]] = list(pairs)
    back = [False] * len(pairs)
    for i in sorted(range(len(pairs)), key=lambda i: delayed[i]):
        u, v = pairs[i]
        if reaches(v, u):
            out[i], back[i] = (v, u), True
        succ[out[i][0]].add(out[i][1])
    return out, back


def _ranks(names: list[str], oriented: list[tuple[str, str]]) -> dict[str, int]:
    """Longest-path layers; then each node without inputs moves next to its nearest consumer."""
    preds: dict[str, list[str]] = {n: [] for n in names}
    succs: dict[str, list[str]] = {n: [] for n in names}
    for u, v in oriented:
        preds[v].append(u)
        succs[u].append(v)
    rank: dict[str, int] = {}

    def depth(n: str) -> int:
        if n not in rank:
            rank[n] = 0  # acyclic by construction; this only guards the recursion
            rank[n] = max((depth(p) + 1 for p in preds[n]), default=0)
        return rank[n]

    for n in names:
        depth(n)
    for n in names:
        if not preds[n] and succs[n]:
            rank[n] = min(rank[s] for s in succs[n]) - 1
    return rank


class _LayeredGraph:
    """The layered graph: real boxes on even layers, labels and edge lanes in between."""

    def __init__(
        self,
        sizes: Mapping[str, tuple[float, float]],
        edges: Sequence[EdgeIn],
        rank: dict[str, int],
        oriented: list[tuple[str, str]],
        backward: list[bool],
    ) -> None:
        self.sizes = dict(sizes)
        self.edges = list(edges)
        n_layers = 2 * max(rank.values(), default=0) + 1
        self.layers: list[list[tuple]] = [[] for _ in range(n_layers)]
        self.size: dict[tuple, tuple[float, float]] = {}
        self.top_extra: dict[tuple, float] = {}
        self.layer_of: dict[tuple, int] = {}
        for n in sizes:
            self._add(("n", n), 2 * rank[n], sizes[n])
        self.chains: dict[int, list[tuple]] = {}
        self.backward: dict[int, bool] = {}
        self.loops: dict[str, list[int]] = {}
        flow = 0
        for i, e in enumerate(self.edges):
            if e.src == e.dst:
                self.loops.setdefault(e.src, []).append(i)
                continue
            (u, v), back = oriented[flow], backward[flow]
            flow += 1
            self.backward[i] = back
            lo, hi = 2 * rank[u], 2 * rank[v]
            label_at = hi - 1 if back else lo + 1  # beside the producer
            chain = [("n", u)]
            for k in range(lo + 1, hi):
                item = ("l", i) if k == label_at else ("d", i, k)
                self._add(item, k, e.label if k == label_at else (0.0, 0.0))
                chain.append(item)
            chain.append(("n", v))
            self.chains[i] = chain
        self._fit_ports()
        for n, loops in self.loops.items():
            self.top_extra[("n", n)] = sum(LOOP_RISE + self.edges[i].label[1] + 4 for i in loops)
        self.pred: dict[tuple, list[tuple]] = {it: [] for it in self.size}
        self.succ: dict[tuple, list[tuple]] = {it: [] for it in self.size}
        for chain in self.chains.values():
            for a, b in pairwise(chain):
                self.succ[a].append(b)
                self.pred[b].append(a)
        self.y: dict[tuple, float] = {}
        self.col_left: list[float] = []
        self.col_width: list[float] = []

    def _fit_ports(self) -> None:
        """Make a box tall enough that the edges on each of its sides stay ``PORT_SPACING`` apart."""
        ends: dict[tuple, list[int]] = {}
        for chain in self.chains.values():
            for side in ((chain[0], 1), (chain[-1], 0)):
                ends.setdefault(side, []).append(0)
        for n, loops in self.loops.items():
            for side in (1, 0):
                ends.setdefault((("n", n), side), []).extend([0] * len(loops))
        for (item, _), on_side in ends.items():
            w, h = self.size[item]
            self.size[item] = (w, max(h, (len(on_side) - 1) * PORT_SPACING + 2 * STUB))

    def _add(self, item: tuple, layer: int, size: tuple[float, float]) -> None:
        self.layers[layer].append(item)
        self.layer_of[item] = layer
        self.size[item] = size

    # -- crossing reduction -------------------------------------------------------------------

    def order_layers(self) -> None:
        """Barycentre sweeps down and up, with adjacent swaps; keeps the order with fewest crossings."""
        for k in range(1, len(self.layers)):
            self._sort_by(k, self.pred, k - 1)
        best, best_cross = [list(layer) for layer in self.layers], self._crossings()
        for sweep in range(SWEEPS):
            down = sweep % 2 == 0
            ks = range(1, len(self.layers)) if down else range(len(self.layers) - 2, -1, -1)
            for k in ks:
                self._sort_by(k, self.pred if down else self.succ, k - 1 if down else k + 1)
            self._transpose()
            cross = self._crossings()
            if cross < best_cross:
                best, best_cross = [list(layer) for layer in self.layers], cross
            if best_cross == 0:
                break
        self.layers = best

    def _sort_by(self, k: int, nbrs: dict[tuple, list[tuple]], ref: int) -> None:
        pos = {it: i for i, it in enumerate(self.layers[ref])}
        layer = self.layers[k]

        def bary(i: int) -> float:
            ps = [pos[m] for m in nbrs[layer[i]] if m in pos]
            return sum(ps) / len(ps) if ps else float(i)

        keys = {it: (bary(i), i) for i, it in enumerate(layer)}
        layer.sort(key=keys.__getitem__)

    def _pair_crossings(self, k: int) -> int:
        pos_next = {it: i for i, it in enumerate(self.layers[k + 1])}
        ends = [(i, pos_next[m]) for i, it in enumerate(self.layers[k]) for m in self.succ[it]]
        return sum(1 for a in ends for b in ends if a[0] < b[0] and a[1] > b[1])

    def _crossings(self) -> int:
        return sum(self._pair_crossings(k) for k in range(len(self.layers) - 1))

    def _transpose(self) -> None:
        improved = True
        while improved:
            improved = False
            for k, layer in enumerate(self.layers):
                for i in range(len(layer) - 1):
                    before = self._local_crossings(k)
                    layer[i], layer[i + 1] = layer[i + 1], layer[i]
                    if self._local_crossings(k) < before:
                        improved = True
                    else:
                        layer[i], layer[i + 1] = layer[i + 1], layer[i]

    def _local_crossings(self, k: int) -> int:
        return (self._pair_crossings(k - 1) if k > 0 else 0) + (
            self._pair_crossings(k) if k < len(self.layers) - 1 else 0
        )

    # -- coordinates --------------------------------------------------------------------------

    def _extent(self, item: tuple) -> tuple[float, float]:
        """Space above and below the item's centre line."""
        h = self.size[item][1]
        return h / 2 + self.top_extra.get(item, 0.0), h / 2

    def _sep(self, a: tuple, b: tuple) -> float:
        gap = NODE_SEP if a[0] == "n" and b[0] == "n" else LANE_SEP
        return self._extent(a)[1] + gap + self._extent(b)[0]

    def _port_offsets(self) -> None:
        """Where each edge meets its box, from the box's centre line: spread in the neighbours' order.

        A self-loop goes over the top, so it takes the topmost place on both sides.
        """
        pos = {it: j for layer in self.layers for j, it in enumerate(layer)}
        sides: dict[tuple[tuple, int], list[tuple[float, int]]] = {}
        for i, chain in self.chains.items():
            sides.setdefault((chain[0], OUT), []).append((pos[chain[1]], i))
            sides.setdefault((chain[-1], IN), []).append((pos[chain[-2]], i))
        for n, loops in self.loops.items():
            for i in loops:
                for side in (IN, OUT):
                    sides.setdefault((("n", n), side), []).append((-1.0, i))
        self.port: dict[tuple[int, int], float] = {}
        for (item, side), ends in sides.items():
            ends.sort()
            step = (
                min(PORT_SPACING, (self.size[item][1] - 2 * STUB) / (len(ends) - 1)) if len(ends) > 1 else 0.0
            )
            for j, (_, i) in enumerate(ends):
                self.port[(i, side)] = (j - (len(ends) - 1) / 2) * step
        # link (neighbour, delta, weight): the edge is straight when y[item] == y[neighbour] + delta
        self.pred_links: dict[tuple, list[tuple[tuple, float, float]]] = {it: [] for it in self.size}
        self.succ_links: dict[tuple, list[tuple[tuple, float, float]]] = {it: [] for it in self.size}
        for i, chain in self.chains.items():
            for j, (a, b) in enumerate(pairwise(chain)):
                off_a = self.port[(i, OUT)] if j == 0 else 0.0
                off_b = self.port[(i, IN)] if j == len(chain) - 2 else 0.0
                w = 1.0 if "n" in (a[0], b[0]) else 4.0  # long edges straight first
                self.succ_links[a].append((b, off_b - off_a, w))
                self.pred_links[b].append((a, off_a - off_b, w))

    def assign_rows(self) -> None:
        """Each item's centre line: least squares to its neighbours, then nearly straight edges made straight."""
        self._port_offsets()
        for layer in self.layers:
            y = 0.0
            for i, it in enumerate(layer):
                y += self._sep(layer[i - 1], it) if i else 0.0
                self.y[it] = y
        both = {it: self.pred_links[it] + self.succ_links[it] for it in self.size}
        n = len(self.layers)
        for _ in range(8):
            for k in range(1, n):
                self._place(self.layers[k], self.pred_links)
            for k in range(n - 2, -1, -1):
                self._place(self.layers[k], self.succ_links)
        for _ in range(4):
            for k in range(n):
                self._place(self.layers[k], both)
        for chain_id in sorted(self.chains, key=lambda i: len(self.chains[i]), reverse=True):
            self._straighten(chain_id)
        self._snap(both)

    def _room(self, it: tuple, moving: Collection[tuple] = ()) -> tuple[float, float]:
        """Where an item can go without touching its neighbours in the column (those not moving with it)."""
        layer = self.layers[self.layer_of[it]]
        j = layer.index(it)
        above = layer[j - 1] if j > 0 and layer[j - 1] not in moving else None
        below = layer[j + 1] if j + 1 < len(layer) and layer[j + 1] not in moving else None
        lo = self.y[above] + self._sep(above, it) if above else -float("inf")
        hi = self.y[below] - self._sep(it, below) if below else float("inf")
        return lo, hi

    def _straighten(self, i: int) -> None:
        """Put a long edge's lane on one line when its columns leave room, level with its producer's port."""
        chain = self.chains[i]
        if len(chain) < 4:
            return
        lo, hi = -float("inf"), float("inf")
        for it in chain[1:-1]:
            a, b = self._room(it)
            lo, hi = max(lo, a), min(hi, b)
        if lo <= hi:
            src, side = (chain[-1], IN) if self.backward[i] else (chain[0], OUT)
            want = self.y[src] + self.port[(i, side)]
            for it in chain[1:-1]:
                self.y[it] = min(max(want, lo), hi)

    def _snap(self, links: dict[tuple, list[tuple[tuple, float, float]]]) -> None:
        """Make nearly straight edges straight: move groups already in line as one, where room allows.

        Greedy least absolute deviations: a group (items joined by straight edges) moves onto the line
        of one of its outside neighbours when that lowers the summed deviation, or keeps it and
        straightens more edges. Each move lowers that pair, so the loop ends.
        """
        for _ in range(30):
            moved = False
            for group in self._groups(links):
                members = set(group)
                lo, hi = -float("inf"), float("inf")
                for it in group:
                    a, b = self._room(it, members)
                    lo, hi = max(lo, a - self.y[it]), min(hi, b - self.y[it])
                outside = [(it, m, d, w) for it in group for m, d, w in links[it] if m not in members]
                if not outside:
                    continue

                def cost(shift: float, outside: list = outside) -> tuple[float, int, float]:
                    devs = [(abs(self.y[m] + d - self.y[it] - shift), w) for it, m, d, w in outside]
                    return round(sum(v * w for v, w in devs), 6), sum(v > 0.01 for v, _ in devs), abs(shift)

                shifts = [min(max(self.y[m] + d - self.y[it], lo), hi) for it, m, d, _ in outside]
                best = min([0.0, *shifts], key=cost)
                if best != 0.0:
                    for it in group:
                        self.y[it] += best
                    moved = True
            if not moved:
                return

    def _groups(self, links: dict[tuple, list[tuple[tuple, float, float]]]) -> list[list[tuple]]:
        """Items joined by straight edges, each group in layer order."""
        parent = {it: it for it in self.size}

        def root(it: tuple) -> tuple:
            while parent[it] != it:
                parent[it] = parent[parent[it]]
                it = parent[it]
            return it

        for it, ls in links.items():
            for m, d, _ in ls:
                if abs(self.y[m] + d - self.y[it]) <= 0.01:
                    parent[root(it)] = root(m)
        groups: dict[tuple, list[tuple]] = {}
        for layer in self.layers:
            for it in layer:
                groups.setdefault(root(it), []).append(it)
        return list(groups.values())

    def _place(self, layer: list[tuple], links: dict[tuple, list[tuple[tuple, float, float]]]) -> None:
        if not layer:
            return
        want, weights = [], []
        for it in layer:
            ls = links[it]
            total = sum(w for _, _, w in ls)
            want.append(sum((self.y[m] + d) * w for m, d, w in ls) / total if ls else self.y[it])
            weights.append(total or 1.0)
        offsets = [0.0]
        for a, b in pairwise(layer):
            offsets.append(offsets[-1] + self._sep(a, b))
        z = _isotonic([w - o for w, o in zip(want, offsets, strict=True)], weights)
        for it, zi, o in zip(layer, z, offsets, strict=True):
            self.y[it] = zi + o

    def assign_columns(self) -> None:
        """Column widths from their contents; gaps wide enough for the curves crossing them."""
        loop_w = {("n", n): max(self.edges[i].label[0] for i in ls) for n, ls in self.loops.items()}
        self.col_width = [
            max((max(self.size[it][0], loop_w.get(it, 0.0)) for it in layer), default=0.0)
            for layer in self.layers
        ]
        x = 0.0
        for k, w in enumerate(self.col_width):
            self.col_left.append(x)
            if k + 1 < len(self.layers):
                rise = max(
                    (abs(self.y[b] - self.y[a]) for a in self.layers[k] for b in self.succ[a]), default=0.0
                )
                x += w + 2 * STUB + min(MAX_CURVE, max(MIN_CURVE, 0.45 * rise))

    # -- geometry out -------------------------------------------------------------------------

    def _box(self, item: tuple) -> Rect:
        k = self.layer_of[item]
        w, h = self.size[item]
        return Rect(self.col_left[k] + (self.col_width[k] - w) / 2, self.y[item] - h / 2, w, h)

    def finish(self) -> Layout:
        boxes = {it[1]: self._box(it) for it in self.size if it[0] == "n"}
        y_out = {i: self.y[c[0]] + self.port[(i, OUT)] for i, c in self.chains.items()}
        y_in = {i: self.y[c[-1]] + self.port[(i, IN)] for i, c in self.chains.items()}
        for n, loops in self.loops.items():
            for i in loops:
                y_out[i] = self.y[("n", n)] + self.port[(i, OUT)]
                y_in[i] = self.y[("n", n)] + self.port[(i, IN)]
        labels: dict[int, Rect] = {}
        routes: dict[int, list[Segment]] = {}
        for i, chain in self.chains.items():
            routes[i] = self._route(chain, y_out[i], y_in[i])
            labels[i] = self._box(("l", i))
            if self.backward[i]:
                routes[i] = [(d, c, b, a) for a, b, c, d in reversed(routes[i])]
        for n, loops in self.loops.items():
            box, rise = boxes[n], 0.0
            for i in loops:
                w, h = self.edges[i].label
                apex = box.y - rise - LOOP_RISE - h / 2
                routes[i] = _loop(box, apex, y_out[i], y_in[i])
                labels[i] = Rect(box.cx - w / 2, apex - h / 2, w, h)
                rise += LOOP_RISE + h + 4
        return self._framed(boxes, labels, routes)

    def _route(self, chain: list[tuple], y0: float, y1: float) -> list[Segment]:
        """Straight runs through each column, S-curves across the gaps between columns."""
        first, last = self._box(chain[0]), self._box(chain[-1])
        runs: list[tuple[Point, Point]] = [((first.right, y0), (self._col_right(chain[0]) + STUB, y0))]
        for it in chain[1:-1]:
            k, y = self.layer_of[it], self.y[it]
            runs.append(((self.col_left[k] - STUB, y), (self.col_left[k] + self.col_width[k] + STUB, y)))
        runs.append(((self.col_left[self.layer_of[chain[-1]]] - STUB, y1), (last.x, y1)))
        segs: list[Segment] = []
        for j, (a, b) in enumerate(runs):
            if j:
                p = runs[j - 1][1]
                mid = (p[0] + a[0]) / 2
                segs.append((p, (mid, p[1]), (mid, a[1]), a))
            segs.append(_line(a, b))
        return [s for s in segs if s[0] != s[3]]

    def _col_right(self, item: tuple) -> float:
        k = self.layer_of[item]
        return self.col_left[k] + self.col_width[k]

    def _framed(
        self, boxes: dict[str, Rect], labels: dict[int, Rect], routes: dict[int, list[Segment]]
    ) -> Layout:
        """Shift everything so the drawing starts at the margin; the canvas fits all of it."""
        rects = list(boxes.values()) + list(labels.values())
        xs = [r.x for r in rects] + [p[0] for segs in routes.values() for s in segs for p in s]
        ys = [r.y for r in rects] + [p[1] for segs in routes.values() for s in segs for p in s]
        xe = [r.right for r in rects] + xs
        ye = [r.bottom for r in rects] + ys
        dx, dy = MARGIN - min(xs, default=0.0), MARGIN - min(ys, default=0.0)

        def move(r: Rect) -> Rect:
            return Rect(r.x + dx, r.y + dy, r.w, r.h)

        def move_seg(s: Segment) -> Segment:
            a, b, c, d = ((p[0] + dx, p[1] + dy) for p in s)
            return a, b, c, d

        order = range(len(self.edges))
        return Layout(
            boxes={n: move(r) for n, r in boxes.items()},
            labels=[move(labels[i]) for i in order],
            routes=[[move_seg(s) for s in routes[i]] for i in order],
            backward=[self.backward.get(i, False) for i in order],
            width=max(xe, default=0.0) + dx + MARGIN,
            height=max(ye, default=0.0) + dy + MARGIN,
        )


def _line(a: Point, b: Point) -> Segment:
    def at(t: float) -> Point:
        return a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])

    return a, at(1 / 3), at(2 / 3), b


def _loop(box: Rect, top: float, y_out: float, y_in: float) -> list[Segment]:
    """A self-loop over the top of a box: out of its right side, back into its left side."""
    bulge = 2 * STUB
    start, apex, end = (box.right, y_out), (box.cx, top), (box.x, y_in)
    return [
        (start, (box.right + bulge, y_out), (box.right + bulge, top), apex),
        (apex, (box.x - bulge, top), (box.x - bulge, y_in), end),
    ]


def _isotonic(values: list[float], weights: list[float]) -> list[float]:
    """The non-decreasing sequence closest to ``values`` in weighted least squares (pool adjacent violators)."""
    blocks: list[list[float]] = []  # [mean, weight, count]
    for v, w in zip(values, weights, strict=True):
        blocks.append([v, w, 1])
        while len(blocks) > 1 and blocks[-2][0] > blocks[-1][0]:
            m2, w2, c2 = blocks.pop()
            m1, w1, c1 = blocks.pop()
            blocks.append([(m1 * w1 + m2 * w2) / (w1 + w2), w1 + w2, c1 + c2])
    return [m for m, _, c in blocks for _ in range(int(c))]
