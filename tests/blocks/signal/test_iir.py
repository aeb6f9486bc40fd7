"""Tests of the iir block (blocks/signal/iir.py): scipy's design and filtering are the oracle."""

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from touchsim_dev import EPS, ba_error_bound, touchsim_traces

from flowtact import ConfigError, SpecError, StreamSpec
from flowtact.blocks.signal.iir import Iir, sos_apply, sos_apply_python
from flowtact.testing import run_offline

signal = pytest.importorskip("scipy.signal")


@pytest.mark.oracle
def test_touchsim_prefilter_equals_scipy_butter_lfilter_on_every_dev_trace():
    """Deliver 1 (prefilter stage): butter(3, 0.004·p0) + lfilter on d (and s for SA1) — TouchSim's
    prefilter — for all 68 traces, one filter per column in a single block (per-channel cut-offs)."""
    traces = touchsim_traces()
    assert len(traces) == 68
    cols, refs, cutoffs, bounds = [], [], [], []
    for key, tr in traces:
        p0 = tr["p"][0]
        b, a = signal.butter(3, 0.004 * p0)
        for name in ("d", "s") if key.split("|")[1] == "SA1" else ("d",):
            x = tr[name]
            ref = signal.lfilter(b, a, x)
            cols.append(x)
            refs.append(ref)
            cutoffs.append(10.0 * p0)  # 0.004·p0 of Nyquist at 5 kHz
            bounds.append(ba_error_bound(b, a, x, ref))
    x = np.stack(cols, axis=1)
    y = run_offline(Iir(order=3, cutoff_hz=cutoffs), x=x, rate_hz=5000.0, chunk=997)["y"].data
    err = np.abs(y - np.stack(refs, axis=1)).max(axis=0)
    assert (err <= np.array(bounds)).all(), (err / np.array(bounds)).max()
    assert np.array(bounds).max() < 1e-6 * np.abs(x).max()  # the bound is tight enough to mean something


@pytest.mark.parametrize(
    ("params", "design"),
    [
        (
            {"family": "butter", "order": 4, "btype": "highpass", "cutoff_hz": [30.0]},
            lambda: signal.butter(4, 30 / 500, "highpass", output="sos"),
        ),
        (
            {"family": "cheby1", "order": 3, "ripple_db": 0.5, "cutoff_hz": [80.0]},
            lambda: signal.cheby1(3, 0.5, 80 / 500, output="sos"),
        ),
        (
            {"family": "ellip", "order": 4, "btype": "bandpass", "cutoff_hz": [20.0], "upper_hz": [120.0]},
            lambda: signal.ellip(4, 1.0, 40.0, [20 / 500, 120 / 500], "bandpass", output="sos"),
        ),
        (
            {"family": "bessel", "order": 2, "cutoff_hz": [50.0]},
            lambda: signal.bessel(2, 50 / 500, output="sos", norm="phase"),
        ),
    ],
)
def test_other_families_equal_scipy_sosfilt_bit_for_bit(params, design):
    """The friends of Butterworth: the same sections and the same recursion as scipy's sosfilt."""
    x = np.random.default_rng(3).normal(size=(3000, 2))
    y = run_offline(Iir(**params), x=x, rate_hz=1000.0, chunk=101)["y"].data
    assert_allclose(y, signal.sosfilt(design(), x, axis=0), rtol=0, atol=64 * EPS * np.abs(x).max())


def test_kernel_equals_its_python_twin_and_state_carries_across_calls():
    rng = np.random.default_rng(4)
    sos = np.stack([signal.butter(3, w, output="sos") for w in (0.01, 0.2, 0.3)], axis=-1)  # (S, 6, C)
    x = rng.normal(size=(500, 3))
    z1, z2 = np.zeros((2, 2, 3)), np.zeros((2, 2, 3))
    whole = sos_apply(x, sos, z1)
    parts = np.concatenate([sos_apply_python(x[:123], sos, z2), sos_apply_python(x[123:], sos, z2)])
    assert_array_equal(whole, parts)
    assert_array_equal(z1, z2)
    assert_allclose(
        whole[:, 2], signal.sosfilt(np.ascontiguousarray(sos[..., 2]), x[:, 2]), rtol=0, atol=64 * EPS
    )  # channel last


def test_zero_initial_state_a_step_starts_at_b0():
    b0 = signal.butter(3, 0.1, output="sos")[0, 0]
    y = run_offline(Iir(cutoff_hz=[250.0]), x=np.ones(5), rate_hz=5000.0)["y"].data
    assert y[0] == b0  # nothing before the stream: not a steady state


def test_cutoffs_must_fit_the_channels_and_nyquist():
    with pytest.raises(SpecError, match="cutoff_hz has 2 values but input 'x' has 3"):
        Iir(cutoff_hz=[1.0, 2.0]).bind({"x": StreamSpec(shape=(3,), rate_hz=100.0)})
    with pytest.raises(SpecError, match="cutoff_hz 60 must be below half the stream's rate"):
        Iir(cutoff_hz=[60.0]).bind({"x": StreamSpec(shape=(), rate_hz=100.0)})
    with pytest.raises(ConfigError, match="upper_hz"):
        Iir(btype="bandpass", cutoff_hz=[5.0])
