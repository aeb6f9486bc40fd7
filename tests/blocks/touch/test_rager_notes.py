"""Two behaviours of Rager et al.'s model in the shipped trials, documented in docs/touch-encoding.md:
the slip trial's SA1 silence after the slip, and the touch trial's FA1 offset burst (issue 33, Deliver 5)."""

from pathlib import Path

import numpy as np
import pytest

from flowtact.blocks.touch.presets import NEURON_PRESETS, TABLE_I
from flowtact.graphfile.graph import load_graph
from flowtact.testing import run_graph

GRAPHS = Path(__file__).parents[3] / "graphs"


def rate(t, start, stop, n):
    return np.count_nonzero((t >= start) & (t < stop)) / n / (stop - start)


@pytest.fixture(scope="module")
def slip():
    return run_graph(GRAPHS / "slip.yaml")


def after_slip():
    c = load_graph(GRAPHS / "slip.yaml").nodes["sensor"].config
    end = c.onset_s + c.ramp_s + c.drag_s + c.slip_s
    return end + 0.05, end + c.hold_s  # the hold after the slip, once the drive has settled


def test_slip_sa1_falls_silent_under_normal_load_because_fx_turned_negative(slip):
    """After the slip Fz stays ≈ 0.32 N but Fx ≈ −0.19 N: Table I's signed SA1 weights give
    0.405·Fx + 0.382·Fz ≈ 0.045, below SA1's threshold drive (1 − v_leak)/gain = 0.06, so SA1 stops.
    Fed |Fx| instead (everything else the same), SA1 keeps firing through that hold: the sign is the cause."""
    t0, t1 = after_slip()
    n = load_graph(GRAPHS / "slip.yaml").nodes["sa1"].config.n
    f = slip["force.f"]
    hold = (f.t >= t0) & (f.t < t1)
    fx, fy, fz = f.data[hold].mean(axis=0)
    assert fz > 0.3 and fx < -0.15  # pressed as hard as on the touch plateau, sheared backwards
    w = TABLE_I["SA1"]
    threshold = (1 - NEURON_PRESETS["SA1"]["v_leak"]) / NEURON_PRESETS["SA1"]["gain"]
    assert w[0] * fx + w[1] * fy + w[2] * fz < threshold < w[0] * abs(fx) + w[1] * fy + w[2] * fz
    assert rate(slip["sa1.spikes"].t, t0, t1, n) == 0
    mirrored = f.data.copy()
    mirrored[:, 0] = np.abs(mirrored[:, 0])
    fed = run_graph(GRAPHS / "slip.yaml", feed={"force.f": (f.t, mirrored)})
    assert rate(fed["sa1.spikes"].t, t0, t1, n) > 50


@pytest.mark.parametrize("shear_ratio", [0.8, 0.0])
def test_touch_fa1_offset_burst_comes_from_the_tangential_load(shear_ratio):
    """touch.yaml's probe adds a tangential load (shear_ratio 0.8 of the normal force, released in
    3 ms at unloading): −0.012·Fx' of Table I's FA1 is then a large positive kick, one spike per FA1
    afferent at offset. A purely normal touch (shear_ratio 0) keeps the onset burst but has none."""
    g = load_graph(GRAPHS / "touch.yaml")
    c, n = g.nodes["sensor"].config, g.nodes["fa1"].config.n
    assert c.shear_ratio == 0.8  # the shipped trial is the sheared one
    out = run_graph(GRAPHS / "touch.yaml", overrides=[f"sensor.shear_ratio={shear_ratio}"])
    fa1 = out["fa1.spikes"].t
    on, off = c.onset_s, c.onset_s + c.ramp_s + c.hold_s
    assert rate(fa1, on, on + 0.1, n) >= 5  # onset: at least one spike per afferent in 100 ms
    offset = np.count_nonzero((fa1 >= off) & (fa1 < off + 0.1))
    if shear_ratio:
        assert offset >= n
        assert np.abs(out["force.f"].data[:, 0]).max() > 0.15  # the tangential load behind it
    else:
        assert offset == 0
        assert np.abs(out["force.f"].data[:, 0]).max() < 0.01  # noise only


