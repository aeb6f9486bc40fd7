"""Tests of blocks/signal/savgol.py: savgol (against scipy, NUMERICS.md §1.4), weighted_sum, delay."""

import doctest
from fractions import Fraction
from math import factorial

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from flowtact import BadDataError, Chunk, ConfigError, SpecError, StreamSpec, concat
from flowtact.blocks.signal.delay import Delay
from flowtact.blocks.signal.savgol import (
    SavGol,
    _exact_coeffs,
    deriv_units,
    savgol_apply,
    savgol_apply_numpy,
    savgol_coeffs,
)
from flowtact.blocks.signal.weighted_sum import WeightedSum
from flowtact.blocks.touch.presets import table_i_weights
from flowtact.errors import MisalignedError
from flowtact.testing import assert_same, run_offline

signal = pytest.importorskip("scipy.signal")

RATE = 1000.0


def random_walk(n: int, channels: int | None = None, seed: int = 0) -> np.ndarray:
    """A random walk plus white noise, O(10): the oracle signal of NUMERICS.md §1.4."""
    rng = np.random.default_rng(seed)
    shape = (n,) if channels is None else (n, channels)
    return np.cumsum(rng.normal(0.0, 0.1, shape), axis=0) + rng.normal(0.0, 0.01, shape)


def oracle_atol(x: np.ndarray, window: int, order: int, deriv: int, pos=None, rate_hz=RATE) -> float:
    """Absolute tolerance of the block against scipy's Savitzky–Golay filter on ``x`` (NUMERICS.md §1.4).

    Each output is a dot product Σ c_i·x_i, so its rounding error scales with the terms, not with the
    result: about N·eps·Σ|c|·max|x| (×4 covers the block, scipy and the rounding of c). A bound scaled
    by max|y| breaks where the terms cancel (a derivative of a slow walk: max|y| ≪ Σ|c|·max|x|), so it
    passes or fails with the numpy/scipy build (9/4/2 causal, scipy 1.17.1: 9.3e-7 at max|y| 6.5e5).
    scipy's c comes from a float least-squares solve and is itself off (5e-14 relative for 9/4/2,
    more than 4·N·eps); the reference inherits that as Σ|c − c_exact|·max|x|, added here against the
    correctly rounded exact weights. Those must agree with scipy's to 1e-12, so a wrong exact weight
    fails here instead of widening the tolerance.
    """
    c = signal.savgol_coeffs(window, order, deriv=deriv, delta=1 / rate_hz, pos=pos, use="dot")
    gap = np.sum(np.abs(c - savgol_coeffs(window, order, deriv, pos=pos, rate_hz=rate_hz)))
    assert gap <= 1e-12 * np.sum(np.abs(c))
    return float((4 * window * np.finfo(np.float64).eps * np.sum(np.abs(c)) + gap) * np.max(np.abs(x)))


def assert_oracle(y: np.ndarray, ref: np.ndarray, atol: float) -> None:
    assert_allclose(y, ref, rtol=1e-12, atol=atol)


def feed(block, chunks_by_port, spec_by_port):
    """Bind ``block`` and step it with explicit lists of chunks per port (zipped; short lists pad empty)."""
    block.bind(spec_by_port)
    outs = []
    n = max(len(v) for v in chunks_by_port.values())
    for i in range(n):
        kw = {p: (cs[i] if i < len(cs) else Chunk.empty(spec_by_port[p])) for p, cs in chunks_by_port.items()}
        outs.append(block(**kw))
    outs.append(block.flush())
    port = next(iter(block.outputs))
    return concat([o[port] for o in outs if port in o], block.output_specs[port])


def split(t, x, sizes):
    out, i = [], 0
    for s in sizes:
        out.append(Chunk(t[i : i + s], x[i : i + s]))
        i += s
    return out


# -- coefficients ----------------------------------------------------------------------------------


