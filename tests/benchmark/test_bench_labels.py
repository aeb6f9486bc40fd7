"""Point labels of the bench plots: coincident points share a label, and labels do not overlap."""

import itertools

import pytest

pytest.importorskip("matplotlib")
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from flowtact.benchmark.labels import PointLabel, label_points


def _texts(ax):
    renderer = ax.figure.canvas.get_renderer()
    return [(t.get_text(), t.get_window_extent(renderer)) for t in ax.texts]


def test_coincident_points_share_one_label_and_the_bold_one_leads():
    fig, ax = plt.subplots()
    ax.plot([1, 2], [1, 2], "o")
    label_points(ax, [PointLabel(1, 1, "5/3"), PointLabel(1, 1, "5/4", bold=True), PointLabel(2, 2, "7/2")])
    texts = sorted(t for t, _ in _texts(ax))
    assert texts == ["5/4 = 5/3", "7/2"]
    assert next(t for t in ax.texts if t.get_text().startswith("5/4")).get_weight() == "bold"
    plt.close(fig)


def test_labels_of_a_dense_cluster_do_not_overlap_each_other():
    fig, ax = plt.subplots(figsize=(6, 4))
    pts = [(1.0 + 0.06 * i, 1.0 + 0.02 * (i % 3)) for i in range(6)]  # 6-8 pixels apart
    ax.plot(*zip(*pts, strict=True), "o")
    ax.set_xlim(0, 3)
    ax.set_ylim(0, 2)
    label_points(ax, [PointLabel(x, y, f"setting {i}") for i, (x, y) in enumerate(pts)])
    boxes = [b for _, b in _texts(ax)]
    assert len(boxes) == 6
    for a, b in itertools.combinations(boxes, 2):
        assert not a.overlaps(b), "two labels overlap"
    plt.close(fig)


def test_a_label_near_the_edge_stays_inside_the_axes():
    fig, ax = plt.subplots(figsize=(4, 3))
    ax.plot([0.99], [0.99], "o")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    label_points(ax, [PointLabel(0.99, 0.99, "a long label near the corner")])
    (_, box), frame = _texts(ax)[0], ax.get_window_extent(fig.canvas.get_renderer())
    assert frame.x0 <= box.x0 and box.x1 <= frame.x1 and frame.y0 <= box.y0 and box.y1 <= frame.y1
    plt.close(fig)