# The rectified variant of Table I (graphs/touch_rectified.yaml, presets touch.SA1.rectified and
# touch.FA1.rectified on rectified_gain): the drive is Σ w·|F| + w'·|F'|, the same neurons.

RECTIFIED = GRAPHS / "touch_rectified.yaml"


def test_the_rectified_drive_is_table_i_on_the_magnitudes():
    """The recorded drives against numpy on the recorded force and derivative: Σ w·|F| + w'·|F'|.
    Every product of a weight and a magnitude is exact in both (g·max(v, 0) − g·min(v, 0) is w·|v|
    to the bit), and the sums run in the same order (two terms per axis, then the axes from x),
    so the drives are equal bit for bit."""
    out = run_graph(RECTIFIED, overrides=["sensor.scenario=slip"], duration_s=1.0)
    f, d = out["force.f"], out["dforce.y"]
    for pop in ("SA1", "FA1"):
        y = out[f"{pop.lower()}_drive.y"]
        n = len(y.t)
        np.testing.assert_array_equal(y.t, d.t[:n])
        w = np.asarray(TABLE_I[pop])
        axes = w[:3] * np.abs(f.data[:n]) + w[3:6] * np.abs(d.data[:n])
        want = axes[:, 0] + axes[:, 1] + axes[:, 2]
        np.testing.assert_array_equal(y.data, want)
        assert not np.allclose(y.data, f.data[:n] @ w[:3] + d.data[:n] @ w[3:6])  # not the signed sum


def test_rectified_sa1_keeps_firing_through_the_hold_after_the_slip():
    """With the signed weights SA1 is silent through the hold (Fx ≈ −0.19 N inhibits, test above);
    on the magnitudes 0.405·|Fx| + 0.382·Fz ≈ 0.2 keeps it firing, as on the touch plateau."""
    t0, t1 = after_slip()
    n = load_graph(RECTIFIED).nodes["sa1"].config.n
    out = run_graph(RECTIFIED, overrides=["sensor.scenario=slip"])
    assert out["force.f"].data[(out["force.f"].t >= t0) & (out["force.f"].t < t1), 0].mean() < -0.15
    assert rate(out["sa1.spikes"].t, t0, t1, n) > 50


@pytest.mark.parametrize(("unload_s", "rectified_offset"), [(0.01, True), (0.03, False)])
def test_rectified_fa1_answers_a_purely_normal_offset_only_when_unloading_is_as_fast_as_loading(
    unload_s, rectified_offset
):
    """No tangential load (shear_ratio 0). The literal weights never give an offset burst (Fz' < 0
    on the +0.024 weight inhibits); the rectified ones give one spike per afferent when the
    unloading is as fast as the 10 ms loading (+0.024·|Fz'| as at onset), and none at the shipped
    30 ms unloading (|Fz'| a third of the onset's: below FA1's threshold)."""
    sets = ["sensor.shear_ratio=0", f"sensor.unload_s={unload_s}"]
    c = load_graph(RECTIFIED, overrides=sets).nodes["sensor"].config
    assert c.ramp_s == 0.01
    on, off = c.onset_s, c.onset_s + c.ramp_s + c.hold_s
    n = load_graph(RECTIFIED).nodes["fa1"].config.n
    for graph, fires in ((RECTIFIED, rectified_offset), (GRAPHS / "touch.yaml", False)):
        out = run_graph(graph, overrides=sets)
        fa1 = out["fa1.spikes"].t
        assert np.abs(out["force.f"].data[:, :2]).max() < 0.01  # no tangential load: noise only
        assert np.count_nonzero((fa1 >= on) & (fa1 < on + 0.1)) >= n  # onset, either way
        offset = np.count_nonzero((fa1 >= off) & (fa1 < off + 0.1))
        assert offset >= n if fires else offset == 0, (graph.name, offset)
