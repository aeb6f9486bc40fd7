"""nlif's per-unit kernel: the last-spike (renewal) and summed histories against a one-step-at-a-time
twin, the threshold block against the membrane clamp, per-unit parameters, ``models:``, the summed
per-unit path against the shared-parameter kernel, and the conformance suite (chunking invariance
included) on a mixed, noisy population."""

import numpy as np
import pytest

from flowtact import ConfigError
from flowtact.block import Example
from flowtact.blocks.spiking._lif_kernels import NOISE_EXTERNAL, NOISE_INTERNAL, NOISE_OFF, seed_streams
from flowtact.blocks.spiking._lif_unit_kernels import lif_units, lif_units_py
from flowtact.blocks.spiking.nlif import Nlif
from flowtact.testing import CHECKS, run_offline

FS = 5000.0


def _kernel_args(n, n_basis=2, seed=0):
    rng = np.random.default_rng(seed)
    coef = np.vstack([
        1 - 1 / rng.uniform(50, 400, n),      # a
        rng.uniform(0.002, 0.02, n),           # b
        rng.uniform(0.0, 0.05, n),             # s
        rng.uniform(-0.5, 0.2, n),             # v_leak
        rng.uniform(50, 400, n),               # gain
    ])  # fmt: skip
    thr = rng.uniform(0.5, 1.5, n)
    w = rng.uniform(-3, 1, (n_basis, n))
    basis = np.zeros((n_basis, 40))
    basis[:, 1:-1] = rng.uniform(0, 1, (n_basis, 38))
    return coef, thr, w, basis


@pytest.mark.parametrize("history", ["last", "sum"])
@pytest.mark.parametrize("noise", [NOISE_OFF, NOISE_EXTERNAL, NOISE_INTERNAL])
@pytest.mark.parametrize("n_clamp", [0, 3])
def test_kernel_matches_its_plain_twin(noise, n_clamp, history):
    """Bit for bit, with the threshold block, the membrane clamp, each history, and each noise
    source (internal noise: two streams, units ≥ 4096 drawing from the second); the run is split
    in two calls (the state, ring slot included, carries over)."""
    n = 4100 if noise == NOISE_INTERNAL else 37
    coef, thr, w, basis = _kernel_args(n)
    u = np.random.default_rng(1).uniform(0, 0.02, (300, n))
    xi = np.random.default_rng(2).standard_normal((300, n))
    rng0 = seed_streams(np.random.default_rng(3), n)
    res = []
    for kernel in ("numba", "py"):
        v = np.zeros(n)
        lag = np.full(n, basis.shape[1] - 1, np.int64)
        refc = np.zeros(n, np.int64)
        ring = np.zeros((n, basis.shape[1] - 2 if history == "sum" else 0))
        rng = rng0.copy()
        v_out = np.empty((300, n))
        pos, parts = 0, []
        for a, b in ((0, 170), (170, 300)):
            if kernel == "numba":
                steps, idx, k, pos = lif_units(
                    u[a:b], coef, thr, w, basis, v, lag, refc, 5, n_clamp, ring, pos, noise, rng, xi[a:b],
                    np.zeros(n), v_out[a:b], np.empty(4, np.int64), np.empty(4, np.int64),
                )  # fmt: skip
                steps, idx = steps[:k], idx[:k]
            else:
                steps, idx, pos = lif_units_py(
                    u[a:b],
                    coef,
                    thr,
                    w,
                    basis,
                    v,
                    lag,
                    refc,
                    5,
                    n_clamp,
                    ring,
                    pos,
                    noise,
                    rng,
                    xi[a:b],
                    v_out[a:b],
                )
            parts.append((steps + a, idx))
        steps = np.concatenate([p[0] for p in parts])
        idx = np.concatenate([p[1] for p in parts])
        res.append((steps, idx, v, lag, ring, v_out))
    assert len(res[0][0]) > 100
    for a, b in zip(res[0], res[1], strict=True):
        np.testing.assert_array_equal(a, b)


def _isi(**params):
    """Inter-spike intervals (steps) of one unit under a constant drive that takes v from 0 past the
    threshold in 3 steps (euler, τ = 100 steps, no post-spike current)."""
    blk = Nlif(history="last", integrator="euler", tau_s=100 / FS, gain=100.0, **params)
    out = run_offline(blk, x=np.full(200, 0.4), rate_hz=FS)
    steps = np.rint(out["spikes"].t * FS).astype(int)
    return set(np.diff(steps).tolist()), steps[0]


def test_threshold_block_lets_the_membrane_integrate():
    # v: 0.4, 0.796, 1.188 → first spike at step 2. Blocked for 5 steps, v goes on rising: the
    # next spike comes as soon as the block ends (6 steps). The membrane clamp instead holds v at 0
    # for 5 steps, then v needs 3 more: 8 steps.
    assert _isi() == ({3}, 2)
    assert _isi(threshold_block_s=6 / FS) == ({6}, 2)
    assert _isi(refractory_s=6 / FS) == ({8}, 2)


def test_per_unit_threshold():
    blk = Nlif(n=2, history="last", integrator="euler", tau_s=100 / FS, gain=100.0, threshold=[1.0, 1.5])
    out = run_offline(blk, x=np.full(200, 0.4), rate_hz=FS)
    first = [np.rint(out["spikes"].t[out["spikes"].data == k][0] * FS) for k in (0, 1)]
    assert first == [2, 3]  # v after step 3 is 1.577 > 1.5


