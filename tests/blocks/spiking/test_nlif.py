"""Behaviour of the nlif block and its kernels (oracles against Brian2 / analytic solutions live in
test_nlif_oracles.py)."""

import math

import numpy as np
import pytest

from flowtact import BadDataError, ConfigError, SpecError, StreamSpec
from flowtact.blocks.spiking._lif_kernels import (
    NOISE_EXTERNAL,
    NOISE_FILL,
    NOISE_GROUP,
    NOISE_INTERNAL,
    NOISE_OFF,
    fill_normal,
    fill_normal_py,
    grid_coefficients,
    interp_coefficients,
    lif_grid,
    lif_grid_py,
    lif_interp,
    lif_interp_py,
    seed_state,
    seed_streams,
)
from flowtact.blocks.spiking._spike_history import history_table
from flowtact.blocks.spiking.nlif import Nlif
from flowtact.blocks.spiking.normal_draws import stream_words
from flowtact.blocks.touch.presets import NEURON_PRESETS
from flowtact.chunk import Chunk
from flowtact.testing import assert_same, run_offline

RATE = 1000.0
INTEGRATORS = ["exp", "euler", "exp_interp"]


def drive(n_t=1500, rate=RATE, n=None, seed=0):
    """A varied drive (0.8 … 2.4) shared by all neurons, or per neuron when ``n`` is given."""
    t = np.arange(n_t) / rate
    u = 1.5 + np.sin(2 * np.pi * 5 * t) + 0.3 * np.sin(2 * np.pi * 23 * t)
    if n is None:
        return u
    gains = np.random.default_rng(seed).uniform(0.7, 1.3, n)
    return u[:, None] * gains[None, :]


def spikes_of(out):
    return out["spikes"].t, out["spikes"].data


# -- configuration ----------------------------------------------------------------------------


def test_preset_values_come_from_afferents_and_explicit_params_override():
    blk = Nlif(n=4, preset="touch.SA1")
    p = blk.config.resolved()
    assert p["tau_s"].tolist() == [NEURON_PRESETS["SA1"]["tau_s"]] * 4
    assert p["refractory_s"] == NEURON_PRESETS["SA1"]["refractory_s"]
    assert p["h_weights"] == tuple(NEURON_PRESETS["SA1"]["h_weights"])
    p2 = Nlif(n=4, preset="touch.SA1", tau_s=0.02, h_weights=[]).config.resolved()
    assert p2["tau_s"].tolist() == [0.02] * 4
    assert p2["h_weights"] == ()
    assert p2["v_leak"].tolist() == [NEURON_PRESETS["SA1"]["v_leak"]] * 4  # the rest still from the preset
    base = Nlif(n=2).config.resolved()
    assert base["integrator"] == "exp" and base["sigma"].tolist() == [0.0, 0.0]


def test_per_neuron_params_broadcast_or_must_have_length_n():
    p = Nlif(n=3, gain=[0.5, 1.0, 2.0], tau_s=0.02).config.resolved()
    assert p["gain"].tolist() == [0.5, 1.0, 2.0]
    assert p["tau_s"].tolist() == [0.02] * 3
    with pytest.raises(ConfigError, match=r"gain.*1 or n = 3"):
        Nlif(n=3, gain=[1.0, 2.0])


@pytest.mark.parametrize(
    ("params", "field"),
    [
        ({"tau_s": 0.0}, "tau_s"),
        ({"tau_s": -0.01}, "tau_s"),
        ({"tau_s": [0.01, 0.0]}, "tau_s"),
        ({"sigma": -1.0}, "sigma"),
        ({"refractory_s": -0.001}, "refractory_s"),
        ({"h_weights": [0.1]}, "h_weights"),
        ({"h_weights": [0.1, 0.2], "h_peaks_s": [0.05, 0.01]}, "h_peaks_s"),
        ({"integrator": "rk4"}, "integrator"),
    ],
)
def test_invalid_config_names_the_field(params, field):
    n = 2 if isinstance(params.get("tau_s"), list) else 1
    with pytest.raises(ConfigError) as e:
        Nlif(n=n, node="aff", **params)
    assert e.value.field == field
    assert "aff" in str(e.value)