def test_window5_order4_is_exact_interpolation():
    assert_array_equal(savgol_coeffs(5, 4, 0), [0.0, 0.0, 1.0, 0.0, 0.0])
    assert_allclose(savgol_coeffs(5, 4, 1) * 12, [1, -8, 0, 8, -1], rtol=1e-15)
    assert_allclose(savgol_coeffs(5, 4, 2) * 12, [-1, 16, -30, 16, -1], rtol=1e-15)
    assert_allclose(savgol_coeffs(5, 4, 1, pos=4) * 12, [3, -16, 36, -48, 25], rtol=1e-15)
    assert_allclose(savgol_coeffs(5, 4, 2, pos=4) * 12, [11, -56, 114, -104, 35], rtol=1e-15)
    # physical units: per second at 1 kHz (NUMERICS §1.2 noise gains ‖c‖₂ × dt^d)
    gains = [
        np.linalg.norm(savgol_coeffs(5, 4, d, pos=p, rate_hz=RATE)) / RATE**d
        for d, p in ((1, None), (2, None), (1, 4), (2, 4))
    ]
    assert_allclose(gains, [0.950, 3.134, 5.584, 14.02], rtol=2e-3)


@pytest.mark.parametrize(
    ("window", "order", "pos"), [(5, 4, 2), (7, 3, 6), (21, 9, 20), (51, 9, 50), (51, 10, 0)]
)
def test_exact_coeffs_differentiate_polynomials_exactly(window, order, pos):
    z = [Fraction(k - pos) for k in range(window)]
    for d in range(order + 1):
        c = _exact_coeffs(window, order, d, pos)
        for j in range(order + 1):  # Σ c_k z_k^j = d-th derivative of z^j at 0 = d!·[j == d]
            assert sum(ck * zk**j for ck, zk in zip(c, z, strict=True)) == factorial(d) * (j == d)


@pytest.mark.oracle
@pytest.mark.parametrize(("window", "order"), [(5, 2), (5, 4), (7, 3), (11, 2), (21, 4)])
@pytest.mark.parametrize("pos", [None, 0, "last"])
def test_coeffs_match_scipy(window, order, pos):
    pos = window - 1 if pos == "last" else pos
    for d in range(order + 1):
        ours = savgol_coeffs(window, order, d, pos=pos, rate_hz=250.0)
        ref = signal.savgol_coeffs(window, order, deriv=d, delta=1 / 250.0, pos=pos, use="dot")
        assert_allclose(ours, ref, rtol=1e-9, atol=1e-9 * np.max(np.abs(ref)))  # scipy: float lstsq


def test_deriv_units():
    assert deriv_units("N", 0) == "N"
    assert deriv_units("N", 1) == "N/s"
    assert deriv_units("N", 2) == "N/s^2"
    assert deriv_units(deriv_units("N", 1), 1) == "N/s^2"
    assert deriv_units("N/s^2", 1) == "N/s^3"
    assert deriv_units("1", 1) == "1/s"


# -- the streaming block against the scipy oracle ----------------------------------------------------

# scipy's own coefficients (float lstsq) carry relative errors up to ~1e-11 at the window's end for
# windows >= 15 with order >= 3 (e.g. 21/3 F': 8.5e-12 against an exact long-double reference), beyond
# the 1e-12 that oracle_atol accepts; those combos are checked against an exact reference below.
COMBOS = [
    (5, 4, 0),
    (5, 4, 1),
    (5, 4, 2),
    (5, 2, 1),
    (9, 4, 2),
    (11, 2, 1),
    (11, 3, 2),
    (21, 2, 1),
    (21, 2, 2),
]


@pytest.mark.oracle
@pytest.mark.parametrize(("window", "order", "deriv"), COMBOS)
def test_causal_matches_lfilter(window, order, deriv):
    x = random_walk(20_000)
    out = run_offline(SavGol(window=window, order=order, deriv=deriv, mode="causal"), x=x, chunk=[1, 997, 13])
    c = signal.savgol_coeffs(window, order, deriv=deriv, delta=1 / RATE, pos=window - 1, use="conv")
    assert_oracle(
        out["y"].data, signal.lfilter(c, [1.0], x), oracle_atol(x, window, order, deriv, pos=window - 1)
    )
    assert_array_equal(out["y"].t, np.arange(20_000) / RATE)  # latency 0: stamped like the input


