"""Rager et al.'s Fig. 4 behaviour from the whole chain, offline.

sensor (touch | slip) → gauge_force (reduced, with the reference gauge) → savgol (window 5, order 4,
first derivative, CENTRED: the paper filtered recorded data offline, and the causal variant of the
same fit has ×5.9 the F' noise, NUMERICS §1.2) → weighted_sum (Table I preset, x1 = F, x2 = F') →
nlif (SA1 / FA1 preset, 30 neurons).

What the paper reports and these tests check:
* touch: FA1 fires at force onset and offset and (almost) not on the plateau; SA1 fires throughout
  the plateau, with more activity just after onset than on the rest of the plateau;
* no population exceeds 300 spikes/s per neuron (20 ms bins);
* slip: SA1 and FA1 patterns differ — SA1 is driven hardest DURING the slip (the tangential force
  swings through +y, and SA1 weighs Fy most, w2 = 8.908) and approaches its refractory ceiling,
  while FA1 fires sparse volleys during the drag and the slip, several times fewer spikes.

The first 100 ms of every run are excluded: the streaming derivative starts from zero history
(zero padding) while the sensor starts under its 0.12 N holding force, so F' jumps at t = 0 and FA1
answers with one volley. Trials start at 0.2 s.
"""

import numpy as np
import pytest

from flowtact.blocks.signal.savgol import SavGol
from flowtact.blocks.signal.weighted_sum import WeightedSum
from flowtact.blocks.spiking.nlif import Nlif
from flowtact.blocks.touch.aunp_sensor import AunpSensor
from flowtact.blocks.touch.calibration import GaugeForce
from flowtact.testing import run_offline, run_source

N = 30
SETTLE_S = 0.1
ONSET_S = 0.2
TOUCH = {"scenario": "touch", "onset_s": ONSET_S, "hold_s": 0.8}
SLIP = {"scenario": "slip", "onset_s": ONSET_S, "hold_s": 0.5}


def spikes(sensor_params, population, seed=0, duration_s=1.5):
    """Run the chain offline; return (spike times, neuron indices, the sensor config)."""
    sensor = AunpSensor(**sensor_params)
    s = run_source(sensor, duration_s, seed=seed)
    f = run_offline(GaugeForce(mode="reduced"), r=s["r"].data, ref=s["ref"].data)["f"]
    df = run_offline(SavGol(window=5, order=4, deriv=1, mode="centred"), x=f.data, units={"x": "N"})["y"]
    drive = run_offline(
        WeightedSum(preset=f"touch.{population}"), x1=f.data, x2=df.data, units={"x1": "N", "x2": "N/s"}
    )["y"]
    assert len(drive) == len(f) == int(duration_s * 1000)
    out = run_offline(Nlif(n=N, preset=f"touch.{population}"), x=drive.data, seed=seed + 100)["spikes"]
    keep = out.t >= SETTLE_S
    return out.t[keep], out.data[keep], sensor.config


def rate(t, start, stop):
    """Mean rate per neuron (spikes/s) in [start, stop)."""
    return np.count_nonzero((t >= start) & (t < stop)) / N / (stop - start)


def touch_times(c):
    onset = c.onset_s
    offset = c.onset_s + c.ramp_s + c.hold_s  # the unloading starts
    return onset, offset


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_touch_fa1_fires_at_onset_and_offset_only(seed):
    t, unit, c = spikes(TOUCH, "FA1", seed)
    onset, offset = touch_times(c)
    near = (np.abs(t - onset) <= 0.06) | (np.abs(t - offset) <= 0.06)
    assert len(t) > 0 and near.mean() >= 0.8
    at_onset = unit[(t >= onset) & (t < onset + 0.06)]
    at_offset = unit[(t >= offset) & (t < offset + 0.06)]
    assert len(np.unique(at_onset)) >= N // 2, "most FA1 neurons answer the onset"
    assert len(np.unique(at_offset)) >= N // 2, "most FA1 neurons answer the offset"
    assert rate(t, onset + 0.06, offset - 0.06) < 1.0  # almost nothing on the plateau
    assert rate(t, SETTLE_S, onset - 0.02) < 1.0  # nor at rest


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_touch_sa1_fires_throughout_the_plateau_with_extra_onset_activity(seed):
    t, _, c = spikes(TOUCH, "SA1", seed)
    onset, offset = touch_times(c)
    windows = np.arange(onset, offset - 0.05 + 1e-9, 0.05)
    counts = [np.count_nonzero((t >= w) & (t < w + 0.05)) for w in windows]
    assert min(counts) > 0, "every 50 ms window of the touch has SA1 spikes"
    plateau = rate(t, onset + 0.15, offset)
    assert plateau > 20.0
    assert rate(t, onset, onset + 0.04) >= 1.5 * plateau, "extra activity at onset"
    assert rate(t, SETTLE_S, onset) < 0.2 * plateau, "the holding force alone barely drives SA1"


@pytest.mark.parametrize("scenario", [TOUCH, SLIP], ids=["touch", "slip"])
@pytest.mark.parametrize("population", ["SA1", "FA1"])
def test_rates_stay_below_300_spikes_per_second(scenario, population):
    t, unit, _ = spikes(scenario, population, seed=3)
    counts, _ = np.histogram(t, np.arange(0.0, 1.5 + 1e-9, 0.02))
    assert counts.max() / N / 0.02 <= 300.0
    for k in range(N):  # and no single neuron either
        per_neuron, _ = np.histogram(t[unit == k], np.arange(0.0, 1.5 + 1e-9, 0.02))
        assert per_neuron.max() / 0.02 <= 300.0


def test_slip_sa1_and_fa1_patterns_differ():
    sa1, _, c = spikes(SLIP, "SA1", seed=4)
    fa1, _, _ = spikes(SLIP, "FA1", seed=4)
    drag = c.onset_s + c.ramp_s
    slip = drag + c.drag_s
    end = slip + c.slip_s
    # SA1: driven hardest during the slip, close to its refractory ceiling (~250/s on a 1 kHz grid)
    assert rate(sa1, slip, end) > 150.0
    assert rate(sa1, slip, end) > 2.0 * rate(sa1, drag, slip)
    counts, edges = np.histogram(sa1, np.arange(0.0, 1.5 + 1e-9, 0.02))
    assert slip <= edges[np.argmax(counts)] < end
    # FA1: sparse volleys during the drag and the slip, several times fewer spikes than SA1 there
    assert rate(fa1, drag, end) > 5.0
    assert rate(sa1, slip, end) > 4.0 * rate(fa1, slip, end)
    # the two populations' 20 ms rate profiles over the trial are far from proportional
    fa1_counts, _ = np.histogram(fa1, edges)
    trial = (edges[:-1] >= drag) & (edges[:-1] < end)
    corr = np.corrcoef(counts[trial], fa1_counts[trial])[0, 1]
    assert corr < 0.5
