"""The naive_bayes decoder: posterior against scikit-learn, model files, windows, chunking."""

import json
import tempfile
import zipfile
from pathlib import Path

import numpy as np
import pytest
from sklearn.naive_bayes import GaussianNB, MultinomialNB

from flowtact import SpecError, StreamSpec
from flowtact.blocks.spiking.naive_bayes import (
    EXAMPLE_RATE_HZ,
    NaiveBayes,
    example_data,
    example_model_path,
)
from flowtact.blocks.spiking.nb_model import (
    ModelError,
    fit_gaussian,
    fit_multinomial,
    load_model,
    log_posterior,
    save_model,
)
from flowtact.blocks.spiking.window_features import window_features
from flowtact.chunk import Chunk
from flowtact.testing import CHECKS, assert_same, run_offline

CLASSES = ("x", "y", "z")


def windows_of(window: np.ndarray, rate: float) -> tuple[np.ndarray, list[int]]:
    """[t0, t1) and value of each maximal run of one value >= 0."""
    out, labels, start = [], [], None
    for k, v in enumerate([*window.tolist(), -1]):
        if start is not None and v != window[start]:
            out.append((start / rate, k / rate))
            labels.append(int(window[start]))
            start = None
        if v >= 0 and start is None:
            start = k
    return np.array(out), labels


def fit_example_model(path, n_bins: int = 2):
    """The shipped example model: counts in 2 sub-bins, fit on 60 synthetic windows (seed 11)."""
    (t, u), window = example_data(labels=tuple(np.arange(60) % 3), seed=11)
    w, labels = windows_of(window, EXAMPLE_RATE_HZ)
    x = window_features(t, u, w, n_units=4, n_bins=n_bins)
    m = fit_multinomial(x, [CLASSES[k] for k in labels], CLASSES, n_units=4, n_bins=n_bins)
    return save_model(path, m, {"made_by": "tests/blocks/spiking/test_naive_bayes.py:fit_example_model"})


def test_shipped_example_model_is_the_documented_fit(tmp_path):
    a, b = load_model(example_model_path()), load_model(fit_example_model(tmp_path / "m.npz"))
    for k in a.arrays:
        np.testing.assert_array_equal(a.arrays[k], b.arrays[k])


def _features(kind, n_bins=3, seed=5):
    rng = np.random.default_rng(seed)
    (t, u), window = example_data(labels=tuple(rng.integers(0, 3, 90)), seed=seed)
    w, labels = windows_of(window, EXAMPLE_RATE_HZ)
    return window_features(t, u, w, n_units=4, n_bins=n_bins, kind=kind), np.array(labels)


def test_multinomial_posterior_equals_scikit_learn():
    x, y = _features("counts")
    names = [CLASSES[k] for k in y]
    m = fit_multinomial(x[:60], names[:60], CLASSES, n_units=4, n_bins=3, alpha=0.5)
    ref = MultinomialNB(alpha=0.5).fit(x[:60], y[:60])
    np.testing.assert_allclose(m.arrays["feature_log_prob"], ref.feature_log_prob_, rtol=1e-12)
    np.testing.assert_allclose(np.exp(log_posterior(m, x[60:])), ref.predict_proba(x[60:]), atol=1e-12)
    np.testing.assert_allclose(log_posterior(m, x[60:]), ref.predict_log_proba(x[60:]), rtol=1e-10)