@pytest.mark.oracle
@pytest.mark.parametrize(("window", "order", "deriv"), COMBOS)
def test_centred_matches_savgol_filter_with_zero_padding(window, order, deriv):
    x = random_walk(20_000, channels=2, seed=1)
    out = run_offline(SavGol(window=window, order=order, deriv=deriv, mode="centred"), x=x, chunk=[333, 1, 2])
    ref = signal.savgol_filter(
        x, window, order, deriv=deriv, delta=1 / RATE, axis=0, mode="constant", cval=0.0
    )
    assert out["y"].data.shape == x.shape
    atol = oracle_atol(x, window, order, deriv)
    assert_oracle(out["y"].data, ref, atol)  # every sample, edges (zero-padding transients) included
    assert_array_equal(out["y"].t, np.arange(20_000) / RATE)  # each estimate stamped with its own sample


@pytest.mark.parametrize(("window", "order", "deriv"), [(15, 4, 2), (21, 3, 1), (21, 4, 2), (51, 6, 3)])
def test_causal_matches_exact_long_double_reference(window, order, deriv):
    """Large windows: exact rational coefficients and a long-double convolution as the reference."""
    x = random_walk(20_000, seed=7)
    exact = _exact_coeffs(window, order, deriv, window - 1)
    c = np.array([np.longdouble(q.numerator) / np.longdouble(q.denominator) for q in exact])
    ref = np.convolve(x.astype(np.longdouble), c[::-1] * np.longdouble(RATE) ** deriv)[: len(x)]
    out = run_offline(SavGol(window=window, order=order, deriv=deriv, mode="causal"), x=x, chunk=100)
    err = np.max(np.abs(out["y"].data - ref)) / np.max(np.abs(ref))
    assert err < 1e-13


@pytest.mark.oracle
def test_other_rate_scales_derivatives_per_second():
    x = random_walk(5000)
    out = run_offline(SavGol(deriv=2, mode="centred"), x=x, rate_hz=250.0)
    ref = signal.savgol_filter(x, 5, 4, deriv=2, delta=1 / 250.0, mode="constant", cval=0.0)
    assert_oracle(out["y"].data, ref, oracle_atol(x, 5, 4, 2, rate_hz=250.0))


def test_ramp_and_parabola_derivatives_in_physical_units():
    t = np.arange(200) / RATE
    x = 3.0 * t + 0.5 * 40.0 * t**2  # F' = 3 + 40 t N/s, F'' = 40 N/s²
    for mode in ("causal", "centred"):
        d1 = run_offline(SavGol(deriv=1, mode=mode), x=x)["y"].data
        d2 = run_offline(SavGol(deriv=2, mode=mode), x=x)["y"].data
        sl = slice(5, -5)
        assert_allclose(d1[sl], 3.0 + 40.0 * t[sl], rtol=1e-8)
        assert_allclose(d2[sl], 40.0, rtol=1e-5)


def test_centred_latency_shows_in_timestamps():
    block = SavGol(window=7, order=2, deriv=1, mode="centred")
    assert block.latency_samples == 3
    assert SavGol(mode="causal").latency_samples == 0
    block.bind({"x": StreamSpec(units="N", rate_hz=RATE)})
    x = random_walk(10)
    t = np.arange(10) / RATE
    emitted = []
    for i in range(10):
        y = block(x=Chunk(t[i : i + 1], x[i : i + 1]))["y"]
        emitted.append(y.t.tolist())
    assert emitted[:3] == [[], [], []]  # the first (N-1)/2 arrivals emit nothing
    assert emitted[3:] == [[t[i - 3]] for i in range(3, 10)]  # sample n emits the estimate for n-3
    tail = block.flush()["y"]
    assert_array_equal(tail.t, t[7:])  # the last (N-1)/2 estimates, zero padded


def test_centred_stream_shorter_than_half_window():
    x = np.array([2.0, 5.0])
    out = run_offline(SavGol(window=9, order=2, deriv=0, mode="centred"), x=x)["y"]
    c = savgol_coeffs(9, 2, 0)
    assert_array_equal(out.t, [0.0, 1 / RATE])
    assert_allclose(out.data, [c[4] * 2 + c[5] * 5, c[3] * 2 + c[4] * 5], rtol=1e-14)


