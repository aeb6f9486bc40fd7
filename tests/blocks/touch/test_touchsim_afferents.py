"""TouchSim's afferent models in nlif: spike for spike against TouchSim's own runs.

The oracle is TouchSim itself: its development set (tests/data/touchsim_dev.npz, read by
flowtact.bench.touchsim_dev_set) holds, for 68 traces (17 models × 4 stimuli, noise off, made by
TouchSim's code), TouchSim's input current ``I`` (samples at 5 kHz), its spikes as sample indices
(spike time × 5000 − 1) and each model's parameters; tests/data/touchsim_ihbasis.npz is its
post-spike basis (/work/shared/touchsim/README.md).
"""

import subprocess
import sys
from pathlib import Path

import numpy as np
import touchsim_dev

from flowtact.blocks.spiking.nlif import Nlif
from flowtact.blocks.touch.touchsim import TOUCHSIM_PRESETS, TOUCHSIM_RATE_HZ, touchsim_models
from flowtact.recording.hdf5 import read_recording
from flowtact.testing import run_offline

MODEL_NAMES = [f"SA1.{i}" for i in range(4)] + [f"RA.{i}" for i in range(9)] + [f"PC.{i}" for i in range(4)]


def dev_set():
    """(names 'STIM|CLASS|IDX', model names, currents (T, 68), TouchSim's spike indices per trace)."""
    dev = touchsim_dev.dev_set()
    return list(dev.names), dev.models, np.ascontiguousarray(dev.current), dev.spikes


def spike_indices(out, n_units):
    """Per unit, the sample indices of its spikes (nlif stamps a spike at its sample's time n/fs)."""
    sp = out["spikes"]
    idx = np.rint(sp.t * TOUCHSIM_RATE_HZ).astype(np.int64)
    assert np.allclose(idx / TOUCHSIM_RATE_HZ, sp.t, rtol=0, atol=1e-9)
    return [idx[sp.data == k] for k in range(n_units)]


def test_the_17_models_are_touchsims_parameters():
    models = touchsim_models()
    assert list(models) == MODEL_NAMES
    assert all(len(p) == 13 for p in models.values())
    dev = touchsim_dev.dev_set()
    names = dev.names
    # the dev set carries the parameters its traces were made with: the package's copy equals them
    assert len(names) == 68 and {".".join(n.split("|")[1:]) for n in names} == set(MODEL_NAMES)
    for name, p in zip(names, dev.params, strict=True):
        # p12 (conduction delay) is 0 in the dev set: TouchSim's default turns delays off
        assert models[".".join(name.split("|")[1:])][:12] == tuple(p[:12]) and p[12] == 0, name


def test_nlif_basis_in_touchsim_terms_is_touchsims_basis():
    # lag k of nlif's table (k·dt after the spike's step) is TouchSim's tap k − 1; both columns
    # agree to float64 rounding of log/cos (a few ulp of 1): a wrong peak or offset errs by > 1e-3
    from flowtact.blocks.spiking._spike_history import history_table

    ihbasis = np.load(touchsim_dev.IHBASIS)["ihbasis"]
    p = TOUCHSIM_PRESETS["SA1.0"]
    for col, row in ((0, 0), (3, 1)):
        w = np.zeros(4)
        w[col] = 1.0
        h = history_table(w, p["h_peaks_s"], p["h_offset_s"], 1 / TOUCHSIM_RATE_HZ)
        assert len(h) == 191
        np.testing.assert_allclose(h[1:], ihbasis[row], rtol=0, atol=1e-14)