def test_last_mode_keeps_only_the_latest_kernel():
    """With a kernel longer than the inter-spike interval, summed kernels inhibit more: fewer spikes."""
    common = {"integrator": "euler", "tau_s": 0.002, "gain": 10.0, "h_weights": [-0.5, -0.5],
              "h_peaks_s": [0.002, 0.02], "h_offset_s": 0.001}  # fmt: skip
    x = np.full(2000, 0.2)
    n_last = len(run_offline(Nlif(history="last", **common), x=x, rate_hz=FS)["spikes"])
    n_sum = len(run_offline(Nlif(history="sum", **common), x=x, rate_hz=FS)["spikes"])
    assert n_last > 5 * n_sum > 0  # 133 against 7


def test_models_give_per_unit_parameters_and_explicit_ones_override():
    p = Nlif(models=["SA1.0", "touch.PC.2"]).config.resolved()
    assert p["tau_s"].shape == (2,) and p["tau_s"][0] != p["tau_s"][1]
    assert p["h_weights"].shape == (2, 4)
    assert p["history"] == "last" and p["integrator"] == "euler"
    p = Nlif(models=["SA1.0", "PC.2"], sigma=0.5).config.resolved()
    assert p["sigma"].tolist() == [0.5, 0.5]


@pytest.mark.parametrize(
    ("params", "field", "says"),
    [
        ({"models": ["SA1.0", "XX.1"]}, "models", "item 1: 'XX.1' is not an nlif preset"),
        ({"models": ["SA1.0", "PC.1"], "n": 3}, "n", "must be 1 or len(models) = 2"),
        ({"models": ["SA1", "PC.1"]}, "models", "differs between the models"),
        ({"n": 2, "history": "last", "h_weights": [[0, 1]]}, "h_weights", "needs 2 lists"),
        ({"history": "last", "integrator": "exp_interp"}, "integrator", "exp_interp has no history: last"),
        ({"threshold": 1.5, "integrator": "exp_interp"}, "integrator", "exp_interp has no"),
        ({"threshold": [1.0, -1.0], "n": 2}, "threshold", "must be > 0"),
        ({"history": "last", "threshold": [1.0, 2.0]}, "threshold", "must have 1 or n = 1 values"),
    ],
)
def test_bad_configs_are_refused_naming_the_field(params, field, says):
    with pytest.raises(ConfigError) as e:
        Nlif(**params)
    assert field in str(e.value) and says in str(e.value)


class NlifLast(Nlif):
    """nlif with an example in the last-spike mode: three TouchSim models and a noisy unit with a
    membrane clamp, for the conformance suite."""

    @classmethod
    def example(cls) -> Example:
        t = np.arange(2000) / FS
        x = 0.02 + 0.02 * np.sin(2 * np.pi * 50 * t)
        return Example(
            params={"models": ["SA1.0", "RA.3", "PC.1"], "sigma": [0.0, 0.3, 0.0], "refractory_s": 0.0004},
            inputs={"x": np.stack([x, 2 * x, 20 * x], axis=1)},
            rate_hz=FS,
        )


class NlifSummedUnits(Nlif):
    """nlif with an example on the per-unit kernel's summed history: Rager's SA1 and FA1 (noisy) in
    one population, with a threshold block, for the conformance suite."""

    @classmethod
    def example(cls) -> Example:
        x = 0.6 + 0.54 * np.sin(2 * np.pi * 7 * np.arange(1500) / 1000.0)
        return Example(params={"models": ["SA1", "FA1", "SA1"], "threshold_block_s": 0.006}, inputs={"x": x})


@pytest.mark.parametrize("check", CHECKS, ids=lambda c: c.__name__.removeprefix("check_"))
@pytest.mark.parametrize("cls", [NlifLast, NlifSummedUnits], ids=["last", "sum"])
def test_conformance_of_the_per_unit_kernel(cls, check):
    ex = cls.example()
    out = run_offline(cls(**ex.params), x=ex.inputs["x"], rate_hz=ex.rate_hz)
    assert len(out["spikes"]) > 20  # the example does spike, so chunking invariance means something
    check(cls)


@pytest.mark.parametrize("integrator", ["exp", "euler"])
def test_summed_per_unit_path_matches_the_shared_kernel(integrator):
    """Rager's SA1 and FA1 in one population (``models: [SA1, FA1]``, noise off) fire as the two
    populations do on the shared-parameter kernel: the same spike steps (the post-spike tables may
    differ by an ulp, far below any threshold margin here)."""
    x = 0.6 + 0.54 * np.sin(2 * np.pi * 7 * np.arange(3000) / 1000.0)  # SA1 421, FA1 63 spikes
    both = run_offline(Nlif(models=["SA1", "FA1"], sigma=0.0, integrator=integrator), x=x)
    for k, name in enumerate(["SA1", "FA1"]):
        alone = run_offline(Nlif(preset=f"touch.{name}", sigma=0.0, integrator=integrator), x=x)
        np.testing.assert_array_equal(both["spikes"].t[both["spikes"].data == k], alone["spikes"].t)
        assert len(alone["spikes"]) > 50
