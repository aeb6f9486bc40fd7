"""The synapse block: spikes → currents through sparse weights with exponential decay."""

import numpy as np
import pytest
from scipy.signal import lfilter

from flowtact import ConfigError, SpecError, StreamSpec
from flowtact.blocks.spiking.synapse import Synapse, grid_connectivity
from flowtact.chunk import Chunk
from flowtact.testing import run_offline


def _spikes(seed, n=600, n_src=24, duration=2.0):
    rng = np.random.default_rng(seed)
    t = np.sort(rng.integers(0, int(duration * 250), n)) / 250.0  # on the 4 ms grid, like nlif's
    t = np.concatenate([t, np.sort(rng.uniform(0.0, duration, n // 2))])  # and anywhere in a bin
    order = np.argsort(t, kind="stable")
    return t[order], rng.integers(0, n_src, len(t))[order]


@pytest.mark.oracle
@pytest.mark.parametrize("chunk", [None, 1, 17])
def test_currents_match_lfilter_of_binned_spikes_times_weights(chunk):
    t, idx = _spikes(4)
    rng = np.random.default_rng(8)
    w = rng.normal(0.0, 1.0, (7, 24)) * (rng.random((7, 24)) < 0.2)  # sparse, signed
    rate, tau = 250.0, 0.012
    out = run_offline(
        Synapse(weights=w.tolist(), tau_s=tau, rate_hz=rate), spikes=(t, idx), rate_hz=rate, chunk=chunk
    )["y"]
    # the oracle: bin the spikes independently, weight them, filter y[k] = a·y[k−1] + x[k]
    n_bins = len(out)
    counts = np.zeros((n_bins, 24))
    bins = np.floor(t * rate + 1e-9).astype(int)
    np.add.at(counts, (bins, idx), 1.0)
    drive = counts @ w.T
    a = np.exp(-1.0 / (rate * tau))
    expected = lfilter([1.0], [1.0, -a], drive, axis=0)
    assert n_bins >= int(t.max() * rate)  # every spike's bin came out
    np.testing.assert_allclose(out.data, expected, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(out.t, np.arange(n_bins) / rate, rtol=0, atol=1e-12)


def _one(weights, index):
    """The currents after one spike of source ``index`` at t = 0, watermark at 5 ms (1 kHz bins)."""
    blk = Synapse(weights=weights, tau_s=0.01, rate_hz=1000.0)
    blk.bind({"spikes": StreamSpec(dtype="int64", events=True, n_units=len(weights[0]))})
    return blk(spikes=Chunk(np.array([0.0]), np.array([index]), 0.005))["y"]


def test_a_spike_adds_its_weight_at_once_then_decays_with_tau():
    out = _one([[2.0, 0.0]], 0)
    assert len(out) == 5 and out.data[0, 0] == 2.0
    np.testing.assert_allclose(out.data[:, 0], 2.0 * np.exp(-0.1 * np.arange(5)), rtol=1e-14)
    assert not _one([[2.0, 0.0]], 1).data.any()  # source 1 has no weight


def test_grid_connectivity_samples_one_to_three_adjacent_sources_and_covers_the_grid():
    fields = grid_connectivity(49, (6, 4), (1, 3), seed=13)
    assert len(fields) == 49
    sizes = [len(f) for f in fields]
    assert min(sizes) == 1 and max(sizes) == 3 and len(set(sizes)) == 3
    assert set().union(*map(set, fields)) == set(range(24))  # every afferent reaches a cuneate neuron
    for f in fields:  # connected through 4-neighbours
        cells = {divmod(s, 4) for s in f}
        seen, todo = set(), [next(iter(cells))]
        while todo:
            r, c = todo.pop()
            seen.add((r, c))
            todo += [n for n in ((r + 1, c), (r - 1, c), (r, c + 1), (r, c - 1)) if n in cells - seen]
        assert seen == cells, f"field {f} is not adjacent"
    assert grid_connectivity(49, (6, 4), (1, 3), seed=13) == fields  # its own seed: reproducible
    assert grid_connectivity(49, (6, 4), (1, 3), seed=14) != fields


def test_grid_weights_are_the_connectivity_and_ignore_the_graph_seed():
    cfg = Synapse(grid=[6, 4], n_targets=49, weight=0.7, connect_seed=13).config
    w = cfg.matrix()
    fields = grid_connectivity(49, (6, 4), (1, 3), 13)
    assert w.shape == (49, 24)
    assert [sorted(np.flatnonzero(r)) for r in w] == fields and set(w[w != 0]) == {0.7}
    a = run_offline(Synapse(grid=[6, 4], n_targets=49), spikes=_spikes(1), seed=1)["y"]
    b = run_offline(Synapse(grid=[6, 4], n_targets=49), spikes=_spikes(1), seed=2)["y"]
    assert np.array_equal(a.data, b.data)


@pytest.mark.parametrize(
    ("params", "field"),
    [
        ({}, "weights"),
        ({"weights": [[1.0]], "grid": [6, 4]}, "weights"),
        ({"weights": [[1.0, 2.0], [1.0]]}, "weights"),
        ({"weights": [[float("nan")]]}, "weights"),
        ({"grid": [6, 4], "fan_in": [3, 1]}, "fan_in"),
        ({"grid": [6, 4], "weight": float("inf")}, "weight"),
    ],
)
def test_bad_parameters_are_refused_naming_the_parameter(params, field):
    with pytest.raises(ConfigError) as e:
        Synapse(**params)
    assert e.value.field == field and "synapse" in str(e.value)


def test_a_spike_stream_of_the_wrong_population_size_is_refused():
    blk = Synapse(weights=[[1.0, 1.0, 1.0]])
    with pytest.raises(SpecError, match="3 source columns but 'spikes' has 24 units"):
        blk.bind({"spikes": StreamSpec(dtype="int64", events=True, n_units=24)})


def test_an_index_outside_the_population_is_an_error_not_a_silent_drop():
    blk = Synapse(weights=[[1.0, 1.0]])
    blk.bind({"spikes": StreamSpec(dtype="int64", events=True, n_units=2)})
    with pytest.raises(ValueError, match=r"source index out of range 0\.\.1"):
        blk(spikes=Chunk(np.array([0.001]), np.array([2]), 0.002))


def test_late_spikes_are_counted_and_ignored():
    blk = Synapse(weights=[[1.0]], rate_hz=1000.0)
    blk.bind({"spikes": StreamSpec(dtype="int64", events=True, n_units=1)})
    first = blk(spikes=Chunk(np.array([0.0]), np.array([0]), 0.005))
    assert len(first["y"]) == 5
    blk(spikes=Chunk(np.array([0.002]), np.array([0]), 0.006))  # bin 2 was already emitted
    assert blk.counters["late_events"] == 1
