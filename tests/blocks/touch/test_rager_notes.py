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
