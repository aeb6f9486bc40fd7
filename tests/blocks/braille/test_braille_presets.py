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
