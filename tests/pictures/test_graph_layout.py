"""The layered layout's geometry: nothing overlaps, routes avoid boxes, feedback runs backwards."""

import random
from itertools import pairwise

import pytest

from flowtact.pictures.graph_layout import EdgeIn, Layout, Rect, layout, segment_points

LABEL = (30.0, 10.0)


def polyline(route):
    pts = []
    for seg in route:
        pts += segment_points(seg)[(1 if pts else 0) :]
    return pts


def crosses(p, q):
    """Do two polylines properly intersect (touching ends do not count)?"""

    def orient(a, b, c):
        v = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
        return 0 if abs(v) < 1e-9 else (1 if v > 0 else -1)

    for a, b in pairwise(p):
        for c, d in pairwise(q):
            o = (orient(a, b, c), orient(a, b, d), orient(c, d, a), orient(c, d, b))
            if o[0] * o[1] < 0 and o[2] * o[3] < 0:
                return True
    return False


def on_border(p, r: Rect, tol=1e-6):
    inside_y = r.y - tol <= p[1] <= r.bottom + tol
    inside_x = r.x - tol <= p[0] <= r.right + tol
    return (inside_y and (abs(p[0] - r.x) < tol or abs(p[0] - r.right) < tol)) or (
        inside_x and (abs(p[1] - r.y) < tol or abs(p[1] - r.bottom) < tol)
    )


def check_geometry(lay: Layout, edges):
    """What every layout must satisfy, whatever the graph."""
    rects = [("box", n, r) for n, r in lay.boxes.items()] + [
        ("label", i, r) for i, r in enumerate(lay.labels)
    ]
    for i, (_, a, ra) in enumerate(rects):
        for _, b, rb in rects[i + 1 :]:
            assert not ra.overlaps(rb), f"{a} overlaps {b}"
    for _, _, r in rects:
        assert r.x >= 0 and r.right <= lay.width and r.y >= 0 and r.bottom <= lay.height
    assert len(lay.routes) == len(edges)
    for i, (e, route) in enumerate(zip(edges, lay.routes, strict=True)):
        assert route, f"edge {i} has no route"
        for seg in route:
            for x, y in seg:  # the curve lies in its control points' hull
                assert 0 <= x <= lay.width and 0 <= y <= lay.height
        start, end = route[0][0], route[-1][3]
        assert on_border(start, lay.boxes[e.src]), f"edge {i} does not leave {e.src}"
        assert on_border(end, lay.boxes[e.dst]), f"edge {i} does not reach {e.dst}"
        pts = polyline(route)
        for n, box in lay.boxes.items():
            assert not any(box.contains(p, margin=0.5) for p in pts), f"edge {i} runs through box {n}"
        label = lay.labels[i]
        assert any(label.contains(p) for p in pts), f"edge {i} does not run through its own label"
        for j, other in enumerate(lay.labels):
            if j != i:
                assert not any(other.contains(p, margin=0.5) for p in pts), f"edge {i} runs through label {j}"


def test_chain_is_one_straight_row_with_labels_between_boxes():
    sizes = {"a": (60.0, 30.0), "b": (80.0, 40.0), "c": (50.0, 30.0)}
    edges = [EdgeIn("a", "b", LABEL), EdgeIn("b", "c", LABEL)]
    lay = layout(sizes, edges)
    check_geometry(lay, edges)
    a, b, c = (lay.boxes[n] for n in "abc")
    assert a.right < b.x and b.right < c.x
    assert a.cy == pytest.approx(b.cy) == pytest.approx(c.cy)
    assert a.right < lay.labels[0].x and lay.labels[0].right < b.x
    assert (b.w, b.h) == (80.0, 40.0)
    assert lay.backward == [False, False]


def test_a_cycle_through_a_delayed_port_is_drawn_backwards_into_its_consumer():
    sizes = {n: (60.0, 30.0) for n in ("src", "a", "b", "c")}
    edges = [
        EdgeIn("src", "a", LABEL),
        EdgeIn("a", "b", LABEL),
        EdgeIn("b", "c", LABEL),
        EdgeIn("c", "a", (60.0, 10.0), delayed=True),
    ]
    lay = layout(sizes, edges)
    check_geometry(lay, edges)
    assert lay.backward == [False, False, False, True]
    boxes = lay.boxes
    assert boxes["src"].right < boxes["a"].x < boxes["b"].x < boxes["c"].x  # layered by the forward flow
    route = lay.routes[3]
    start, (before, end) = route[0][0], route[-1][2:]
    assert start[0] == pytest.approx(boxes["c"].x)  # leaves c on its left
    assert end[0] == pytest.approx(boxes["a"].right)  # enters a on its right ...
    assert before[0] > end[0]  # ... heading left, so the arrow head points into a
    assert lay.labels[3].x > boxes["b"].right  # the label sits beside its producer, c


def test_a_delayed_edge_that_closes_no_cycle_runs_forward():
    sizes = {"a": (40.0, 30.0), "b": (40.0, 30.0)}
    edges = [EdgeIn("a", "b", LABEL, delayed=True)]
    lay = layout(sizes, edges)
    check_geometry(lay, edges)
    assert lay.backward == [False] and lay.boxes["a"].right < lay.boxes["b"].x


