"""Raised-cosine post-spike basis (NUMERICS §4) and the streaming post-spike current."""

import numpy as np
import pytest

from flowtact.blocks.spiking._spike_history import (
    basis_peaks_s,
    basis_support_s,
    history_reference,
    history_stream,
    history_stream_py,
    history_table,
    raised_cosine_basis,
)
from flowtact.blocks.spiking.nlif import Nlif
from flowtact.testing import run_offline

NB, PEAKS, B = 5, (0.002, 0.05), 0.005


def test_peak_times_and_support_match_the_glmspiketools_example():
    np.testing.assert_allclose(basis_peaks_s(NB, PEAKS, B) * 1e3, [2.0, 6.72, 14.62, 27.85, 50.0], atol=0.01)
    support = basis_support_s(NB, PEAKS, B)
    assert 0.149 <= support < 0.150  # "support 0–149 ms at dt = 1 ms"
    assert len(history_table([1.0] * NB, PEAKS, B, 1e-3)) == 150  # lags 0 … 149 ms


def test_partition_of_unity_between_second_and_second_to_last_peak():
    peaks = basis_peaks_s(NB, PEAKS, B)
    t = np.linspace(peaks[1], peaks[-2], 20001)
    total = raised_cosine_basis(t, NB, PEAKS, B).sum(axis=1)
    np.testing.assert_allclose(total, 2.0, rtol=0, atol=1e-12)
    # and for another shape
    t = np.linspace(0.0, 0.3, 30001)
    peaks8 = basis_peaks_s(8, (0.001, 0.1), 0.002)
    inside = (t >= peaks8[1]) & (t <= peaks8[-2])
    np.testing.assert_allclose(
        raised_cosine_basis(t, 8, (0.001, 0.1), 0.002)[inside].sum(axis=1), 2.0, atol=1e-12
    )


@pytest.mark.parametrize("dt", [1e-3, 1e-4])
def test_column_argmax_at_its_peak(dt):
    t = np.arange(0, basis_support_s(NB, PEAKS, B) + dt, dt)
    raw = raised_cosine_basis(t, NB, PEAKS, B, first_flat=False)
    peaks = basis_peaks_s(NB, PEAKS, B)
    for j in range(NB):
        assert abs(t[np.argmax(raw[:, j])] - peaks[j]) <= dt
    flat = raised_cosine_basis(t, NB, PEAKS, B)
    assert (flat[t <= PEAKS[0], 0] == 1.0).all()  # GLMspiketools: column 0 flat before its peak


def test_basis_is_a_function_of_continuous_time():
    coarse_t = np.arange(150) * 1e-3
    fine_t = np.arange(150_000) * 1e-6
    coarse = raised_cosine_basis(coarse_t, NB, PEAKS, B)
    fine = raised_cosine_basis(fine_t, NB, PEAKS, B)[::1000]
    np.testing.assert_allclose(coarse, fine, rtol=0, atol=1e-12)
    h1 = history_table([0.3, -0.2, 0.1, 0.05, -0.4], PEAKS, B, 1e-3)
    h2 = history_table([0.3, -0.2, 0.1, 0.05, -0.4], PEAKS, B, 1e-4)
    np.testing.assert_allclose(h1, h2[::10][: len(h1)], atol=1e-12)


def test_streaming_current_equals_convolution_whatever_the_chunking():
    rng = np.random.default_rng(0)
    spikes = rng.random((3000, 6)) < 0.05
    h = history_table([-0.5, -0.3, 0.2, -0.1, -0.05], PEAKS, B, 1e-3)
    ref = history_reference(spikes, h)
    for sizes in ([3000], [1], [7, 500, 1, 64]):
        ring, pos, start, parts = np.zeros((6, len(h) - 1)), 0, 0, []
        i = 0
        while start < 3000:
            k = min(sizes[i % len(sizes)], 3000 - start)
            out, pos = history_stream(spikes[start : start + k], h, ring, pos)
            parts.append(out)
            start += k
            i += 1
        np.testing.assert_allclose(np.concatenate(parts), ref, rtol=0, atol=1e-12)
    out_py, _ = history_stream_py(spikes, h, np.zeros((6, len(h) - 1)), 0)
    np.testing.assert_allclose(out_py, ref, rtol=0, atol=1e-12)
    out_nb, _ = history_stream(spikes, h, np.zeros((6, len(h) - 1)), 0)
    np.testing.assert_array_equal(out_nb, out_py)


@pytest.mark.parametrize("tile_n", [3, 40])
def test_neuron_sees_exactly_the_convolved_history_current(tile_n):
    """With τ ≪ dt the exp step sets v to the drive, so v(t_{n+1}) = I_hist[n] on silent steps."""
    rng = np.random.default_rng(1)
    n_t = 600
    forced = rng.random((n_t, tile_n)) < 0.04
    x = np.where(forced, 50.0, 0.0)
    w = [-0.3, -0.2, -0.1, -0.05, -0.02]
    out = run_offline(Nlif(n=tile_n, tau_s=1e-9, h_weights=w, h_peaks_s=list(PEAKS), h_offset_s=B), x=x)
    fired = np.zeros((n_t, tile_n), bool)
    steps = np.round(out["spikes"].t * 1000).astype(int)
    fired[steps, out["spikes"].data] = True
    np.testing.assert_array_equal(fired, forced)  # the history current never prevents a forced spike
    i_hist = history_reference(forced, history_table(w, PEAKS, B, 1e-3))
    v_next = out["v"].data[1:]  # v(t_{n+1}) for n = 0 … n_t − 2
    silent = ~forced[:-1]
    np.testing.assert_allclose(v_next[silent], i_hist[:-1][silent], rtol=0, atol=1e-12)
    assert (i_hist[:-1][silent] < -0.01).sum() > 100  # the comparison is not vacuous
