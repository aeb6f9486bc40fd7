"""Tests of the rectified_gain block (blocks/signal/rectified_gain.py): TouchSim's input current."""

import numpy as np
import pytest
from numpy.testing import assert_array_equal
from touchsim_dev import EPS, prefilter_bound, touchsim_traces

from flowtact import SpecError, StreamSpec
from flowtact.blocks.signal.iir import Iir
from flowtact.blocks.signal.rectified_gain import RectifiedGain
from flowtact.testing import run_offline

signal = pytest.importorskip("scipy.signal")
stats = pytest.importorskip("scipy.stats")

FS = 5000.0


def touchsim_params(p, noise=False):
    """The block's parameters for TouchSim's p (x1 = s, x2 = d)."""
    out = {
        "pos1": [p[1]], "neg1": [p[2]], "pos2": [p[3]], "neg2": [p[4]],
        "ahead": "x2", "ahead_pos": [p[5]], "ahead_neg": [p[6]], "saturation": [p[7]],
    }  # fmt: skip
    if noise:
        out["noise_sd"] = [p[8]]
    return out


def term_sum(p, s, d):
    """Σ|terms| of step 1 of the README per sample: the scale of the sum's rounding."""
    dd = np.r_[np.diff(d), 0.0]
    return (
        (abs(p[1]) + abs(p[2])) * np.abs(s)
        + (abs(p[3]) + abs(p[4])) * np.abs(d)
        + (abs(p[5]) + abs(p[6])) * np.abs(dd)
    )


@pytest.mark.oracle
def test_reproduces_touchsims_current_from_prefiltered_s_and_d_on_every_dev_trace():
    """Deliver 2 (weighting stage): TouchSim's I (noise off) from scipy's butter+lfilter of s, d and
    the README's steps 1 and 3 (one-sample-ahead Δd, saturation, NaN → 0), all 68 traces.

    Tolerance: our sum rounds by ≤ 8·ε·Σ|terms| per sample (six products, five sums; saturation's
    slope is ≤ 1 and it adds ≤ 3ε·|I|); TouchSim's I was made from its own filtered s, d, which may
    differ from scipy's here by the (b, a) filter's derived bound, carried through the gains
    (``prefilter_bound``; measured: up to 578× the sum's rounding, 6.5e-4 of the bound)."""
    traces = touchsim_traces()
    assert len(traces) == 68
    for key, tr in traces:
        p = tr["p"]
        b, a = signal.butter(3, 0.004 * p[0])
        d = signal.lfilter(b, a, tr["d"])
        s = signal.lfilter(b, a, tr["s"]) if key.split("|")[1] == "SA1" else tr["s"]
        y = run_offline(RectifiedGain(**touchsim_params(p)), x1=s, x2=d, rate_hz=FS, chunk=331)["y"]
        assert len(y.data) == len(tr["I"])  # the held-back last sample comes out at the end
        tol = (8 * term_sum(p, s, d) + 3 * np.abs(tr["I"])) * EPS + prefilter_bound(key, tr)
        assert (np.abs(y.data - tr["I"]) <= tol).all(), key
        # and a wrong convention is far outside: Δd one sample behind (d[n] − d[n−1]) instead of ahead
        if p[5] or p[6]:
            behind = np.r_[0.0, np.diff(d)]
            ahead = np.r_[np.diff(d), 0.0]
            shift = (abs(p[5]) + abs(p[6])) * np.abs(ahead - behind).max()
            assert shift > 1e3 * prefilter_bound(key, tr), key


