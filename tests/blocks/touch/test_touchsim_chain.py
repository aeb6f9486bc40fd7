"""touchsim_chain: the fused block equals the chain of generic blocks (iir → rectified_gain → nlif)
bit for bit — spikes and current, noise on, any chunking — and so fires TouchSim's spikes."""

import itertools

import numpy as np
import pytest
from touchsim_dev import touchsim_traces

from flowtact.blocks.signal.iir import Iir
from flowtact.blocks.signal.rectified_gain import RectifiedGain
from flowtact.blocks.spiking.nlif import Nlif
from flowtact.blocks.touch.touchsim import touchsim_models
from flowtact.blocks.touch.touchsim_chain import TouchsimChain
from flowtact.chunk import Chunk, StreamSpec

pytest.importorskip("scipy.signal")

FS = 5000.0


def _generic(models, seed, noise=True):
    """The chain of graphs/touchsim_afferents.yaml as bound blocks; the current's seed is ``seed``."""
    p = np.array([touchsim_models()[m] for m in models])
    cut = (10.0 * p[:, 0]).tolist()
    col = lambda k: p[:, k].tolist()  # noqa: E731
    blocks = [
        Iir(family="butter", order=3, cutoff_hz=cut),
        Iir(family="butter", order=3, cutoff_hz=cut),
        RectifiedGain(
            pos1=col(1), neg1=col(2), pos2=col(3), neg2=col(4), ahead="x2", ahead_pos=col(5),
            ahead_neg=col(6), saturation=col(7), noise_sd=col(8) if noise else [0.0],
        ),
        Nlif(models=list(models)),
    ]  # fmt: skip
    spec = StreamSpec(dtype="float64", shape=(len(models),), rate_hz=FS)
    blocks[0].bind({"x": spec}, seed=99)
    blocks[1].bind({"x": spec}, seed=98)
    blocks[2].bind({"x1": spec, "x2": spec}, seed=seed)
    blocks[3].bind({"x": spec}, seed=97, demanded=frozenset({"spikes"}))
    return blocks


def _run_generic(blocks, s, d, cuts):
    fs, fd, cur, neu = blocks
    spikes, currents = [], []
    t_all = np.arange(len(s)) / FS
    for a, b in itertools.pairwise(cuts):
        t = t_all[a:b]
        y = cur(x1=fs(x=Chunk(t, s[a:b]))["y"], x2=fd(x=Chunk(t, d[a:b]))["y"])["y"]
        currents.append(y)
        spikes.append(neu(x=y)["spikes"])
    y = cur.flush()["y"]
    currents.append(y)
    spikes.append(neu(x=y)["spikes"])
    return spikes, currents


def _run_fused(block, s, d, cuts):
    spikes, currents = [], []
    t_all = np.arange(len(s)) / FS
    for a, b in itertools.pairwise(cuts):
        t = t_all[a:b]
        out = block(s=Chunk(t, s[a:b]), d=Chunk(t, d[a:b]))
        spikes.append(out["spikes"])
        currents.append(out["current"])
    out = block.flush()
    spikes.append(out["spikes"])
    currents.append(out["current"])
    return spikes, currents


def _dev():
    traces = touchsim_traces()
    models = [".".join(key.split("|")[1:]) for key, _ in traces]  # STIM|SA1|0 -> SA1.0
    s = np.stack([tr["s"] for _, tr in traces], axis=1)
    d = np.stack([tr["d"] for _, tr in traces], axis=1)
    return traces, models, s, d


def _joined(chunks):
    t = np.concatenate([c.t for c in chunks])
    x = np.concatenate([np.asarray(c.data).reshape(len(c.t), *np.shape(c.data)[1:]) for c in chunks])
    return t, x


