"""Pictures of graphs, checked on the drawn artists' own extents (matplotlib's renderer), not on pixels."""

import textwrap
from pathlib import Path

import pytest

pytest.importorskip("matplotlib")

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import to_hex
from matplotlib.transforms import Bbox
from runs import TEST_BLOCKS

from flowtact.cli import main
from flowtact.graphfile.graph import load_graph
from flowtact.pictures.graph_figure import FEEDBACK, GREY, graph_figure
from flowtact.running.compile import compile_graph
from flowtact.running.launch import load_compiled

GRAPH_DIR = Path(__file__).resolve().parents[2] / "graphs"
GRAPHS = sorted(p.stem for p in GRAPH_DIR.glob("*.yaml"))
TOL = 0.5  # pixels


def rendered(plan):
    fig = graph_figure(plan)
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return fig, canvas.get_renderer()


def by_gid(fig, prefix):
    ax = fig.axes[0]
    return {
        a.get_gid(): a for a in [*ax.patches, *ax.texts, *ax.lines] if (a.get_gid() or "").startswith(prefix)
    }


def overlap(a: Bbox, b: Bbox) -> bool:
    return a.x0 + TOL < b.x1 and b.x0 + TOL < a.x1 and a.y0 + TOL < b.y1 and b.y0 + TOL < a.y1


def inside(inner: Bbox, outer: Bbox) -> bool:
    return (
        inner.x0 >= outer.x0 - TOL
        and inner.x1 <= outer.x1 + TOL
        and inner.y0 >= outer.y0 - TOL
        and inner.y1 <= outer.y1 + TOL
    )


def check_picture(plan):
    """No overlaps, nothing clipped, each edge once with its head at its consumer, pruned parts grey."""
    fig, r = rendered(plan)
    g = plan.graph
    boxes = {k.split(":", 1)[1]: a.get_window_extent(r) for k, a in by_gid(fig, "node:").items()}
    assert set(boxes) == set(g.nodes)
    names = list(boxes)
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            assert not overlap(boxes[a], boxes[b]), f"boxes {a} and {b} overlap"
    labels = {}
    for k, t in by_gid(fig, "label:").items():
        ext = Bbox.union([t.get_window_extent(r), t.get_bbox_patch().get_window_extent(r)])
        labels[int(k.split(":")[1])] = ext
    assert sorted(labels) == list(range(len(g.edges)))
    for i, ext in labels.items():
        for n, box in boxes.items():
            assert not overlap(ext, box), f"label of {g.edges[i]} overlaps box {n}"
        for j, other in labels.items():
            assert j == i or not overlap(ext, other), f"labels of {g.edges[i]} and {g.edges[j]} overlap"
    for k, t in by_gid(fig, "nodetext:").items():
        node = k.split(":")[1]
        assert inside(t.get_window_extent(r), boxes[node]), f"text {t.get_text()!r} spills out of {node}"
        for n, box in boxes.items():
            assert n == node or not overlap(t.get_window_extent(r), box)
    ax = fig.axes[0]
    for a in [*ax.patches, *ax.texts, *ax.lines]:
        assert inside(a.get_window_extent(r), fig.bbox), f"{a.get_gid() or a} is clipped by the canvas"
    edges, arrows = by_gid(fig, "edge:"), by_gid(fig, "arrow:")
    assert sorted(edges) == sorted(f"edge:{i}" for i in range(len(g.edges)))
    assert sorted(arrows) == sorted(f"arrow:{i}" for i in range(len(g.edges)))
    active = {str(e) for e in plan.active_edges}
    for i, e in enumerate(g.edges):
        tip, *wings = arrows[f"arrow:{i}"].get_verts()[:3]  # the polygon's data vertices, in display units
        box = boxes[e.dst]
        assert box.y0 - TOL <= tip[1] <= box.y1 + TOL
        assert min(abs(tip[0] - box.x0), abs(tip[0] - box.x1)) < 1.0, f"{e} does not end at {e.dst}"
        pointing_right = all(w[0] < tip[0] for w in wings)
        assert pointing_right == (abs(tip[0] - box.x0) < 1.0), f"{e}'s arrow points out of {e.dst}"
        color = to_hex(edges[f"edge:{i}"].get_edgecolor())
        assert (color == GREY) == (str(e) not in active)
    for n in g.nodes:
        patch = by_gid(fig, f"node:{n}")[f"node:{n}"]
        assert (to_hex(patch.get_edgecolor()) == GREY) == (n not in plan.order), n
    return fig, r, boxes, arrows, edges