def test_numba_kernel_equals_numpy_twin_bit_for_bit():
    rng = np.random.default_rng(5)
    for window, channels in ((5, 1), (11, 3), (21, 2)):
        coef = rng.normal(size=window)
        tail_a = rng.normal(size=(window - 1, channels))
        tail_b = tail_a.copy()
        for n in (0, 1, 3, 500):
            x = rng.normal(size=(n, channels))
            assert_array_equal(savgol_apply(coef, tail_a, x), savgol_apply_numpy(coef, tail_b, x))
            assert_array_equal(tail_a, tail_b)


@pytest.mark.parametrize("mode", ["causal", "centred"])
def test_chunking_invariance_with_irregular_and_empty_chunks(mode):
    x = random_walk(3000, channels=3, seed=2)
    block = SavGol(window=11, order=3, deriv=1, mode=mode)
    whole = run_offline(block, x=x)
    rng = np.random.default_rng(0)
    sizes = [int(s) for s in rng.integers(0, 40, 300)]
    sizes[0] = 0
    spec = {"x": StreamSpec(shape=(3,), units="N", rate_hz=RATE)}
    t = np.arange(3000) / RATE
    chunks = split(t, x, [*sizes, 3000])
    out = feed(SavGol(window=11, order=3, deriv=1, mode=mode), {"x": chunks}, spec)
    assert_same({"y": out}, whole, mode)


def test_specs_units_labels_and_rate():
    spec = StreamSpec(shape=(3,), units="N", rate_hz=RATE, labels=("Fx", "Fy", "Fz"))
    for d, units in ((0, "N"), (1, "N/s"), (2, "N/s^2")):
        y = SavGol(deriv=d).bind({"x": spec})["y"]
        assert (y.units, y.shape, y.rate_hz, y.labels) == (units, (3,), RATE, spec.labels)
    SavGol(rate_hz=1000.0).bind({"x": spec})
    with pytest.raises(SpecError, match=r"expects 250 Hz \(rate_hz\) but the input stream is 1000 Hz") as e:
        SavGol(rate_hz=250.0).bind({"x": spec})
    assert e.value.port == "x"
    for bad in (spec.with_(shape=(3, 2)), spec.with_(dtype="float32"), spec.with_(events=True, rate_hz=None)):
        with pytest.raises(SpecError):
            SavGol().bind({"x": bad})


def test_config_rules():
    with pytest.raises(ConfigError, match="'order' must be < window"):
        SavGol(window=5, order=5)
    with pytest.raises(ConfigError, match="'deriv' must be <= order"):
        SavGol(window=7, order=2, deriv=3)
    with pytest.raises(ConfigError, match="'window' must be odd"):
        SavGol(window=6)
    assert SavGol(preset="touch.rager", mode="causal").config.mode == "causal"  # real-time variant allowed
    assert SavGol(preset="touch.rager", window=7, order=2).config.window == 7  # given values override
    rager = SavGol(preset="touch.rager", deriv=2).config
    assert (rager.window, rager.order, rager.mode, rager.deriv) == (5, 4, "centred", 2)
    default = SavGol().config
    assert (default.window, default.order, default.mode, default.deriv) == (5, 4, "centred", 1)


@pytest.mark.parametrize("mode", ["causal", "centred"])
def test_bad_data_policies(mode):
    x = random_walk(200, channels=2, seed=3)
    bad = x.copy()
    bad[[20, 21, 150], 1] = [np.nan, np.inf, np.nan]
    with pytest.raises(BadDataError, match=r"2 non-finite sample.* input 'x', first at t=0.020000 s"):
        run_offline(SavGol(mode=mode), x=bad, chunk=50)

    block = SavGol(mode=mode, on_bad_data="drop")
    out = run_offline(block, x=bad, chunk=50)["y"]
    keep = np.ones(200, bool)
    keep[[20, 21, 150]] = False
    ref = run_offline(SavGol(mode=mode), x=x[keep], t=np.arange(200)[keep] / RATE)["y"]
    assert_array_equal(out.t, np.arange(200)[keep] / RATE)
    assert_array_equal(out.data, ref.data)
    assert block.counters == {"nonfinite_drop": 3, "sample_gaps": 2}  # the filter bridged two gaps

    block = SavGol(mode=mode, on_bad_data="hold")
    out = run_offline(block, x=bad, chunk=50)["y"]
    held = x.copy()
    held[[20, 21], 1] = x[19, 1]
    held[150, 1] = x[149, 1]
    assert_array_equal(out.data, run_offline(SavGol(mode=mode), x=held)["y"].data)
    assert block.counters == {"nonfinite_hold": 3}


