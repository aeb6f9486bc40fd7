"""The braille suite's measures: information with its bias correction, the constant-speed comparison, the held-out text."""

import numpy as np
import pytest

from flowtact.bench.braille import fastest_constant, heldout_text, rates
from flowtact.bench.braille_metrics import (
    chow_threshold,
    confusion,
    entropy_bits,
    mi_bits,
    mi_corrected,
    pt_bias_bits,
)
from flowtact.blocks.braille.train_braille import HELDOUT_SEED


def test_plug_in_information_of_perfect_and_independent_confusions():
    assert mi_bits(np.eye(26) * 10) == pytest.approx(np.log2(26))
    assert mi_bits(np.ones((26, 26))) == pytest.approx(0.0, abs=1e-12)
    m = np.array([[3, 1], [1, 3]])  # p(correct) 3/4: 1 − H2(1/4) bits
    h2 = -(0.25 * np.log2(0.25) + 0.75 * np.log2(0.75))
    assert mi_bits(m) == pytest.approx(1 - h2)


def test_bias_corrections_on_responses_that_carry_no_information():
    """The suite's estimator (extrapolation) leaves < 0.15 bits of 4.7 at 40 trials per letter;
    at 10 it does not, nor does Panzeri–Treves: why the suite reads 40 per letter."""
    rng = np.random.default_rng(0)
    assert pt_bias_bits(np.eye(26, dtype=int) * 10) <= 0  # a perfect decoder: nothing to remove
    for per, bound in ((40, 0.15), (10, None)):
        y = np.repeat(np.arange(26), per)
        est = [mi_corrected(rng.poisson(2.0, (len(y), 24)), y, 26, seed=s)[0] for s in range(3)]
        m = confusion(y, rng.integers(0, 26, len(y)), 26)
        if bound is not None:
            assert np.mean(est) < bound
        else:
            assert np.mean(est) > 0.3 and mi_bits(m) - pt_bias_bits(m) > 0.5  # biased at 10 per letter
    floor = mi_corrected(rng.poisson(1.0, (26 * 40, 24)) * 0 + np.repeat(np.eye(26), 40, axis=0)[:, :24] * 5,
                         np.repeat(np.arange(26), 40), 26, shuffle=True)[0]  # fmt: skip
    assert floor < 0.15  # shuffled letters: informative responses, yet 0 bits about the labels


def test_information_grows_with_the_signal_and_stays_below_the_stimulus_entropy():
    rng = np.random.default_rng(1)
    y = np.repeat(np.arange(26), 20)
    lam = rng.uniform(0.5, 5.0, (26, 24))
    h = entropy_bits(np.bincount(y))
    mis = [mi_corrected(rng.poisson(lam[y] * s), y, 26)[0] for s in (0.05, 0.3, 3.0)]
    assert mis[0] < mis[1] < mis[2] <= h
    assert mis[2] > 0.9 * h


def test_fastest_constant_speed_of_equal_accuracy_interpolates_the_curve():
    curve = [(10.0, 1.0), (100.0, 1.0), (200.0, 0.9), (300.0, 0.5)]
    assert fastest_constant(curve, 1.0) == pytest.approx(100.0, abs=0.2)
    assert fastest_constant(curve, 0.95) == pytest.approx(150.0, abs=0.2)
    assert fastest_constant(curve, 0.7) == pytest.approx(250.0, abs=0.2)
    assert np.isnan(fastest_constant([(10.0, 0.5), (20.0, 0.4)], 0.9))


def test_held_out_text_is_balanced_and_from_the_held_out_seed():
    text = heldout_text(3)
    assert len(text) == 78 and all(text.count(c) == 3 for c in "abcdefghijklmnopqrstuvwxyz")
    rng = np.random.default_rng(HELDOUT_SEED)
    assert text[:26] == "".join(rng.permutation(list("abcdefghijklmnopqrstuvwxyz")))


def test_chow_threshold_minimises_errors_plus_half_the_abstentions_by_brute_force():
    """Against the risk of every threshold on a fine grid (an independent oracle): the chosen one
    reaches the least risk, and no threshold abstaining on fewer windows does."""
    rng = np.random.default_rng(2)
    top = np.round(rng.uniform(1 / 26, 1.0, 400), 2)  # ties on purpose
    correct = rng.uniform(0, 1, 400) < top  # confident windows are right more often
    risk = lambda th: np.sum(~correct & (top >= th)) + 0.5 * np.sum(top < th)  # noqa: E731
    grid = np.linspace(0, 1.01, 10_102)
    best = min(risk(th) for th in grid)
    th = chow_threshold(top, correct, 0.5)
    n_out = np.sum(top < th)
    assert risk(th) == best and all(risk(g) > best for g in grid if np.sum(top < g) < n_out)  # fewest abstain
    assert chow_threshold(top, np.ones(400, bool)) == 0.0  # never wrong: never abstain
    th = chow_threshold(top, np.zeros(400, bool))  # always wrong: abstain on all
    assert (top < th).all()


def test_rates_count_abstentions_apart_from_errors():
    truth = np.array([0, 1, 2, 3])
    assert rates(np.array([0, 26, 2, 5]), truth) == (0.5, 0.25)  # 26: not classified