def test_all_68_dev_traces_spike_for_spike_from_touchsims_current():
    """Deliver 1 / Done means: from TouchSim's current (noise off), the same spike count and the
    same sample index for every spike, on every trace — one population mixing all 17 models."""
    names, models, current, expected = dev_set()
    out = run_offline(Nlif(models=models), x=current, rate_hz=TOUCHSIM_RATE_HZ, chunk=997)
    got = spike_indices(out, len(names))
    bad = [
        (n, len(e), len(g)) for n, e, g in zip(names, expected, got, strict=True) if not np.array_equal(e, g)
    ]
    assert not bad, f"{len(bad)} of 68 traces differ (name, TouchSim's count, ours): {bad[:5]}"
    assert sum(len(e) for e in expected) == 1703  # the README's total: the whole set was compared


def test_each_model_alone_as_a_preset():
    names, _models, current, expected = dev_set()
    k = names.index("sine100|PC|1")
    out = run_offline(Nlif(preset="touch.PC.1"), x=current[:, k : k + 1], rate_hz=TOUCHSIM_RATE_HZ)
    np.testing.assert_array_equal(spike_indices(out, 1)[0], expected[k])


def test_summed_history_misses_touchsims_spikes():
    """The parity test above can fail: nlif's default summed kernel (Rager's) with the same
    parameters misses TouchSim's spikes wherever spikes come closer than the kernel (~38 ms).
    (Without the threshold block the dev set still agrees: its kernels inhibit for longer than
    1.2 ms; tests/blocks/spiking/test_nlif_units.py checks the block itself.)"""
    names, models, current, expected = dev_set()
    differ = []
    for k, m in enumerate(models):
        change = {"history": "sum", "threshold_block_s": 0.0}
        out = run_offline(
            Nlif(preset=f"touch.{m}", **change), x=current[:, k : k + 1], rate_hz=TOUCHSIM_RATE_HZ
        )
        if not np.array_equal(spike_indices(out, 1)[0], expected[k]):
            differ.append(names[k])
    assert len(differ) >= 10, differ


def test_the_shipped_graph_replays_touchsims_current_spike_for_spike(tmp_path):
    """Deliver 2: ``flowtact run graphs/touchsim_currents.yaml --fast --replay current=FILE.npz``
    with TouchSim's currents of one stimulus (17 traces, one per model, in the graph's column
    order): the recording's ``afferents.spikes`` are TouchSim's, unit index = column."""
    names, _, current, expected = dev_set()
    cols = [names.index(f"noise7|{m.replace('.', '|')}") for m in MODEL_NAMES]
    t = np.arange(current.shape[0]) / TOUCHSIM_RATE_HZ
    np.savez(tmp_path / "touchsim_noise7.npz", t=t, y=np.ascontiguousarray(current[:, cols]))
    graph = Path(__file__).parents[3] / "graphs" / "touchsim_currents.yaml"
    cmd = ["run", str(graph), "--fast", "--replay", "current=touchsim_noise7.npz", "--record", "out.h5"]
    proc = subprocess.run(
        [sys.executable, "-m", "flowtact.cli", *cmd],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stderr
    spikes = read_recording(tmp_path / "out.h5").streams["afferents.spikes"]
    got = spike_indices({"spikes": spikes}, len(MODEL_NAMES))
    for unit, col in enumerate(cols):
        np.testing.assert_array_equal(got[unit], expected[col], err_msg=names[col])
    assert len(spikes.t) == sum(len(expected[c]) for c in cols) > 300


def test_an_unknown_model_in_the_graph_is_refused_at_its_place(tmp_path):
    graph = Path(__file__).parents[3] / "graphs" / "touchsim_currents.yaml"
    text = graph.read_text().replace("models: [SA1.0, SA1.1,", "models: [SA1.0, SA1.9,")
    (tmp_path / "g.yaml").write_text(text)
    (tmp_path / "touchsim_currents.npz").symlink_to(graph.with_suffix(".npz"))
    proc = subprocess.run(
        [sys.executable, "-m", "flowtact.cli", "validate", "g.yaml"],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=tmp_path,
    )
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    line = proc.stderr.splitlines()[0]
    assert (
        line.startswith("g.yaml:")
        and "afferents (nlif): 'models' item 1: 'SA1.9' is not an nlif preset" in line
    )