def test_noise_gain_causal_versus_centred():
    """Causal 5/4 F' costs ×5.9 the noise of the centred one (NUMERICS §1.2)."""
    noise = np.random.default_rng(9).normal(0.0, 0.01, 200_000)
    rms = {m: np.std(run_offline(SavGol(mode=m), x=noise)["y"].data[10:-10]) for m in ("causal", "centred")}
    assert_allclose(rms["centred"], 9.50, rtol=0.02)
    assert_allclose(rms["causal"], 55.8, rtol=0.02)


# -- weighted_sum -------------------------------------------------------------------------------------

N_SPEC = StreamSpec(shape=(3,), units="N", rate_hz=RATE)
D1_SPEC = N_SPEC.with_(units="N/s")
D2_SPEC = N_SPEC.with_(units="N/s^2")


def test_weighted_sum_explicit_weights():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(300, 2)), rng.normal(size=300)
    out = run_offline(WeightedSum(w1=[2.0, -1.0], w2=[0.5], bias=0.25, units="uA"), x1=a, x2=b, chunk=7)
    assert_allclose(out["y"].data, 0.25 + 2 * a[:, 0] - a[:, 1] + 0.5 * b, rtol=1e-14)
    assert out["y"].data.shape == (300,)
    block = WeightedSum(w1=[1.0, 1.0], units="uA")
    assert block.bind({"x1": StreamSpec(shape=(2,), rate_hz=RATE)})["y"] == StreamSpec(
        shape=(), units="uA", rate_hz=RATE
    )


@pytest.mark.parametrize("population", ["SA1", "FA1"])
def test_weighted_sum_table_i_preset(population):
    rng = np.random.default_rng(1)
    f, df, ddf = rng.normal(size=(3, 100, 3))
    units = {"x1": "N", "x2": "N/s", "x3": "N/s^2"}
    ddf[5] = np.nan  # x3 has zero weights: it is not needed, so not even read
    out = run_offline(WeightedSum(preset=f"touch.{population}"), x1=f, x2=df, x3=ddf, units=units, chunk=9)
    w1, w2, _ = table_i_weights(population)
    assert_allclose(out["y"].data, f @ np.array(w1) + df @ np.array(w2), rtol=1e-12)


def test_weighted_sum_needs_prunes_zero_weights():
    all4 = frozenset({"x1", "x2", "x3", "x4"})
    assert WeightedSum(preset="touch.SA1").needs(frozenset({"x1", "x2", "x3"})) == {"x1", "x2"}
    assert WeightedSum(w1=[1.0], w2=[0.0, 0.0], w3=[0.0, 1e-9]).needs(all4) == {"x1", "x3"}
    assert WeightedSum(w1=[0.0]).needs(frozenset({"x1"})) == {"x1"}  # x1 is the clock: always needed


