"""Measures of the Braille evaluation: recognition, confusion, and stimulus–response information.

Mutual information (the paper's Fig. 4A, in the decoding form): for each window length ``T`` the
response of a trial is its spike counts per neuron in ``[onset, onset + T)``; a multinomial naive
Bayes, cross-validated in ``k`` folds, predicts the letter of every held-out trial, and
``I(S; R) ≥ I(S; Ŝ)`` is the plug-in information of the confusion matrix (the data-processing
inequality makes it a lower bound of the information the counts carry). Its upward bias (a finite
confusion matrix has positive plug-in information even for a random decoder) is removed by
quadratic extrapolation to infinitely many trials (Strong et al. 1998; Panzeri et al. 2007): the
plug-in information of random halves and quarters of the (letter, decision) pairs, fitted as
``I(N) = I∞ + a/N + b/N²``. Tried and measured on responses that carry 0 bits, 26 letters
(tests/benchmark/test_bench_braille.py): with 10 trials per letter Panzeri–Treves' first-order correction
still leaves 1.1 bits and the extrapolation 0.7; with 40 trials the extrapolation leaves < 0.1
(Panzeri–Treves 0.2); a shuffle correction over-corrects a good decoder (3.7 of 4.7 bits for a
perfect one). So the suite uses 40 trials per letter (10 with ``--quick``: read its early values
as an upper bound) and draws the estimator's floor: the same estimate with shuffled letters.
The conditional entropy ``H(S|R) = H(S) − I``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from flowtact.blocks.spiking.nb_model import fit_multinomial, log_posterior

__all__ = [
    "chow_threshold",
    "confusion",
    "crossval_predict",
    "entropy_bits",
    "mi_bits",
    "mi_corrected",
    "mi_extrapolated",
    "pt_bias_bits",
]


def confusion(true: Sequence[int], pred: Sequence[int], n: int) -> np.ndarray:
    """Counts ``m[i, j]``: trials of class ``i`` decided as ``j``."""
    m = np.zeros((n, n), np.int64)
    np.add.at(m, (np.asarray(true, np.int64), np.asarray(pred, np.int64)), 1)
    return m


def entropy_bits(p: np.ndarray) -> float:
    """Entropy in bits of a distribution (zeros ignored)."""
    p = np.asarray(p, float)
    p = p[p > 0] / p.sum()
    return float(-(p * np.log2(p)).sum())


def mi_bits(m: np.ndarray) -> float:
    """Plug-in mutual information in bits of a confusion (joint count) matrix."""
    joint = m / m.sum()
    ps, pr = joint.sum(axis=1, keepdims=True), joint.sum(axis=0, keepdims=True)
    nz = joint > 0
    return float((joint[nz] * np.log2(joint[nz] / (ps @ pr)[nz])).sum())


def crossval_predict(
    x: np.ndarray, y: np.ndarray, n_classes: int, folds: int, rng: np.random.Generator
) -> np.ndarray:
    """Held-out decisions of a multinomial naive Bayes, ``folds``-fold cross-validated."""
    order = rng.permutation(len(y))
    pred = np.empty(len(y), np.int64)
    names = [str(c) for c in range(n_classes)]
    for f in range(folds):
        test = order[f::folds]
        train = np.setdiff1d(order, test)
        present = np.unique(y[train])
        classes = [names[c] for c in present]
        m = fit_multinomial(x[train], [names[c] for c in y[train]], classes, n_units=x.shape[1], n_bins=1)
        pred[test] = present[np.argmax(log_posterior(m, x[test]), axis=1)]
    return pred


def pt_bias_bits(m: np.ndarray) -> float:
    """Panzeri–Treves first-order bias, in bits, of the plug-in information of confusion ``m``."""
    rows = m[m.sum(axis=1) > 0]
    r_s = (rows > 0).sum(axis=1)
    r = int((m.sum(axis=0) > 0).sum())
    return float(((r_s - 1).sum() - (r - 1)) / (2.0 * m.sum() * np.log(2.0)))


def mi_extrapolated(
    true: np.ndarray, pred: np.ndarray, n_classes: int, rng: np.random.Generator, reps: int = 30
) -> float:
    """Plug-in information of the (true, pred) pairs extrapolated to infinitely many pairs, bits."""
    n = len(true)
    inv, vals = [], []
    for frac in (1.0, 0.5, 0.25):
        k = max(round(n * frac), 2)
        subsets = [np.arange(n)] if frac == 1.0 else [rng.choice(n, k, replace=False) for _ in range(reps)]
        inv.append(1.0 / k)
        vals.append(float(np.mean([mi_bits(confusion(true[s], pred[s], n_classes)) for s in subsets])))
    return float(np.polyfit(inv, vals, 2)[-1])


def mi_corrected(
    x: np.ndarray, y: np.ndarray, n_classes: int, *, folds: int = 5, seed: int = 0, shuffle: bool = False
) -> tuple[float, float]:
    """(bias-corrected information in bits, the bias removed) of responses ``x`` about labels ``y``;
    ``shuffle`` permutes the labels first (the estimator's floor: the truth is then 0 bits)."""
    rng = np.random.default_rng(seed)
    if shuffle:
        y = rng.permutation(y)
    pred = crossval_predict(x, y, n_classes, folds, rng)
    raw = mi_bits(confusion(y, pred, n_classes))
    h_s = entropy_bits(np.bincount(y, minlength=n_classes))
    est = min(max(mi_extrapolated(y, pred, n_classes, rng), 0.0), h_s)
    return est, raw - est


def chow_threshold(top: np.ndarray, correct: np.ndarray, cost: float = 0.5) -> float:
    """The reject threshold minimising Chow's risk on validation windows: errors + ``cost`` ×
    abstentions, where a window abstains when its largest posterior ``top`` is below the threshold
    and ``correct`` says whether its most probable class was right. Candidates: 0 (never abstain)
    and each window's ``top`` (abstain on every window below it); the smallest of equal risks.
    With calibrated posteriors the optimum is ``1 − cost`` (Chow 1970); a naive Bayes model is
    over-confident, hence the search."""
    top = np.asarray(top, np.float64)
    correct = np.asarray(correct, bool)
    order = np.argsort(top, kind="stable")
    t, c = top[order], correct[order]
    # abstaining on the k lowest windows: errors among the rest + cost · k
    errors_kept = np.concatenate([[np.sum(~c)], np.sum(~c) - np.cumsum(~c)])
    risk = errors_kept + cost * np.arange(len(t) + 1)
    cand = np.concatenate([[0.0], t])  # threshold = t[k] abstains on t < t[k]: the k lowest when distinct
    # a threshold must abstain on whole groups of equal tops: only k where t[k-1] < t[k] (or k = 0, n)
    ok = np.ones(len(t) + 1, bool)
    ok[1:-1] = t[:-1] < t[1:]
    k = int(np.flatnonzero(ok)[np.argmin(risk[ok])])
    if k == len(t):
        return float(np.nextafter(t[-1], np.inf)) if len(t) else 0.0
    return float(cand[k] if k == 0 else t[k])