def test_specs_reject_bad_inputs():
    blk = Nlif(n=3)
    good = StreamSpec(shape=(), units="1", rate_hz=1000.0)
    out = blk.specs({"x": good})
    assert out["spikes"].events and out["spikes"].n_units == 3
    assert out["v"].shape == (3,) and out["v"].rate_hz == 1000.0
    assert blk.specs({"x": good.with_(shape=(3,))})["v"].shape == (3,)
    for bad, words in [
        (good.with_(units="N"), "units"),
        (good.with_(shape=(4,)), "shape"),
        (good.with_(rate_hz=None), "rate"),
        (good.with_(dtype="int64"), "float64"),
        (StreamSpec(dtype="int64", events=True, n_units=3), "sample stream"),
    ]:
        with pytest.raises(SpecError, match=words) as e:
            blk.bind({"x": bad})  # the declared port and the block's own rules, on every path
        assert e.value.port == "x"
    with pytest.raises(SpecError, match="euler is unstable"):
        Nlif(integrator="euler", tau_s=0.0004).specs({"x": good})
    Nlif(integrator="exp", tau_s=1e-9).specs({"x": good})  # exp is fine for any tau


# -- numba kernels equal their numpy twins -------------------------------------------------------


def _coef(method, n, rng, dt, sigma):
    tau = rng.uniform(0.005, 0.02, n)
    sig = np.full(n, sigma)
    vl = rng.uniform(-0.2, 0.3, n)
    g = rng.uniform(0.6, 1.4, n)
    if method == "exp_interp":
        return np.ascontiguousarray(np.vstack([interp_coefficients(tau, sig, dt), vl, g]))
    return np.ascontiguousarray(np.vstack([grid_coefficients(method, tau, sig, dt), vl, g]))


def _call(impl, args, v_out, n_work, tile):
    """``impl(*args, …)``, its spikes as the twins return them: the numpy twins take no scratch
    rows, tile size or spike buffers (short ones here, so that the kernels must grow them)."""
    if impl in (lif_grid_py, lif_interp_py):
        return impl(*args, v_out)
    bufs = [np.empty(3, np.int64), np.empty(5), np.empty(4, np.int64)]
    if impl is lif_grid:
        del bufs[1]
    n = v_out.shape[1]
    *spikes, n, pos = impl(*args, np.zeros((n_work, n)), np.zeros(max(NOISE_FILL, n)), v_out, tile, *bufs)
    return (*(a[:n] for a in spikes), pos)


def _run_kernel(method, impl, n, u, noise, h, ref_s, chunks, tile, xi=None, seed=0):
    """Run kernel ``impl`` over ``u`` in the given chunk sizes; return spikes, v and final state."""
    rng = np.random.default_rng(seed)
    dt = 1e-3
    coef = _coef(method, n, rng, dt, 0.8 if noise else 0.0)
    h_tab = history_table((-0.4, -0.2, 0.1, -0.05), (0.002, 0.03), 0.004, dt) if h else np.zeros(1)
    ring = np.zeros((n, len(h_tab) - 1 if h else 0))
    state = seed_streams(np.random.default_rng(seed + 1), n)
    v = np.zeros(n)
    refc = np.zeros(n, np.int64)
    rl = np.zeros(n)
    pos = 0
    n_clamp = max(0, math.ceil(ref_s / dt - 1e-9) - 1)
    mode = NOISE_OFF if not noise else (NOISE_EXTERNAL if xi is not None else NOISE_INTERNAL)
    steps, idx, offs, vs = [], [], [], []
    start = 0
    u_first = u[0]
    body = u[1:] if method == "exp_interp" else u
    for size in chunks:
        uc = np.ascontiguousarray(body[start : start + size])
        xic = np.ascontiguousarray(xi[start : start + size]) if xi is not None else np.zeros((0, n))
        v_out = np.empty((len(uc), n))
        if method == "exp_interp":
            args = (u_first, uc, dt, coef, v, rl, ref_s, ring, pos, h_tab, mode, state, xic)
            s, o, k, pos = _call(impl, args, v_out, 3, tile)
            offs.append(np.asarray(o) + 0.0)
            if len(uc):
                u_first = uc[-1]
        else:
            args = (uc, coef, v, refc, n_clamp, ring, pos, h_tab, mode, state, xic)
            s, k, pos = _call(impl, args, v_out, 2, tile)
        steps.append(np.asarray(s) + start)
        idx.append(np.asarray(k))
        vs.append(v_out)
        start += size
    return {
        "steps": np.concatenate(steps),
        "idx": np.concatenate(idx),
        "offs": np.concatenate(offs) if offs else None,
        "v": np.concatenate(vs),
        "state": (v.copy(), refc.copy(), rl.copy(), ring.copy(), *(stream_words(row) for row in state)),
    }