def test_weighted_sum_preset_checks_units_and_wiring():
    ws = WeightedSum(preset="touch.SA1")
    ws.bind({"x1": N_SPEC, "x2": D1_SPEC, "x3": D2_SPEC})
    cases = [
        ({"x1": N_SPEC.with_(units="mN"), "x2": D1_SPEC}, "x1", "'x1' must be in 'N' .* but gets 'mN'"),
        ({"x1": N_SPEC.with_(units="N/s"), "x2": D1_SPEC}, "x1", "but gets 'N/s'"),
        ({"x1": N_SPEC, "x2": N_SPEC}, "x2", "'x2' must be in 'N/s' \\(expect_units"),
        ({"x1": N_SPEC, "x2": D1_SPEC, "x3": N_SPEC}, "x3", "must be in 'N/s\\^2'"),
        ({"x1": N_SPEC}, "x2", "w2 gives non-zero weights to 'x2' but 'x2' is not connected"),
        ({"x1": N_SPEC, "x2": D1_SPEC, "x4": N_SPEC}, "x4", "connected but has no weights"),
        ({"x1": N_SPEC.with_(shape=(2,)), "x2": D1_SPEC}, "x1", "has 3 weights but input 'x1' has 2"),
        ({"x1": N_SPEC, "x2": D1_SPEC.with_(rate_hz=500.0)}, "x2", "500 Hz but x1 is 1000 Hz"),
    ]
    for specs, port, msg in cases:
        with pytest.raises(SpecError, match=msg) as e:
            WeightedSum(preset="touch.SA1").bind(specs)
        assert e.value.port == port


def test_weighted_sum_config_rules():
    assert WeightedSum(preset="touch.FA1", w2=[1.0, 1.0, 1.0]).config.w2 == (1.0, 1.0, 1.0)  # given wins
    assert WeightedSum(preset="touch.FA1").config.w1 == table_i_weights("FA1")[0]
    with pytest.raises(ConfigError, match="'w1' is required"):
        WeightedSum()
    with pytest.raises(ConfigError, match="'w1'"):
        WeightedSum(w1=[])


def test_weighted_sum_aligns_inputs_with_different_delays():
    """A centred derivative arrives (N-1)/2 samples after the force: pair samples by timestamp."""
    f = random_walk(1000, channels=3, seed=4)
    t = np.arange(1000) / RATE
    d1 = run_offline(SavGol(deriv=1, mode="centred"), x=f, units={"x": "N"})["y"]
    whole = run_offline(WeightedSum(preset="touch.FA1"), x1=f, x2=d1.data, units={"x1": "N", "x2": "N/s"})[
        "y"
    ]
    w1, w2, _ = table_i_weights("FA1")
    assert_allclose(whole.data, f @ np.array(w1) + d1.data @ np.array(w2), rtol=1e-12, atol=1e-14)
    rng = np.random.default_rng(3)
    for _ in range(3):  # independent, irregular chunkings per input; x2 runs 2 samples late
        s1 = [int(v) for v in rng.integers(0, 30, 80)] + [1000]
        s2 = [0, 0] + [int(v) for v in rng.integers(0, 30, 90)] + [1000]
        chunks = {"x1": split(t, f, s1), "x2": split(d1.t, d1.data, s2)}
        out = feed(WeightedSum(preset="touch.FA1"), chunks, {"x1": N_SPEC, "x2": D1_SPEC})
        assert_array_equal(out.t, t)
        assert_array_equal(out.data, whole.data)  # bit for bit


def test_weighted_sum_end_to_end_with_streaming_savgol():
    """force -> savgol(centred) -> weighted_sum, chunk by chunk, equals the offline computation."""
    f = random_walk(500, channels=3, seed=6)
    t = np.arange(500) / RATE
    sg, ws = SavGol(deriv=1, mode="centred"), WeightedSum(preset="touch.SA1")
    sg.bind({"x": N_SPEC})
    ws.bind({"x1": N_SPEC, "x2": D1_SPEC})
    ys = []
    for i in range(0, 500, 37):
        c = Chunk(t[i : i + 37], f[i : i + 37])
        ys.append(ws(x1=c, x2=sg(x=c)["y"])["y"])
    ys.append(ws(x1=Chunk.empty(N_SPEC), x2=sg.flush()["y"])["y"])
    y = concat(ys)
    d1 = signal.savgol_filter(f, 5, 4, deriv=1, delta=1 / RATE, axis=0, mode="constant", cval=0.0)
    w1, w2, _ = table_i_weights("SA1")
    assert_array_equal(y.t, t)
    assert_allclose(y.data, f @ np.array(w1) + d1 @ np.array(w2), rtol=1e-9, atol=1e-12)


