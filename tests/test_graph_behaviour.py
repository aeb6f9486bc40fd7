"""graphs/touch.yaml and graphs/slip.yaml, run as shipped, reproduce Rager et al.'s Fig. 4 behaviour.

The block chain is tested piece by piece (tests/test_rager_behaviour.py); this file checks the
graphs a user runs: FA1 spikes cluster at touch onset and offset, SA1 fires through the plateau,
no population exceeds 300 spikes/s per neuron in 20 ms bins, and slip drives the two differently.
"""

from pathlib import Path

import numpy as np
import pytest

from flowtact.graphfile.graph import load_graph
from flowtact.testing import run_graph

GRAPHS = Path(__file__).parent.parent / "graphs"


@pytest.fixture(scope="module")
def touch():
    return run_graph(GRAPHS / "touch.yaml")


@pytest.fixture(scope="module")
def slip():
    return run_graph(GRAPHS / "slip.yaml")


def sensor_times(name):
    c = load_graph(GRAPHS / name).nodes["sensor"].config
    return c.onset_s, c.onset_s + c.ramp_s + c.hold_s, c


def n_units(name, population):
    return load_graph(GRAPHS / name).nodes[population].config.n


def rate(t, start, stop, n):
    return np.count_nonzero((t >= start) & (t < stop)) / n / (stop - start)


def test_touch_fa1_spikes_cluster_at_onset_and_offset(touch):
    onset, offset, _ = sensor_times("touch.yaml")
    t = touch["fa1.spikes"].t
    n = n_units("touch.yaml", "fa1")
    near = (np.abs(t - onset) <= 0.06) | (np.abs(t - offset) <= 0.06)
    assert len(t) >= n and near.mean() >= 0.9
    assert rate(t, onset, onset + 0.06, n) > 10 and rate(t, offset, offset + 0.06, n) > 10
    assert rate(t, onset + 0.06, offset - 0.02, n) < 1.0  # almost none on the plateau
    assert rate(t, 0.0, onset - 0.02, n) < 1.0  # nor at rest (no start-up transient)


def test_touch_sa1_fires_throughout_the_plateau(touch):
    onset, offset, _ = sensor_times("touch.yaml")
    t = touch["sa1.spikes"].t
    n = n_units("touch.yaml", "sa1")
    windows = np.arange(onset, offset - 0.05 + 1e-9, 0.05)
    assert all(np.count_nonzero((t >= w) & (t < w + 0.05)) > 0 for w in windows)
    plateau = rate(t, onset + 0.15, offset, n)
    assert plateau > 20
    assert rate(t, onset, onset + 0.04, n) > 1.5 * plateau  # extra activity at onset
    assert rate(t, offset + 0.1, 3.0, n) < 0.2 * plateau  # quiet once the probe is gone


@pytest.mark.parametrize("graph", ["touch", "slip"])
@pytest.mark.parametrize("population", ["sa1", "fa1"])
def test_no_population_exceeds_300_spikes_per_second(graph, population, touch, slip):
    out = {"touch": touch, "slip": slip}[graph][f"{population}.spikes"]
    n = n_units(f"{graph}.yaml", population)
    counts, _ = np.histogram(out.t, np.arange(0.0, 3.0 + 1e-9, 0.02))
    assert counts.max() / n / 0.02 <= 300.0


def test_slip_drives_sa1_and_fa1_differently(slip):
    _, _, c = sensor_times("slip.yaml")
    start = c.onset_s + c.ramp_s + c.drag_s
    end = start + c.slip_s
    sa1, fa1 = slip["sa1.spikes"].t, slip["fa1.spikes"].t
    n_sa1, n_fa1 = n_units("slip.yaml", "sa1"), n_units("slip.yaml", "fa1")
    assert rate(sa1, start, end, n_sa1) > 100
    assert rate(sa1, start, end, n_sa1) > 4 * rate(fa1, start, end, n_fa1)
    assert rate(fa1, c.onset_s, end, n_fa1) > 2  # FA1 answers the drag and the slip in volleys


def test_the_second_derivative_is_never_computed():
    from flowtact.running.compile import compile_graph

    plan = compile_graph(load_graph(GRAPHS / "touch.yaml"))
    assert "ddforce" in plan.pruned and "ddforce" not in plan.order
    assert plan.needed["sa1_drive"] == {"x1", "x2"} and plan.needed["fa1_drive"] == {"x1", "x2"}
    assert all(e.src != "ddforce" for e in plan.active_edges)