@pytest.mark.parametrize("graph", GRAPHS)
def test_every_shipped_graph_draws_readably(graph):
    plan = load_compiled(GRAPH_DIR / f"{graph}.yaml")
    check_picture(plan)


def test_touch_greys_what_the_compiler_pruned():
    plan = load_compiled(GRAPH_DIR / "touch.yaml")
    assert "ddforce" in plan.pruned
    fig, *_ = check_picture(plan)
    patch = by_gid(fig, "node:ddforce")["node:ddforce"]
    assert to_hex(patch.get_facecolor()) == "#ffffff" and patch.get_linestyle() != "-"


def test_teleops_feedback_arc_is_drawn_backwards_into_the_exoskeleton():
    plan = load_compiled(GRAPH_DIR / "teleop.yaml")
    fig, r, boxes, arrows, edges = check_picture(plan)
    (i,) = [i for i, e in enumerate(plan.graph.edges) if (e.src, e.dst) == ("control", "exo")]
    tip, *wings = arrows[f"arrow:{i}"].get_verts()[:3]
    assert abs(tip[0] - boxes["exo"].x1) < 1.0 and all(w[0] > tip[0] for w in wings)
    path = edges[f"edge:{i}"]
    assert to_hex(path.get_edgecolor()) == FEEDBACK and path.get_linestyle() != "-"
    assert inside(path.get_window_extent(r), fig.bbox)


def test_a_cycle_through_a_delayed_port_and_a_self_loop():
    text = """
    name: loops
    nodes:
      src: {block: "toyblocks:Ramp"}
      a:   {block: "toyblocks:Loop"}
      b:   {block: "toyblocks:Scale"}
      c:   {block: "toyblocks:Scale"}
      s:   {block: "toyblocks:Add"}
    edges:
      - src.y -> a.x
      - a.y -> b.x
      - b.y -> c.x
      - c.y -> a.fb
      - c.y -> s.a
      - s.y -> s.fb
    record: [c.y, s.y]
    """
    plan = compile_graph(load_graph("loops.yaml", text=textwrap.dedent(text), allow_modules=TEST_BLOCKS))
    _, r, boxes, arrows, edges = check_picture(plan)
    (back,) = [i for i, e in enumerate(plan.graph.edges) if (e.src, e.dst) == ("c", "a")]
    tip, *wings = arrows[f"arrow:{back}"].get_verts()[:3]
    assert abs(tip[0] - boxes["a"].x1) < 1.0 and all(w[0] > tip[0] for w in wings)
    assert boxes["a"].x1 < boxes["b"].x0 < boxes["c"].x0
    (loop,) = [i for i, e in enumerate(plan.graph.edges) if e.src == e.dst]
    assert edges[f"edge:{loop}"].get_window_extent(r).y1 > boxes["s"].y1  # over the top of s


def test_svg_names_every_edge_and_node(tmp_path):
    out = tmp_path / "teleop.svg"
    assert main(["graph", str(GRAPH_DIR / "teleop.yaml"), "-o", str(out)]) == 0
    svg = out.read_text()
    plan = load_compiled(GRAPH_DIR / "teleop.yaml")
    for n in plan.graph.nodes:
        assert f'id="node:{n}"' in svg
    for i in range(len(plan.graph.edges)):
        assert f'id="edge:{i}"' in svg and f'id="arrow:{i}"' in svg


def test_an_unknown_picture_format_is_a_usage_error(tmp_path, capsys):
    out = tmp_path / "touch.jpg"
    assert main(["graph", str(GRAPH_DIR / "touch.yaml"), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "cannot draw to '.jpg'; use .svg, .png, .pdf, .dot" in err and "Traceback" not in err
    assert not out.exists()
    pdf = tmp_path / "touch.pdf"
    assert main(["graph", str(GRAPH_DIR / "touch.yaml"), "-o", str(pdf)]) == 0
    assert pdf.read_bytes().startswith(b"%PDF")