def test_weighted_sum_rejects_misaligned_streams():
    t = np.arange(10) / RATE
    ws = WeightedSum(w1=[1.0], w2=[1.0])
    ws.bind({"x1": StreamSpec(rate_hz=RATE), "x2": StreamSpec(rate_hz=RATE)})
    ws(x1=Chunk(t, np.zeros(10)), x2=Chunk(t, np.zeros(10)))
    with pytest.raises(MisalignedError, match="'x1' and 'x2' are not sample-aligned"):
        ws(x1=Chunk(t + 0.01, np.zeros(10)), x2=Chunk(t + 0.0105, np.zeros(10)))


def test_weighted_sum_unpaired_samples_counted_at_end():
    t = np.arange(10) / RATE
    ws = WeightedSum(w1=[1.0], w2=[1.0])
    ws.bind({"x1": StreamSpec(rate_hz=RATE), "x2": StreamSpec(rate_hz=RATE)})
    y = ws(x1=Chunk(t, np.ones(10)), x2=Chunk(t[:6], np.ones(6)))["y"]
    assert_array_equal(y.t, t[:6])
    assert ws.flush() == {}
    assert ws.counters == {"unpaired_at_end": 4}


def test_weighted_sum_bad_data():
    a, b = np.ones((20, 1)), np.full(20, 2.0)
    a[3, 0] = np.nan
    b[7] = np.inf
    with pytest.raises(BadDataError, match="input 'x1'"):
        run_offline(WeightedSum(w1=[1.0], w2=[1.0]), x1=a, x2=b)
    block = WeightedSum(w1=[1.0], w2=[1.0], on_bad_data="drop")
    out = run_offline(block, x1=a, x2=b, chunk=4)["y"]
    assert_array_equal(out.t, np.delete(np.arange(20), [3, 7]) / RATE)  # the instant, on every input
    assert_array_equal(out.data, 3.0)
    assert block.counters == {"nonfinite_drop": 2}
    out = run_offline(WeightedSum(w1=[1.0], w2=[1.0], on_bad_data="hold"), x1=a, x2=b, chunk=4)["y"]
    assert_array_equal(out.data, 3.0)
    assert len(out) == 20


# -- delay --------------------------------------------------------------------------------------------


def test_delay_passes_samples_through_unchanged():
    assert Delay.inputs["x"].delay
    x = np.random.default_rng(0).normal(size=(50, 2))
    out = run_offline(Delay(), x=x, chunk=[1, 7, 20])["y"]
    assert_array_equal(out.data, x)
    assert_array_equal(out.t, np.arange(50) / RATE)
    spec = StreamSpec(dtype="int64", shape=(2,), units="uA", rate_hz=40.0, labels=("a", "b"))
    d = Delay()
    assert d.bind({"x": spec}) == {"y": spec}
    assert len(d()["y"]) == 0  # nothing arrived: an empty chunk of the right shape
    assert d()["y"].data.shape == (0, 2)


def test_docstring_examples_run():
    import flowtact.blocks.signal.savgol as module

    result = doctest.testmod(module, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted >= 3
    assert result.failed == 0


@pytest.mark.parametrize("mode", ["causal", "centred"])
def test_hold_padding_has_no_edge_transient_on_a_loaded_sensor(mode):
    """A force sitting at 0.12 N from t = 0: zero padding sees a step, hold padding does not."""
    x = np.full((50, 3), 0.12) + np.linspace(0, 0.01, 50)[:, None]  # 0.2 N/s ramp
    held = run_offline(SavGol(deriv=1, mode=mode, padding="hold"), x=x, units={"x": "N"})["y"].data
    zero = run_offline(SavGol(deriv=1, mode=mode), x=x, units={"x": "N"})["y"].data
    assert np.abs(zero[:2]).max() > 10  # the step at t = 0 is a spurious 1e1..1e2 N/s
    assert np.abs(held).max() < 1.0  # no transient: the kink where the ramp starts overshoots to 0.43 at most
    np.testing.assert_allclose(held[5:-5], zero[5:-5], rtol=1e-9)  # the interior is unchanged
