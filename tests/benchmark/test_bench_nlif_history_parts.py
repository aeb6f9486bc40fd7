"""The nlif suite's split of the post-spike cost: its helpers drive the kernels' ring as the kernels do."""

from __future__ import annotations

import numpy as np

from flowtact.bench.blocks.spiking.nlif import H_WEIGHTS, RATE_HZ, _ring_adds, _ring_reads
from flowtact.blocks.spiking._lif_kernels import _ring_add_py
from flowtact.blocks.spiking._spike_history import history_table
from flowtact.blocks.spiking.nlif import NLIF_DEFAULTS


def _table() -> np.ndarray:
    return history_table(H_WEIGHTS, NLIF_DEFAULTS["h_peaks_s"], NLIF_DEFAULTS["h_offset_s"], 1 / RATE_HZ)


def test_the_suite_measures_a_212_tap_current():
    assert len(_table()) - 1 == 212  # the taps bench/README and the suite's docstring name


def test_ring_adds_put_each_spike_at_the_next_slot_as_the_numpy_twin_does():
    h, rows = _table(), np.array([3, 0, 3, 7, 1] * 60)  # 300 spikes: slots wrap past 212
    ring, twin = np.zeros((8, len(h) - 1)), np.zeros((8, len(h) - 1))
    _ring_adds(ring, h, rows)
    for j, k in enumerate(rows):
        _ring_add_py(twin, j % twin.shape[1], int(k), h, 0.0)
    assert np.array_equal(ring, twin) and np.any(ring != 0)


def test_ring_reads_move_every_slot_into_the_drive_and_clear_it():
    ring = np.arange(1.0, 1 + 4 * 5).reshape(4, 5)
    drive = np.zeros(4)
    _ring_reads(ring, drive, 7)  # slots 0 … 4, then 0 and 1 again (cleared by then)
    assert np.array_equal(drive, np.arange(1.0, 1 + 4 * 5).reshape(4, 5).sum(axis=1))
    assert not ring.any()