@pytest.mark.oracle
def test_the_whole_prefilter_and_weighting_chain_reproduces_touchsims_current():
    """s, d → iir (10·p0 Hz, one filter per afferent) → rectified_gain, all 68 traces as the columns
    of one pair of blocks, fed in uneven chunks: TouchSim's I within the derived bounds."""
    traces = touchsim_traces()
    s = np.stack([tr["s"] for _, tr in traces], axis=1)
    d = np.stack([tr["d"] for _, tr in traces], axis=1)
    P = np.stack([tr["p"] for _, tr in traces])
    sa1 = np.array([k.split("|")[1] == "SA1" for k, _ in traces])
    cut = list(10.0 * P[:, 0])
    dfil = run_offline(Iir(cutoff_hz=cut), x=d, rate_hz=FS, chunk=[1, 7, 1000])["y"].data
    sfil = run_offline(Iir(cutoff_hz=cut), x=s, rate_hz=FS, chunk=500)["y"].data
    sfil = np.where(sa1, sfil, s)  # TouchSim prefilters s only for SA1
    y = run_offline(
        RectifiedGain(
            pos1=list(P[:, 1]), neg1=list(P[:, 2]), pos2=list(P[:, 3]), neg2=list(P[:, 4]), ahead="x2",
            ahead_pos=list(P[:, 5]), ahead_neg=list(P[:, 6]), saturation=list(P[:, 7]),
        ),
        x1=sfil, x2=dfil, rate_hz=FS, chunk=[1, 7, 1000],
    )["y"].data  # fmt: skip
    cur = np.stack([tr["I"] for _, tr in traces], axis=1)
    terms = np.stack([term_sum(tr["p"], sfil[:, j], dfil[:, j]) for j, (_, tr) in enumerate(traces)], axis=1)
    tol = (8 * terms + 3 * np.abs(cur)) * EPS + np.array([prefilter_bound(k, tr) for k, tr in traces])
    assert (np.abs(y - cur) <= tol).all()


def test_ahead_difference_stamps_and_end_of_stream():
    """Output n is stamped like input n, Δ[n] = a[n+1] − a[n], and the last sample comes out at the
    flush with Δ = 0 (nothing lost), whatever the chunking."""
    t = np.array([0.0, 0.1, 0.2, 0.3, 0.4])
    a = np.array([1.0, 4.0, 2.0, 2.5, 7.0])
    for chunk in (1, 2, 5):
        out = run_offline(
            RectifiedGain(pos1=[0.0], ahead="x1", ahead_pos=[1.0], ahead_neg=[10.0]),
            x1=a,
            t=t,
            rate_hz=10.0,
            chunk=chunk,
        )["y"]
        assert_array_equal(out.t, t)
        assert_array_equal(out.data, [3.0, 20.0, 0.5, 4.5, 0.0])
    held = run_offline(
        RectifiedGain(pos1=[0.0], ahead="x1", ahead_pos=[1.0]), x1=a, t=t, rate_hz=10.0, flush=False
    )
    assert_array_equal(held["y"].t, t[:-1])  # one sample held back until the stream ends


def test_noise_is_exact_normal_seeded_and_added_before_saturation():
    """Deliver 2/3: (y − y_quiet)/σ is N(0, 1) (Kolmogorov–Smirnov and Cramér–von Mises against
    scipy.stats' N(0, 1) at a 1e-3 false-alarm rate each: a fixed seed, so the test is deterministic, and a
    correct generator fails it for 0.1 % of seeds); the same seed gives the same bits, another seed
    other values; saturation acts on the noisy current (noise first, TouchSim's order)."""
    rng = np.random.default_rng(0)
    x = rng.normal(size=(20000, 3))
    base = {"pos1": [1.0, 2.0, 0.5], "neg1": [0.3]}
    quiet = run_offline(RectifiedGain(**base), x1=x, rate_hz=FS)["y"].data
    noisy = run_offline(
        RectifiedGain(**base, noise_sd=[0.5, 1.0, 2.0]), x1=x, rate_hz=FS, seed=11, chunk=[1, 129, 4096]
    )
    xi = (noisy["y"].data - quiet) / np.array([0.5, 1.0, 2.0])
    z = xi.ravel()
    assert stats.kstest(z, "norm").pvalue > 1e-3
    assert stats.cramervonmises(z, "norm").pvalue > 1e-3  # against N(0, 1) itself, not a fitted normal
    again = run_offline(RectifiedGain(**base, noise_sd=[0.5, 1.0, 2.0]), x1=x, rate_hz=FS, seed=11)["y"].data
    assert_array_equal(again, noisy["y"].data)
    other = run_offline(RectifiedGain(**base, noise_sd=[0.5, 1.0, 2.0]), x1=x, rate_hz=FS, seed=12)["y"].data
    assert not np.any(other == noisy["y"].data)
    sat = run_offline(
        RectifiedGain(**base, noise_sd=[0.5, 1.0, 2.0], saturation=[1.5]), x1=x, rate_hz=FS, seed=11
    )
    i = noisy["y"].data
    assert_array_equal(sat["y"].data, 1.5 * i / (1.5 + np.abs(i)))


