"""The braille suite's measures: information with its bias correction, the constant-speed comparison, the held-out text."""

import numpy as np
import pytest

from flowtact.bench.braille import _fastest_constant, heldout_text
from flowtact.bench.braille_metrics import confusion, entropy_bits, mi_bits, mi_corrected, pt_bias_bits
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
    assert _fastest_constant(curve, 1.0) == pytest.approx(100.0, abs=0.2)
    assert _fastest_constant(curve, 0.95) == pytest.approx(150.0, abs=0.2)
    assert _fastest_constant(curve, 0.7) == pytest.approx(250.0, abs=0.2)
    assert np.isnan(_fastest_constant([(10.0, 0.5), (20.0, 0.4)], 0.9))


def test_held_out_text_is_balanced_and_from_the_held_out_seed():
    text = heldout_text(3)
    assert len(text) == 78 and all(text.count(c) == 3 for c in "abcdefghijklmnopqrstuvwxyz")
    rng = np.random.default_rng(HELDOUT_SEED)
    assert text[:26] == "".join(rng.permutation(list("abcdefghijklmnopqrstuvwxyz")))
