"""The braille domain's presets: published, and they build the pathway's populations."""

import numpy as np

from flowtact.blocks.braille.presets import AFFERENT, CUNEATE_SYNAPSE
from flowtact.blocks.spiking.nlif import Nlif
from flowtact.blocks.spiking.synapse import Synapse, grid_connectivity
from flowtact.catalog.presets import presets_for


def test_the_braille_domain_publishes_its_neuron_and_synapse_presets():
    assert {"braille.afferent", "braille.cuneate"} <= set(presets_for("nlif"))
    assert set(presets_for("synapse")) == {"braille.cuneate"}


def test_presets_build_24_afferents_and_49_cuneate_neurons_on_a_fixed_connectivity():
    assert Nlif(preset="braille.afferent").config.n == 24 and Nlif(preset="braille.cuneate").config.n == 49
    w = Synapse(preset="braille.cuneate").config.matrix()
    assert w.shape == (49, 24)
    fields = grid_connectivity(49, (6, 4), (1, 3), CUNEATE_SYNAPSE["connect_seed"])
    assert [list(np.flatnonzero(r)) for r in w] == fields
    assert AFFERENT["refractory_s"] >= 2 / 250.0  # at most 125 spikes/s on the 4 ms clock


def _cuneate_spikes(afferent_times: np.ndarray, source: int, **nlif: float) -> np.ndarray:
    """Spike times of every cuneate neuron (preset synapse and nlif, offline) for one afferent's train."""
    from flowtact.chunk import StreamSpec
    from flowtact.testing import run_offline

    spec = {"spikes": StreamSpec("int64", (), "1", 250.0, events=True, n_units=24)}
    t = np.asarray(afferent_times, np.float64)
    y = run_offline(Synapse(preset="braille.cuneate"), specs=spec, spikes=(t, np.full(len(t), source)))["y"]
    x = np.vstack([y.data, np.zeros((10, y.data.shape[1]))])  # let the currents decay past the last spike
    s = run_offline(Nlif(preset="braille.cuneate", **nlif), x=x, rate_hz=250.0)["spikes"]
    return np.column_stack([s.t, s.data])


def test_a_cuneate_neuron_relays_each_spike_of_its_single_afferent_at_once_and_only_once():
    # The session-39 repair (docs/braille.md, "The second-order layer"): with the old preset (gain 1,
    # tau_syn 10 ms) an isolated afferent spike fired nothing (4 at 80 spikes/s fired one), so
    # the layer dropped the 1-2 spike responses that tell weak and off-centre dots apart.
    w = Synapse(preset="braille.cuneate").config.matrix()
    rng = np.random.default_rng(3)
    isi = np.round(rng.uniform(2, 12, 40)) * 0.004  # 8-48 ms: the afferents' refractory allows >= 8 ms
    train = 0.1 + np.cumsum(isi)
    for source in range(24):
        got = _cuneate_spikes(train, source, sigma=0.0)
        for target in range(49):
            times = got[got[:, 1] == target, 0]
            if w[target, source] == 0:
                assert len(times) == 0, f"neuron {target} does not sample afferent {source}"
            else:  # one spike for each afferent spike, in the same 4 ms sample
                np.testing.assert_allclose(times, train, atol=1e-9, err_msg=f"neuron {target}")
    # with the preset's noise (sigma 1 /sqrt(s)) the margin (6 noise sd) still passes every spike
    got = _cuneate_spikes(train, 5, sigma=1.0)
    for target in np.flatnonzero(w[:, 5]):
        assert len(got[got[:, 1] == target]) == len(train)


def test_the_cuneate_connectivity_keeps_every_afferent_recoverable():
    # A linear pooling through the preset's 49 x 24 matrix loses nothing (rank 24): the information
    # the old layer lost came from its threshold, not from which afferents it samples. Not true of
    # every draw: connect_seed 21 or 22 gives rank 23.
    w = Synapse(preset="braille.cuneate").config.matrix()
    assert np.linalg.matrix_rank(w) == 24
    bad = Synapse(**{**CUNEATE_SYNAPSE, "connect_seed": 21}).config.matrix()
    assert np.linalg.matrix_rank(bad) == 23