def test_saturation_turns_nan_into_zero_and_zero_means_none():
    x = np.array([1.0, -2.0, 10.0])
    y = run_offline(RectifiedGain(pos1=[1e308], neg1=[1e308], saturation=[4.0]), x1=x)["y"].data
    assert_array_equal(y, [4.0 * 1e308 / (4.0 + 1e308), 0.0, 0.0])  # inf/inf → NaN → 0, as TouchSim
    y = run_offline(RectifiedGain(pos1=[3.0], neg1=[1.0], saturation=[0.0]), x1=x)["y"].data
    assert_array_equal(y, [3.0, 2.0, 30.0])


def test_wiring_errors_name_the_port():
    spec = StreamSpec(shape=(2,), rate_hz=FS)
    with pytest.raises(SpecError, match="gains on 'x2' are not zero but 'x2' is not connected"):
        RectifiedGain(pos2=[1.0]).bind({"x1": spec})
    with pytest.raises(SpecError, match="pos1 has 3 values but the inputs have 2 channel"):
        RectifiedGain(pos1=[1.0, 2.0, 3.0]).bind({"x1": spec})
    with pytest.raises(SpecError, match="input 'x2' has shape"):
        RectifiedGain(pos2=[1.0]).bind({"x1": spec, "x2": StreamSpec(shape=(3,), rate_hz=FS)})
    assert RectifiedGain(pos2=[0.0]).needs(frozenset({"x1", "x2"})) == {"x1"}  # zero gains: not needed


def test_kernels_equal_the_numpy_statement():
    """The numba kernels (chunked, one sample held back) against rectified_current's numpy: bit for bit
    without noise; with noise and saturation to 1e-8,
    noise and saturation included: the ξ are recovered from a saturation-free twin run."""
    rng = np.random.default_rng(8)
    s, d = rng.normal(size=(700, 4)), rng.normal(size=(700, 4)) * 3
    gains = {"pos1": [1.0, 0.5, 0.0, 2.0], "neg1": [0.2], "pos2": [-3.0, 1.0, 2.0, 0.1], "neg2": [1.5]}
    ahead = {"ahead": "x2", "ahead_pos": [4.0, 0.0, 1.0, -2.0], "ahead_neg": [0.5]}
    sd, sat = np.array([0.1, 0.2, 0.3, 0.4]), np.array([0.0, 2.0, 5.0, 0.5])
    blk = RectifiedGain(**gains, **ahead, noise_sd=list(sd), saturation=list(sat))
    y = run_offline(blk, x1=s, x2=d, rate_hz=FS, seed=3, chunk=[1, 2, 97, 300])["y"].data
    quiet = run_offline(RectifiedGain(**gains, **ahead), x1=s, x2=d, rate_hz=FS)["y"].data
    loud = run_offline(RectifiedGain(**gains, **ahead, noise_sd=list(sd)), x1=s, x2=d, rate_hz=FS, seed=3)[
        "y"
    ].data
    xi = (loud - quiet) / sd  # the stream's normals, to rounding
    dd = np.r_[np.diff(d, axis=0), np.zeros((1, 4))]
    g = blk.config
    terms = [(s, np.broadcast_to(g.pos1, 4), np.broadcast_to(g.neg1, 4)),
             (d, np.asarray(g.pos2), np.broadcast_to(g.neg2, 4)),
             (dd, np.asarray(g.ahead_pos), np.broadcast_to(g.ahead_neg, 4))]  # fmt: skip
    from flowtact.blocks.signal.rectified_gain import rectified_current

    assert_array_equal(quiet, rectified_current(terms, None, sd, np.zeros(4)))
    ref = rectified_current(terms, np.round(xi, 9), sd, sat)  # ξ recovered to ~1e-15, rounded alike
    assert np.abs(y - ref).max() < 1e-8