def _equal_to_the_chain(models, s, d, chunk):
    n = len(s)
    cuts = [*range(0, n, chunk), n]
    g_spk, g_cur = _run_generic(_generic(models, seed=5), s, d, cuts)
    fused = TouchsimChain(models=models)
    spec = StreamSpec(dtype="float64", shape=(len(models),), rate_hz=FS)
    fused.bind({"s": spec, "d": spec}, seed=5, demanded=frozenset({"spikes", "current"}))
    f_spk, f_cur = _run_fused(fused, s, d, cuts)
    assert len(f_spk) == len(g_spk)
    for a, b in zip(g_cur, f_cur, strict=True):
        np.testing.assert_array_equal(a.t, b.t)
        assert a.data.tobytes() == b.data.tobytes()
    for a, b in zip(g_spk, f_spk, strict=True):
        np.testing.assert_array_equal(a.t, b.t)
        np.testing.assert_array_equal(a.data, b.data)
        assert a.end == b.end
    return sum(len(c.t) for c in f_spk)


@pytest.mark.parametrize("chunk", [1, 7, 50, 4000])
def test_the_fused_block_equals_the_generic_chain_bit_for_bit_with_noise(chunk):
    """Deliver 4 (issue 33, speed): on the 68 development traces, noise on, the fused block's current
    and spikes are the chain's to the bit, chunk by chunk (the same tick partition of spikes too)."""
    _, models, s, d = _dev()
    assert _equal_to_the_chain(models, s, d, chunk) > 1000  # noise on: the traces fire


def test_many_tiles_and_noise_streams_equal_the_chain_bit_for_bit():
    """4 352 afferents (68 tiles, 2 noise streams of 4 096), the traces' columns shuffled so SA1
    (whose s is filtered) and the others share tiles: still the chain's current and spikes."""
    _, models, s, d = _dev()
    cols = np.random.default_rng(3).permutation(np.arange(4352) % len(models))
    s, d = np.ascontiguousarray(s[:1200, cols]), np.ascontiguousarray(d[:1200, cols])
    assert _equal_to_the_chain([models[c] for c in cols], s, d, 50) > 1000


def test_tiles_without_sa1_equal_the_chain_bit_for_bit():
    """The one-pass row's other form: tiles whose afferents are all RA or PC (s not filtered).
    The columns sorted so SA1 comes last: 256 afferents, the first three tiles of 64 have no SA1."""
    _, models, s, d = _dev()
    cols = sorted(np.arange(256) % len(models), key=lambda c: models[c].startswith("SA1"))
    assert not any(models[c].startswith("SA1") for c in cols[:192])
    s, d = np.ascontiguousarray(s[:1200, cols]), np.ascontiguousarray(d[:1200, cols])
    assert _equal_to_the_chain([models[c] for c in cols], s, d, 50) > 100


def test_the_fused_block_fires_touchsims_spikes_on_every_dev_trace():
    """Done means (issue 33): noise off, all 68 traces, TouchSim's spikes on the same samples."""
    traces, models, s, d = _dev()
    n = len(s)
    fused = TouchsimChain(models=models, noise_scale=0.0)
    spec = StreamSpec(dtype="float64", shape=(len(models),), rate_hz=FS)
    fused.bind({"s": spec, "d": spec})
    spk, _ = _run_fused(fused, s, d, [*range(0, n, 25), n])
    t, unit = _joined(spk)
    samples = np.rint(t * FS).astype(np.int64)
    for j, (key, tr) in enumerate(traces):
        np.testing.assert_array_equal(samples[unit == j], tr["spk"], err_msg=key)


def test_s_is_filtered_only_where_a_model_weighs_it():
    """TouchSim filters s for SA1 only: RA and PC have no s gains, so their s never matters."""
    _, models, s, d = _dev()
    spec = StreamSpec(dtype="float64", shape=(len(models),), rate_hz=FS)
    outs = []
    for s_in in (s, np.where(np.array([m.startswith("SA1") for m in models]), s, 1e3)):
        b = TouchsimChain(models=models, noise_scale=0.0)
        b.bind({"s": spec, "d": spec}, demanded=frozenset({"spikes", "current"}))
        outs.append(_joined(_run_fused(b, s_in, d, [0, len(s)])[1])[1])
    assert outs[0].tobytes() == outs[1].tobytes()


def test_an_unknown_model_is_refused_by_name():
    with pytest.raises(Exception, match=r"unknown TouchSim model 'SA2\.0'"):
        TouchsimChain(models=["SA1.0", "SA2.0"])