def test_gaussian_posterior_equals_scikit_learn():
    x, y = _features("latency")
    names = [CLASSES[k] for k in y]
    m = fit_gaussian(x[:60], names[:60], CLASSES, n_units=4, var_smoothing=1e-3)
    ref = GaussianNB(var_smoothing=1e-3).fit(x[:60], y[:60])
    np.testing.assert_allclose(m.arrays["theta"], ref.theta_, rtol=1e-12)
    np.testing.assert_allclose(m.arrays["var"], ref.var_, rtol=1e-12)
    np.testing.assert_allclose(log_posterior(m, x[60:]), ref.predict_log_proba(x[60:]), rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("kind", ["counts", "latency"])
def test_the_block_posterior_is_the_oracle_on_the_same_windows(tmp_path, kind):
    """The block's per-window posterior = scikit-learn's on features computed from the same windows."""
    x, y = _features(kind, n_bins=2 if kind == "counts" else 1, seed=8)
    names = [CLASSES[k] for k in y]
    if kind == "counts":
        m = fit_multinomial(x, names, CLASSES, n_units=4, n_bins=2)
        ref = MultinomialNB().fit(x, y)
    else:
        m = fit_gaussian(x, names, CLASSES, n_units=4, var_smoothing=1e-2)
        ref = GaussianNB(var_smoothing=1e-2).fit(x, y)
    path = save_model(tmp_path / "m.npz", m)
    (t, u), window = example_data(labels=(2, 0, 1, 1, 0), seed=21)
    out = decode(NaiveBayes(model=str(path)), t, u, window, with_running=kind == "counts")
    w, _ = windows_of(window, EXAMPLE_RATE_HZ)
    xs = window_features(t, u, w, n_units=4, n_bins=m.n_bins, kind=kind)
    np.testing.assert_allclose(out["posterior"].data, ref.predict_proba(xs), atol=1e-12)
    np.testing.assert_allclose(out["posterior"].t, w[:, 1])
    assert out["decision"].data.tolist() == ref.predict(xs).tolist() == [2, 0, 1, 1, 0]


def decode(blk, t, u, window, with_running=True):
    """Feed in chunks of 9 window samples (spikes split alike), flush, join each output."""
    specs = {
        "spikes": StreamSpec(dtype="int64", events=True, n_units=4),
        "window": StreamSpec(dtype="int64", rate_hz=EXAMPLE_RATE_HZ),
    }
    outs = {"posterior", "decision"} | ({"running"} if with_running else set())
    blk.bind(specs, demanded=frozenset(outs))
    got = []
    for a in range(0, len(window), 9):
        t0, t1 = a / EXAMPLE_RATE_HZ, min(a + 9, len(window)) / EXAMPLE_RATE_HZ
        sel = (t >= t0) & (t < t1)
        got.append(
            blk(
                spikes=Chunk(t[sel], u[sel], t1),
                window=Chunk(np.arange(a, a + 9)[: len(window) - a] / EXAMPLE_RATE_HZ, window[a : a + 9]),
            )
        )
    got.append(blk.flush())
    return {
        k: Chunk(np.concatenate([g[k].t for g in got]), np.concatenate([g[k].data for g in got]))
        for k in outs
    }


def test_a_latency_model_cannot_feed_running():
    x, y = _features("latency")
    m = fit_gaussian(x, [CLASSES[k] for k in y], CLASSES, n_units=4, var_smoothing=1e-3)
    (t, u), window = example_data()
    with pytest.raises(SpecError, match="output 'running' needs a counts model"):
        decode(NaiveBayes(model=str(save_model(Path(tempfile.mkdtemp()) / "g.npz", m))), t, u, window)


def test_running_posterior_is_the_marginal_model_on_the_spikes_so_far():
    m = load_model(example_model_path())
    (t, u), window = example_data()
    out = run_offline(
        NaiveBayes(model=str(example_model_path())), spikes=(t, u), window=window, rate_hz=250.0
    )
    run = out["running"]
    assert run.data.shape == (len(window), 3) and run.t[5] == 5 / 250.0
    # sample 40 lies in the first window [20, 70): counts since 20/250 up to 41/250, unit-marginal model
    x = window_features(t, u, np.array([[20 / 250.0, 41 / 250.0]]), n_units=4)
    marg = m.unit_marginal()
    np.testing.assert_allclose(run.data[40], np.exp(log_posterior(marg, x)[0]), atol=1e-14)
    flp = marg.arrays["feature_log_prob"]  # a proper distribution over units per class
    np.testing.assert_allclose(np.exp(flp).sum(axis=1), 1.0)
    # before the first window: the prior; in the gap after window 1: window 1's posterior
    np.testing.assert_allclose(run.data[0], np.exp(m.arrays["class_log_prior"]))
    np.testing.assert_array_equal(run.data[75], out["posterior"].data[0])


def test_an_empty_window_gives_the_prior_not_nan():
    window = np.r_[np.full(10, -1), np.full(30, 1), np.full(10, -1)]
    blk = NaiveBayes(model=str(example_model_path()))
    specs = {
        "spikes": StreamSpec(dtype="int64", events=True, n_units=4),
        "window": StreamSpec(dtype="int64", rate_hz=250.0),
    }
    out = run_offline(
        blk, spikes=(np.zeros(0), np.zeros(0, np.int64)), window=window, rate_hz=250.0, specs=specs
    )
    prior = np.exp(load_model(example_model_path()).arrays["class_log_prior"])
    np.testing.assert_allclose(out["posterior"].data, [prior])
    assert np.isfinite(out["running"].data).all()
    assert blk.counters["empty_windows"] == 1


def test_a_window_open_at_the_end_is_dropped_and_counted():
    (t, u), window = example_data()
    blk = NaiveBayes(model=str(example_model_path()))
    out = run_offline(blk, spikes=(t, u), window=window[:100], rate_hz=250.0)
    assert len(out["decision"]) == 1 and blk.counters["unfinished_windows"] == 1


def test_results_wait_for_the_spike_watermark():
    blk = NaiveBayes(model=str(example_model_path()))
    blk.bind(
        {
            "spikes": StreamSpec(dtype="int64", events=True, n_units=4),
            "window": StreamSpec(dtype="int64", rate_hz=250.0),
        }
    )
    w = np.r_[np.full(5, 0), -1]
    out = blk(spikes=Chunk(np.array([0.001]), np.array([0]), 0.004), window=Chunk(np.arange(6) / 250.0, w))
    assert len(out["running"]) == 1 and len(out["decision"]) == 0  # spikes only known up to 4 ms
    out = blk(
        spikes=Chunk(np.zeros(0), np.zeros(0, np.int64), 0.03),
        window=Chunk(np.zeros(0), np.zeros(0, np.int64)),
    )
    assert len(out["decision"]) == 1 and len(out["running"]) == 5


def test_chunking_does_not_change_anything():
    (t, u), window = example_data(labels=(0, 2, 2, 1, 0, 1), seed=4)
    runs = [
        run_offline(
            NaiveBayes(model=str(example_model_path())), spikes=(t, u), window=window, rate_hz=250.0, chunk=c
        )
        for c in (None, 1, [3, 50, 1, 17])
    ]
    assert_same(runs[0], runs[1], "chunks of 1")
    assert_same(runs[0], runs[2], "irregular chunks")


def test_window_categories_name_the_gaps():
    cats = ("a", "b", "c", "gap")
    blk = NaiveBayes(model=str(example_model_path()), gap=("gap",))
    spec = {
        "spikes": StreamSpec(dtype="int64", events=True, n_units=4),
        "window": StreamSpec(dtype="int64", rate_hz=250.0, categories=("x", "y", "z", "gap")),
    }
    out = blk.bind(spec)
    assert out["decision"].categories == CLASSES and out["posterior"].labels == CLASSES
    assert out["posterior"].rate_hz is None and out["running"].rate_hz == 250.0
    with pytest.raises(
        SpecError, match=r"model classes \['x', 'y', 'z'\] are not among the window categories"
    ):
        NaiveBayes(model=str(example_model_path())).bind(
            {**spec, "window": spec["window"].with_(categories=cats)}
        )


def test_a_model_for_another_population_is_refused():
    blk = NaiveBayes(model=str(example_model_path()))
    with pytest.raises(SpecError, match="trained on 4 units; input 'spikes' has 24"):
        blk.bind(
            {
                "spikes": StreamSpec(dtype="int64", events=True, n_units=24),
                "window": StreamSpec(dtype="int64", rate_hz=250.0),
            }
        )


def _rewrite(src, dst, change):
    with np.load(src) as z:
        d = {k: np.array(z[k]) for k in z.files}
    change(d)
    with open(dst, "wb") as f:
        np.savez(f, **d)
    return dst


def test_damaged_or_foreign_model_files_are_refused_with_a_reason(tmp_path):
    src = example_model_path()

    def tamper(d):
        d["feature_log_prob"] = d["feature_log_prob"] + 0.01

    def other_format(d):
        meta = json.loads(str(d["meta"]))
        meta["format"] = "something/9"
        d["meta"] = np.array(json.dumps(meta))

    with pytest.raises(ModelError, match="checksum mismatch"):
        load_model(_rewrite(src, tmp_path / "t.npz", tamper))
    with pytest.raises(ModelError, match="format 'something/9'"):
        load_model(_rewrite(src, tmp_path / "f.npz", other_format))
    cut = tmp_path / "cut.npz"
    cut.write_bytes(src.read_bytes()[:300])
    with pytest.raises(ModelError, match="not a readable naive Bayes model file"):
        load_model(cut)
    with pytest.raises(ModelError, match="no such model file"):
        load_model(tmp_path / "none.npz")
    assert zipfile.is_zipfile(src)
    with pytest.raises(SpecError, match=r"naive_bayes \(naive_bayes\): model: .*checksum mismatch"):
        NaiveBayes(model=str(tmp_path / "t.npz")).bind(
            {
                "spikes": StreamSpec(dtype="int64", events=True, n_units=4),
                "window": StreamSpec(dtype="int64", rate_hz=250.0),
            }
        )


def test_model_round_trip_keeps_arrays_and_provenance(tmp_path):
    x, y = _features("latency")
    m = fit_gaussian(x, [CLASSES[k] for k in y], CLASSES, n_units=4, var_smoothing=1e-3)
    back = load_model(save_model(tmp_path / "g.npz", m, {"seed": 3, "speeds_mm_s": [30.0]}))
    assert back.classes == CLASSES and back.features == "latency" and back.provenance["seed"] == 3
    for k in m.arrays:
        np.testing.assert_array_equal(back.arrays[k], m.arrays[k])


@pytest.mark.parametrize("check", CHECKS, ids=lambda c: c.__name__.removeprefix("check_"))
def test_naive_bayes_conforms(check):
    check(NaiveBayes)


def test_spikes_out_of_order_are_sorted_and_late_ones_counted():
    specs = {
        "spikes": StreamSpec(dtype="int64", events=True, n_units=4),
        "window": StreamSpec(dtype="int64", rate_hz=250.0),
    }
    blk = NaiveBayes(model=str(example_model_path()))
    blk.bind(specs, demanded=frozenset({"posterior"}))
    w = np.r_[np.full(10, 0), np.full(5, -1)]
    t = np.arange(15) / 250.0
    # spikes of unit 2 arrive reversed: the window's counts are the same as in time order
    out = blk(spikes=Chunk(np.array([0.03, 0.02, 0.01]), np.array([2, 2, 2]), 0.06), window=Chunk(t, w))
    ref = NaiveBayes(model=str(example_model_path()))
    ref.bind(specs, demanded=frozenset({"posterior"}))
    want = ref(spikes=Chunk(np.array([0.01, 0.02, 0.03]), np.array([2, 2, 2]), 0.06), window=Chunk(t, w))
    np.testing.assert_array_equal(out["posterior"].data, want["posterior"].data)
    blk(
        spikes=Chunk(np.array([0.005]), np.array([1]), 0.07), window=Chunk(np.zeros(0), np.zeros(0, np.int64))
    )
    assert blk.counters["late_spikes"] == 1  # its window was decoded already


def test_a_watermark_one_rounding_past_the_next_sample_makes_no_late_spike():
    """The Braille loop's case: a producer's watermark ``t + dt`` (0.068 + 0.004 =
    0.07200000000000001) passes the next sample's own time 0.072 by an ulp. Spikes at 0.072 are
    neither late nor lost, and the running posterior at 0.068 leaves them out in every chunking."""
    specs = {
        "spikes": StreamSpec(dtype="int64", events=True, n_units=4),
        "window": StreamSpec(dtype="int64", rate_hz=250.0),
    }
    assert 0.068 + 0.004 > 18 / 250.0  # the rounding this test is about
    t = np.arange(40) / 250.0
    w = np.r_[np.full(30, 0), np.full(10, -1)]
    spk_t, spk_u = np.array([0.02, 0.072, 0.072, 0.1]), np.array([0, 2, 2, 3])

    def by_ticks() -> tuple[dict, dict]:
        blk = NaiveBayes(model=str(example_model_path()))
        blk.bind(specs)
        outs = []
        for i in range(len(t)):  # one sample per tick, as the closed loop runs it
            sel = (spk_t >= t[i] - 1e-12) & (spk_t < t[i] + 0.002)
            end = t[i] + 1 / 250.0  # the producer's watermark: t_last + dt, rounded
            outs.append(
                blk(spikes=Chunk(spk_t[sel], spk_u[sel], end), window=Chunk(t[i : i + 1], w[i : i + 1]))
            )
        outs.append(blk.flush())
        joined = {k: np.concatenate([o[k].data for o in outs]) for k in ("posterior", "running")}
        return joined, blk.counters

    ticked, counters = by_ticks()
    assert "late_spikes" not in counters, counters
    whole = NaiveBayes(model=str(example_model_path()))
    whole.bind(specs)
    one = whole(spikes=Chunk(spk_t, spk_u, 1.0), window=Chunk(t, w))
    rest = whole.flush()
    np.testing.assert_array_equal(
        ticked["posterior"], np.concatenate([one["posterior"].data, rest["posterior"].data])
    )
    np.testing.assert_array_equal(
        ticked["running"], np.concatenate([one["running"].data, rest["running"].data])
    )


@pytest.mark.parametrize(
    ("cats", "n_right"),
    [(("x", "y", "z", "gap"), 5), (("y", "z", "x", "gap"), 0)],
    ids=["labelled", "mislabelled"],
)
def test_the_summary_counts_windows_read_right_against_their_labels(cats, n_right):
    """The example's windows are driven as classes 0, 1, 2, 0, 2 and read so (the docstring
    example): named as the model names them they are all right; named otherwise, none is."""
    (t, u), window = example_data(labels=(0, 1, 2, 0, 2), seed=3)
    window = np.where(window < 0, 3, window)  # the gaps named
    blk = NaiveBayes(model=str(example_model_path()), gap=("gap",))
    blk.bind(
        {
            "spikes": StreamSpec(dtype="int64", events=True, n_units=4),
            "window": StreamSpec(dtype="int64", rate_hz=EXAMPLE_RATE_HZ, categories=cats),
        }
    )
    assert blk.summary() is None  # nothing read yet: nothing to say
    blk(spikes=Chunk(t, u, 10.0), window=Chunk(np.arange(len(window)) / EXAMPLE_RATE_HZ, window))
    assert blk.summary() == f'read 5 windows, {n_right} right (against the window labels): "xyzxz"'


def test_the_reject_rule_abstains_below_the_threshold_only():
    from flowtact.blocks.spiking.nb_model import decide

    p = np.array([[0.5, 0.3, 0.2], [0.2, 0.2, 0.6], [1 / 3, 1 / 3, 1 / 3], [0.45, 0.45, 0.1]])
    assert decide(p).tolist() == [0, 2, 0, 0]  # no threshold: the most probable, the first of equals
    assert decide(p, 0.5).tolist() == [0, 2, 3, 3]  # below 0.5: "not classified" (index 3)
    assert decide(p, 0.6).tolist() == [3, 2, 3, 3]  # at the threshold: still classified
    assert decide(p, 1.0).tolist() == [3, 3, 3, 3]
    with pytest.raises(ValueError, match="threshold must be in"):
        decide(p, 1.5)


def test_the_block_abstains_by_the_shared_rule_and_counts_it():
    """Decisions are decide(posterior, threshold) of the block's own posteriors; abstentions get the
    category 'not classified', a counter and a place in the summary."""
    from flowtact.blocks.spiking.nb_model import NOT_CLASSIFIED, decide

    (t, u), window = example_data(labels=(0, 1, 2, 0, 2, 1, 1, 0), seed=5)
    plain = run_offline(NaiveBayes(model=str(example_model_path())), spikes=(t, u), window=window,
                        rate_hz=EXAMPLE_RATE_HZ)  # fmt: skip
    top = plain["posterior"].data.max(axis=1)
    thr = float(np.median(top))  # half the windows fall below it
    blk = NaiveBayes(model=str(example_model_path()), threshold=thr)
    out = run_offline(blk, spikes=(t, u), window=window, rate_hz=EXAMPLE_RATE_HZ)
    dec = out["decision"].data
    np.testing.assert_array_equal(dec, decide(out["posterior"].data, thr))
    n_abstained = int((top < thr).sum())
    assert 0 < n_abstained < len(top) and int((dec == 3).sum()) == n_abstained
    spec = blk.specs(
        {
            "spikes": StreamSpec(dtype="int64", events=True, n_units=4),
            "window": StreamSpec(dtype="int64", rate_hz=EXAMPLE_RATE_HZ),
        }
    )
    assert spec["decision"].categories[-1] == NOT_CLASSIFIED and len(spec["decision"].categories) == 4


def test_the_summary_counts_abstentions_and_scores_only_labelled_windows():
    (t, u), window = example_data(labels=(0, 1, 2, 0, 2), seed=3)
    spikes, win = Chunk(t, u, 10.0), Chunk(np.arange(len(window)) / EXAMPLE_RATE_HZ, window)
    specs = {
        "spikes": StreamSpec(dtype="int64", events=True, n_units=4),
        "window": StreamSpec(dtype="int64", rate_hz=EXAMPLE_RATE_HZ),
    }
    blk = NaiveBayes(model=str(example_model_path()), threshold=1.0)  # abstains on every window
    blk.bind(specs)
    blk(spikes=spikes, window=win)
    assert blk.summary() == 'read 5 windows, 0 right, 5 not classified (against the window labels): "?????"'
    assert blk.counters["not_classified"] == 5
    blk = NaiveBayes(model=str(example_model_path()), window_labels=False)  # windows that only delimit
    blk.bind(specs)
    blk(spikes=spikes, window=win)
    assert blk.summary() == 'read 5 windows: "xyzxz"'