def test_self_loop_goes_over_its_box_with_its_label_above():
    sizes = {"src": (40.0, 30.0), "a": (60.0, 30.0), "top": (200.0, 30.0)}
    edges = [EdgeIn("src", "a", LABEL), EdgeIn("a", "a", LABEL, delayed=True), EdgeIn("src", "top", LABEL)]
    lay = layout(sizes, edges)
    check_geometry(lay, edges)
    a = lay.boxes["a"]
    assert lay.labels[1].bottom < a.y
    assert min(p[1] for p in polyline(lay.routes[1])) < a.y
    assert not lay.labels[1].overlaps(lay.boxes["top"])


def test_a_tree_given_in_shuffled_order_is_drawn_without_crossings():
    rng = random.Random(3)
    parent = {f"n{i}": f"n{(i - 1) // 3}" for i in range(1, 22)}
    names = ["n0", *parent]
    rng.shuffle(names)
    edges = [EdgeIn(p, c, LABEL) for c, p in parent.items()]
    rng.shuffle(edges)
    lay = layout({n: (50.0, 24.0) for n in names}, edges)
    check_geometry(lay, edges)
    lines = [polyline(r) for r in lay.routes]
    for i in range(len(lines)):
        for j in range(i + 1, len(lines)):
            assert not crosses(lines[i], lines[j]), f"{edges[i]} crosses {edges[j]}"


def test_crossing_reduction_untangles_two_interleaved_ladders():
    # two chains a0->a1->a2 and b0->b1->b2, plus a0->b2, given so that naive order crosses
    names = ["a0", "b0", "b1", "a1", "a2", "b2"]
    edges = [EdgeIn(f"{c}{k}", f"{c}{k + 1}", LABEL) for c in "ab" for k in range(2)]
    lay = layout({n: (40.0, 24.0) for n in names}, edges)
    check_geometry(lay, edges)
    lines = [polyline(r) for r in lay.routes]
    assert not any(crosses(p, q) for i, p in enumerate(lines) for q in lines[i + 1 :])
    ys = {n: lay.boxes[n].cy for n in names}
    assert (ys["a0"] < ys["b0"]) == (ys["a1"] < ys["b1"]) == (ys["a2"] < ys["b2"])


@pytest.mark.parametrize("seed", range(4))
def test_random_graphs_of_forty_nodes_keep_every_invariant(seed):
    rng = random.Random(seed)
    names = [f"node{i}" for i in range(40)]
    sizes = {n: (rng.uniform(40, 120), rng.choice([30.0, 40.0])) for n in names}
    edges = []
    for j in range(1, 40):
        for _ in range(rng.choice([1, 1, 2])):
            edges.append(
                EdgeIn(names[rng.randrange(max(0, j - 8), j)], names[j], (rng.uniform(12, 60), 10.0))
            )
    edges.append(EdgeIn(names[3], names[30], LABEL))
    edges.append(EdgeIn(names[30], names[3], LABEL, delayed=True))  # closes the loop 3 -> 30 -> 3
    edges.append(EdgeIn(names[12], names[12], LABEL, delayed=True))
    lay = layout(sizes, edges)
    check_geometry(lay, edges)
    assert lay.backward[-2] and not lay.backward[-1]


def test_empty_and_single_node_graphs():
    lay = layout({"solo": (50.0, 30.0)}, [])
    check_geometry(lay, [])
    assert lay.width == pytest.approx(50.0 + 20) and lay.height == pytest.approx(30.0 + 20)
    assert layout({}, []).boxes == {}


def test_chains_beside_fans_and_long_edges_are_drawn_straight():
    # teleop's shape: a source fanning out to three branches, one long chain, a long edge into its end
    names = ["exo", "fsr", "finger", "kin", "c1", "c2", "c3", "c4", "control"]
    edges = [
        EdgeIn("exo", "fsr", LABEL),
        EdgeIn("fsr", "finger", LABEL),
        EdgeIn("exo", "finger", LABEL),
        EdgeIn("exo", "kin", LABEL),
        EdgeIn("kin", "c1", LABEL),
        *(EdgeIn(f"c{k}", f"c{k + 1}", LABEL) for k in range(1, 4)),
        EdgeIn("c4", "control", LABEL),
        EdgeIn("finger", "control", LABEL),
        EdgeIn("control", "exo", LABEL, delayed=True),
    ]
    lay = layout({n: (60.0, 40.0) for n in names}, edges)
    check_geometry(lay, edges)
    for e, route in zip(edges, lay.routes, strict=True):
        if e.src in ("kin", "c1", "c2", "c3", "c4"):
            assert route[0][0][1] == pytest.approx(route[-1][3][1], abs=0.01), f"{e} is not straight"
    back = lay.routes[-1]  # the feedback lane runs level between its two bends
    lane = [p[1] for seg in back[2:-2] for p in (seg[0], seg[3])]
    assert max(lane) - min(lane) < 0.01
