"""The rate block: spikes → firing rate in bins."""

import numpy as np
import pytest

from flowtact import ConfigError, SpecError, StreamSpec
from flowtact.blocks.spiking.nlif import Nlif
from flowtact.blocks.spiking.rate import Rate
from flowtact.chunk import Chunk
from flowtact.testing import assert_same, run_offline


def events(t, idx):
    return (np.asarray(t, np.float64), np.asarray(idx, np.int64))


def run(blk, t, idx, n_units, end):
    """Feed events as one chunk with watermark ``end``, then flush; return bin times and rates."""
    blk.bind({"spikes": StreamSpec(dtype="int64", events=True, n_units=n_units)})
    outs = [blk(spikes=Chunk(np.asarray(t, float), np.asarray(idx, np.int64), end)), blk.flush()]
    y = [o["y"] for o in outs]
    return np.concatenate([c.t for c in y]), np.concatenate([c.data for c in y])


def test_counts_per_bin_and_unit():
    t = [0.001, 0.005, 0.019, 0.020, 0.021, 0.055]
    k = [0, 1, 0, 1, 1, 0]
    bt, y = run(Rate(bin_s=0.02), t, k, 2, end=0.06)
    np.testing.assert_allclose(bt, [0.0, 0.02, 0.04])
    np.testing.assert_allclose(y, [[100.0, 50.0], [0.0, 100.0], [50.0, 0.0]])  # 0.020 is in bin 1


def test_population_mode_is_the_mean_rate_per_unit():
    t = [0.001, 0.005, 0.019, 0.020, 0.021, 0.055]
    k = [0, 1, 0, 1, 1, 0]
    _, y = run(Rate(bin_s=0.02, mode="population"), t, k, 4, end=0.06)
    assert y.shape == (3,)
    np.testing.assert_allclose(y, [150.0 / 4, 100.0 / 4, 50.0 / 4])


def test_bins_wait_for_the_watermark_and_flush_emits_the_partial_bin():
    blk = Rate(bin_s=0.02)
    blk.bind({"spikes": StreamSpec(dtype="int64", events=True, n_units=1)})
    out = blk(spikes=Chunk(np.array([0.001, 0.025]), np.array([0, 0]), 0.03))
    assert out["y"].t.tolist() == [0.0]  # bin [0.02, 0.04) is still open
    out = blk(spikes=Chunk(np.empty(0), np.empty(0, np.int64), 0.04))
    assert out["y"].t.tolist() == [0.02] and out["y"].data.tolist() == [[50.0]]
    out = blk(spikes=Chunk(np.array([0.041]), np.array([0]), 0.045))
    assert len(out["y"]) == 0
    last = blk.flush()["y"]
    assert last.t.tolist() == [0.04]
    assert last.data[0, 0] == pytest.approx(1 / 0.005)  # one spike over the 5 ms covered


def test_grid_times_on_boundaries_land_in_the_later_bin_despite_rounding():
    # 0.06 / 0.02 = 2.9999999999999996 and 15 · 0.02 = 0.30000000000000004 in floating point
    for t, k in [(0.06, 3), (0.3, 15), (0.14, 7), (0.0599, 2)]:
        _, y = run(Rate(bin_s=0.02), [t], [0], 1, end=0.4)
        assert np.argmax(y[:, 0]) == k, t
    grid = np.arange(0, 1000, 4) / 1000.0  # a spike every 4 ms: exactly 5 per 20 ms bin
    _, y = run(Rate(bin_s=0.02), grid, np.zeros(len(grid), np.int64), 1, end=1.0)
    np.testing.assert_array_equal(y[:, 0], 250.0)


@pytest.mark.parametrize("mode", ["unit", "population"])
def test_chunking_invariance_and_empty_chunks(mode):
    rng = np.random.default_rng(2)
    t = np.sort(rng.uniform(0, 2.0, 2000))
    k = rng.integers(0, 5, 2000)
    ref = run_offline(Rate(bin_s=0.02, mode=mode), spikes=events(t, k))
    for chunk in (1, 7, [3, 250, 1, 64]):
        assert_same(run_offline(Rate(bin_s=0.02, mode=mode), spikes=events(t, k), chunk=chunk), ref)
    assert_same(
        run_offline(Rate(bin_s=0.02, mode=mode), spikes=events(t, k), chunk=13, empty_between=True), ref
    )
    total = ref["y"].data.sum() * 0.02 * (5 if mode == "population" else 1)
    assert total == pytest.approx(2000, rel=0.03)  # the partial last bin is normalised by its coverage


def test_rate_of_an_nlif_population_stays_under_the_refractory_bound():
    x = np.full(2000, 1e3)
    spikes = run_offline(Nlif(n=5, refractory_s=0.0035), x=x)["spikes"]
    y = run_offline(Rate(), spikes=spikes)["y"].data
    assert y.shape[1] == 5
    np.testing.assert_allclose(y[:-1], 250.0)  # 4-step ISI on a 1 kHz grid; the last bin is partial
    assert y[:-1].max() <= 1 / 0.0035


def test_late_events_are_counted_and_ignored():
    blk = Rate(bin_s=0.02)
    blk.bind({"spikes": StreamSpec(dtype="int64", events=True, n_units=1)})
    blk(spikes=Chunk(np.array([0.001]), np.array([0]), 0.05))
    blk(spikes=Chunk(np.array([0.01, 0.06]), np.array([0, 0]), 0.07))
    assert blk.counters == {"late_events": 1}


def test_spec_and_config_errors():
    with pytest.raises(SpecError, match="event stream"):
        Rate().bind({"spikes": StreamSpec(rate_hz=1000.0)})
    with pytest.raises(SpecError, match="n_units"):
        Rate().specs({"spikes": StreamSpec(dtype="int64", events=True)})
    spec = Rate(bin_s=0.05).specs({"spikes": StreamSpec(dtype="int64", events=True, n_units=3)})["y"]
    assert spec.shape == (3,) and spec.rate_hz == pytest.approx(20.0) and spec.units == "spikes/s"
    assert (
        Rate(mode="population")
        .specs({"spikes": StreamSpec(dtype="int64", events=True, n_units=3)})["y"]
        .shape
        == ()
    )
    with pytest.raises(ConfigError, match="bin_s"):
        Rate(bin_s=0.0)
    blk = Rate()
    blk.bind({"spikes": StreamSpec(dtype="int64", events=True, n_units=2)})
    with pytest.raises(ValueError, match="out of range"):
        blk(spikes=Chunk(np.array([0.01]), np.array([2]), 0.02))