def _split(total, sizes):
    out, done = [], 0
    i = 0
    while done < total:
        k = min(sizes[i % len(sizes)], total - done)
        out.append(k)
        done += k
        i += 1
    return out


@pytest.mark.parametrize("method", INTEGRATORS)
@pytest.mark.parametrize("n", [1, 3, 12, 20])
@pytest.mark.parametrize(
    ("noise", "h", "ref_s"),
    [(False, False, 0.0), (True, False, 0.0), (True, True, 0.0035), (False, True, 0.002), (True, True, 0.0),
     (False, True, 0.0)],
)  # fmt: skip
def test_kernel_equals_numpy_twin(method, n, noise, h, ref_s):
    """Every variant of the update loop (drive computed in it or read from a row, noise, refractory
    counts, post-spike current), neuron-major (n ≤ 8) and tiled, shared (n = 12) and per-neuron
    (n = 20) drive."""
    n_t = 400
    u = drive(n_t, n=n) if n == 20 else drive(n_t)[:, None]
    total = n_t - 1 if method == "exp_interp" else n_t
    chunks = _split(total, [400])
    impl = lif_interp if method == "exp_interp" else lif_grid
    twin = lif_interp_py if method == "exp_interp" else lif_grid_py
    fast = _run_kernel(method, impl, n, u, noise, h, ref_s, chunks, tile=7)
    ref = _run_kernel(method, twin, n, u, noise, h, ref_s, chunks, tile=0)
    assert len(fast["steps"]) >= 5
    np.testing.assert_array_equal(fast["steps"], ref["steps"])
    np.testing.assert_array_equal(fast["idx"], ref["idx"])
    np.testing.assert_array_equal(fast["v"], ref["v"])
    if method == "exp_interp":
        np.testing.assert_array_equal(fast["offs"], ref["offs"])
    for a, b in zip(fast["state"], ref["state"], strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("method", INTEGRATORS)
@pytest.mark.parametrize("n", [2, 30])
def test_kernel_tiling_and_chunking_do_not_change_results(method, n):
    """Neuron tiles (time-blocked, re-sorted) and chunk boundaries give bit-identical output."""
    n_t = 600
    u = drive(n_t, n=n)
    total = n_t - 1 if method == "exp_interp" else n_t
    impl = lif_interp if method == "exp_interp" else lif_grid
    whole = _run_kernel(method, impl, n, u, False, True, 0.003, [total], tile=0)
    for tile, sizes in [(7, [1]), (4, [13, 250, 1]), (0, [64])]:
        part = _run_kernel(method, impl, n, u, False, True, 0.003, _split(total, sizes), tile=tile)
        for key in ("steps", "idx", "v"):
            np.testing.assert_array_equal(part[key], whole[key], err_msg=f"{key} tile={tile} sizes={sizes}")


@pytest.mark.parametrize("method", INTEGRATORS)
def test_noise_streams_of_large_populations(method):
    """Beyond NOISE_GROUP neurons each group draws its own stream: the kernel (tiled by groups)
    equals the twin, whatever the chunking, and the groups' noise is not the same numbers."""
    n, n_t = NOISE_GROUP + 37, 24
    u = drive(n_t)[:, None]
    total = n_t - 1 if method == "exp_interp" else n_t
    impl = lif_interp if method == "exp_interp" else lif_grid
    twin = lif_interp_py if method == "exp_interp" else lif_grid_py
    ref = _run_kernel(method, twin, n, u, True, False, 0.0, [total], tile=0)
    for sizes in ([total], [1, 5, 9]):
        fast = _run_kernel(method, impl, n, u, True, False, 0.0, _split(total, sizes), tile=0)
        for key in ("steps", "idx", "v"):
            np.testing.assert_array_equal(fast[key], ref[key], err_msg=f"{key} sizes={sizes}")
        for a, b in zip(fast["state"], ref["state"], strict=True):
            np.testing.assert_array_equal(a, b)
    assert len(ref["state"]) == 4 + 2  # two streams


def test_noise_groups_are_independent_streams():
    """Identical neurons in two noise groups do not share their noise (each group is seeded apart)."""
    blk = Nlif(n=NOISE_GROUP + 4, sigma=1.0)
    blk.bind({"x": StreamSpec(rate_hz=RATE)}, seed=2, demanded=frozenset({"v"}))
    t = np.arange(50) / RATE
    v = blk(x=Chunk(t, np.full(50, 0.5)))["v"].data
    assert np.all(v[1:, :4] != v[1:, NOISE_GROUP:])
    assert np.all(v[1:, :4] != v[1:, 4:8])


def test_external_noise_equals_internal_stream():
    """Noise mode 'external' with the normals the internal generator would draw gives the same run."""
    n, n_t = 5, 300
    u = drive(n_t)[:, None]
    xi = np.empty((n_t, n))
    st = seed_state(np.random.default_rng(1))  # _run_kernel seeds the generator with seed + 1
    for i in range(n_t):
        fill_normal(st, xi[i])
    for method in ("exp", "euler"):
        a = _run_kernel(method, lif_grid, n, u, True, False, 0.0, [n_t], tile=0)
        b = _run_kernel(method, lif_grid, n, u, True, False, 0.0, [n_t], tile=0, xi=xi)
        np.testing.assert_array_equal(a["v"], b["v"])


def test_normal_generator_twin():
    """The numba generator and its pure-Python twin give the same bits, whatever the request sizes."""
    st = seed_state(np.random.default_rng(3))
    st2 = st.copy()
    a, b = np.empty(5000), np.empty(5000)
    for lo, hi in ((0, 7), (7, 1500), (1500, 5000)):
        fill_normal(st, a[lo:hi])
    for lo, hi in ((0, 1000), (1000, 5000)):
        fill_normal_py(st2, b[lo:hi])
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(stream_words(st), stream_words(st2))


# -- the block ----------------------------------------------------------------------------------


@pytest.mark.parametrize("method", INTEGRATORS)
@pytest.mark.parametrize("per_neuron", [False, True])
@pytest.mark.parametrize(
    "params", [{}, {"sigma": 0.8, "refractory_s": 0.004, "h_weights": [-0.5, -0.2, -0.1]}]
)
def test_block_chunking_invariance(method, per_neuron, params):
    n = 12
    x = drive(700, n=n if per_neuron else None)
    make = lambda: Nlif(n=n, integrator=method, **params)  # noqa: E731
    whole = run_offline(make(), x=x, seed=4)
    assert len(whole["spikes"]) > 50
    for chunk in (1, 7, [3, 250, 1, 64]):
        assert_same(run_offline(make(), x=x, chunk=chunk, seed=4), whole, f"{method} chunk={chunk}")
    assert_same(run_offline(make(), x=x, chunk=13, empty_between=True, seed=4), whole, "empty chunks")


def test_spikes_sorted_by_time_then_index_and_watermark():
    for method in INTEGRATORS:
        blk = Nlif(n=40, integrator=method, sigma=1.0)
        out = run_offline(blk, x=drive(500), chunk=100)
        t, k = spikes_of(out)
        order = np.lexsort((k, t))
        np.testing.assert_array_equal(order, np.arange(len(t)))
        assert out["spikes"].end == pytest.approx(0.5)
        assert out["spikes"].data.dtype == np.int64 and out["spikes"].t.dtype == np.float64
        assert out["v"].data.shape == (500, 40) and out["v"].data.dtype == np.float64


def test_grid_spikes_are_stamped_at_step_start_and_v_is_the_start_state():
    blk = Nlif(n=1, tau_s=1e-9)  # v jumps to the drive in one step
    x = np.zeros(10)
    x[3] = 5.0  # fires in step 3
    out = run_offline(blk, x=x)
    assert out["spikes"].t.tolist() == [0.003]
    assert out["v"].data[:, 0].tolist() == [0.0] * 10  # reset in the same step; v(t_i) before sample i
    x[3] = 0.7
    out = run_offline(Nlif(n=1, tau_s=1e-9), x=x)
    assert out["v"].data[4, 0] == 0.7 and out["v"].data[3, 0] == 0.0


def test_exp_interp_has_one_sample_of_latency_and_flush_finishes():
    x = drive(300)
    blk = Nlif(n=1, integrator="exp_interp")
    ref = run_offline(Nlif(n=1, integrator="exp_interp"), x=x)
    assert len(ref["spikes"]) > 5
    blk.bind({"x": StreamSpec(rate_hz=RATE)})
    from flowtact.chunk import Chunk

    t = np.arange(300) / RATE
    got = []
    for i in range(300):
        out = blk(x=Chunk(t[i : i + 1], x[i : i + 1]))
        st = out["spikes"].t
        # a spike inside step [t_{i-1}, t_i) can only be known once x_i arrived
        assert np.all(st < t[i] + 1e-12)
        got.append(st)
        if i:
            assert out["spikes"].end == pytest.approx(t[i])
    tail = blk.flush()["spikes"].t
    np.testing.assert_array_equal(np.concatenate([*got, tail]), ref["spikes"].t)


def test_refractory_period_caps_the_rate_whatever_the_drive():
    x = np.full(1000, 1e6)
    for method, ref in [("exp", 0.0035), ("euler", 0.0035), ("exp_interp", 0.0035), ("exp", 0.003)]:
        out = run_offline(Nlif(n=2, integrator=method, refractory_s=ref), x=x)
        t = out["spikes"].t[out["spikes"].data == 0]
        isi = np.diff(t)
        assert isi.min() >= ref - 1e-12
        if method != "exp_interp":  # grid: exactly ceil(ref/dt) steps
            np.testing.assert_allclose(isi, math.ceil(ref * 1000 - 1e-9) / 1000, atol=1e-12)
        assert len(t) <= 1.0 / ref + 1
    # without refractoriness a discrete neuron fires at every step (the 1/dt artefact)
    out = run_offline(Nlif(n=1), x=x)
    assert len(out["spikes"]) == 1000


@pytest.mark.parametrize("method", INTEGRATORS)
def test_nan_policy_raise_names_node_and_time(method):
    x = drive(200)
    x[57] = np.nan
    blk = Nlif(n=2, integrator=method, node="sa1")
    with pytest.raises(BadDataError, match=r"sa1.*t=0\.057"):
        run_offline(blk, x=x, chunk=50)


@pytest.mark.parametrize("method", INTEGRATORS)
@pytest.mark.parametrize("policy", ["hold", "drop"])
def test_a_single_bad_sample_does_not_kill_the_neuron(method, policy):
    x = drive(1000)
    for bad in (np.nan, np.inf, -np.inf):
        xb = x.copy()
        xb[100] = bad
        blk = Nlif(n=3, integrator=method, on_bad_data=policy)
        out = run_offline(blk, x=xb, chunk=64)
        assert blk.counters == {f"nonfinite_{policy}": 1}
        assert np.isfinite(out["v"].data).all()
        t = out["spikes"].t
        assert (t > 0.5).sum() > 20  # still firing long after the bad sample
        clean = run_offline(Nlif(n=3, integrator=method), x=x, chunk=64)
        assert abs(len(t) - len(clean["spikes"])) <= 3 * 3
        if policy == "drop":
            assert len(out["v"]) == 999
        else:
            assert len(out["v"]) == 1000


@pytest.mark.parametrize("method", INTEGRATORS)
def test_huge_finite_inputs_keep_the_neuron_working(method):
    x = np.full(3000, 0.5)
    x[100:110] = 1e300
    x[200] = -1e300
    x[201:] = 1.5
    out = run_offline(Nlif(n=1, integrator=method, tau_s=0.01), x=x)
    v = out["v"].data[:, 0]
    assert np.isfinite(v).all()
    t = out["spikes"].t
    assert ((t >= 0.1) & (t < 0.111)).sum() >= 9  # fires at every step of the huge drive
    assert (t > 2.5).sum() > 10  # recovers from the −1e300 kick (clamped drive, τ ln(1e99) ≈ 2.3 s)
    # per-neuron huge values too
    xn = np.tile(drive(500)[:, None], (1, 2))
    xn[50, 1] = 1e308
    out = run_offline(Nlif(n=2, integrator=method, gain=[1.0, 3.0]), x=xn)
    assert np.isfinite(out["v"].data).all()


def test_seeded_noise_is_deterministic_and_seed_dependent():
    x = np.full(800, 0.9)
    a = run_offline(Nlif(n=20, sigma=2.0), x=x, seed=1)
    b = run_offline(Nlif(n=20, sigma=2.0), x=x, seed=1)
    c = run_offline(Nlif(n=20, sigma=2.0), x=x, seed=2)
    assert_same(a, b)
    assert len(a["spikes"]) > 20
    assert not np.array_equal(a["v"].data, c["v"].data)
    # different neurons see different noise
    assert not np.array_equal(a["v"].data[:, 0], a["v"].data[:, 1])


def test_only_demanded_outputs_are_computed():
    blk = Nlif(n=3)
    blk.bind({"x": StreamSpec(rate_hz=RATE)}, demanded=frozenset({"spikes"}))
    from flowtact.chunk import Chunk

    t = np.arange(100) / RATE
    out = blk(x=Chunk(t, drive(100)))
    assert set(out) == {"spikes"}
    blk.bind({"x": StreamSpec(rate_hz=RATE)}, demanded=frozenset({"v"}))
    assert set(blk(x=Chunk(t, drive(100)))) == {"v"}


def test_zero_history_weights_cost_nothing():
    blk = Nlif(n=4, h_weights=[0.0, 0.0, 0.0])
    run_offline(blk, x=drive(50))
    assert blk._ring.shape[1] == 0  # noqa: SLF001 — the ring buffer's size is the cost in question
    blk = Nlif(n=4, h_weights=[-0.1, 0.0, 0.0])
    run_offline(blk, x=drive(50))
    assert blk._ring.shape[1] > 0  # noqa: SLF001 — the ring buffer's size is the cost in question


def test_negative_history_current_adapts_the_rate():
    x = np.full(2000, 1.8)
    plain = run_offline(Nlif(n=1), x=x)["spikes"].t
    adapt = run_offline(Nlif(n=1, h_weights=[-0.6, -0.4, -0.2, -0.1]), x=x)["spikes"].t
    assert plain[0] == adapt[0]  # no history before the first spike
    assert len(adapt) < 0.8 * len(plain)
    first_isi = np.diff(adapt)[0]
    assert np.diff(adapt)[-20:].mean() > first_isi  # intervals lengthen: adaptation


@pytest.mark.parametrize("population", ["SA1", "FA1"])
def test_presets_fire_for_table_i_sized_drives_and_stay_bounded(population):
    """Drive levels of a touch as documented in afferents.py (Table I sums of the touch scenario):
    SA1 0.046 at rest → 0.19 on the plateau; FA1 0.054 → 0.37, transients ≈ 0.9 at onset/offset."""
    t = np.arange(3000) / RATE
    rest, plateau = (0.046, 0.19) if population == "SA1" else (0.054, 0.37)
    x = np.interp(t, [0.5, 0.52, 2.0, 2.02], [rest, plateau, plateau, rest])
    if population == "FA1":  # force-derivative transients of ~10 ms at onset and offset
        x = x + 0.55 * np.exp(-(((t - 0.51) / 0.004) ** 2)) + 0.7 * np.exp(-(((t - 2.01) / 0.004) ** 2))
    out = run_offline(Nlif(n=30, preset=f"touch.{population}"), x=x, seed=1)
    st = out["spikes"].t
    assert (st < 0.5).sum() / 30 / 0.5 < 0.5  # (nearly) quiet before contact
    per_bin = np.histogram(st, bins=np.arange(0, 3.0001, 0.02))[0] / 30 / 0.02
    assert per_bin.max() <= 300.0
    onset = ((st >= 0.5) & (st < 0.56)).sum() / 30 / 0.06
    held = ((st >= 1.0) & (st < 2.0)).sum() / 30 / 1.0
    offset = ((st >= 2.0) & (st < 2.06)).sum() / 30 / 0.06
    if population == "SA1":
        assert held > 20.0  # sustained through the touch
        assert onset > 1.3 * held  # extra activity at onset (post-spike adaptation)
        every_50ms = np.histogram(st, bins=np.arange(0.6, 2.0001, 0.05))[0]
        assert every_50ms.min() > 0
    else:
        assert onset > 10.0 and offset > 10.0  # fires on changes
        assert held < 1.0  # silent on a held touch
