"""Noisy spike statistics of TouchSim's afferents, and a two-sample comparison of two simulators' runs.

TouchSim's noise (p8·ξ added to the current before saturation) comes from numba's generator inside
its compiled kernel, which Python cannot seed: its noisy runs can only be compared as distributions.
Per trace and repeat three statistics: the spike count, the first spike's sample (latency) and the
mean inter-spike interval (samples). Per trace and statistic, a two-sample Kolmogorov–Smirnov test
of one simulator's repeats against the other's; the family of tests is Bonferroni-corrected, so a
correct simulator fails any of them with probability at most ``ALPHA`` (KS on these discrete
statistics is conservative: ties only lower the false-alarm rate).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

__all__ = ["ALPHA", "MIN_DEFINED", "STATS", "Comparison", "compare", "spike_stats"]

ALPHA = 0.01
"""Family-wise false-alarm rate: the chance that a correct simulator fails any of the tests."""
MIN_DEFINED = 20
"""A statistic is tested on a trace only where both sides define it in at least this many repeats
(the latency needs a spike, the mean interval two): fewer give a KS test with no power."""
STATS = ("count", "first", "isi")


def spike_stats(spikes: list[np.ndarray]) -> dict[str, np.ndarray]:
    """Per unit: spike count, first spike's sample (NaN if silent), mean inter-spike interval in
    samples (NaN below two spikes)."""
    count = np.array([len(s) for s in spikes], np.float64)
    first = np.array([s[0] if len(s) else np.nan for s in spikes], np.float64)
    isi = np.array([(s[-1] - s[0]) / (len(s) - 1) if len(s) > 1 else np.nan for s in spikes], np.float64)
    return {"count": count, "first": first, "isi": isi}


@dataclass
class Comparison:
    """The tests of one comparison: per (trace, statistic) the KS p-value (NaN: not tested)."""

    names: list[str]
    p: dict[str, np.ndarray]
    tests: int
    threshold: float

    @property
    def rejected(self) -> list[tuple[str, str, float]]:
        """(trace, statistic, p) of every test below the corrected threshold."""
        return [
            (self.names[i], k, float(p[i]))
            for k, p in self.p.items()
            for i in np.flatnonzero(p < self.threshold)
        ]

    def summary(self) -> str:
        bad = self.rejected
        head = f"{len(bad)} of {self.tests} KS tests reject at family-wise α = {ALPHA:g} (per test {self.threshold:.2g})"
        return head + ("" if not bad else ": " + ", ".join(f"{n} {k} p={p:.1e}" for n, k, p in bad[:6]))


def compare(ours: dict[str, np.ndarray], theirs: dict[str, np.ndarray], names: list[str]) -> Comparison:
    """KS tests of each statistic, trace by trace; ``ours``/``theirs`` map a statistic to an array
    (repeats × traces). Identical constant samples (a silent trace on both sides) pass."""
    from scipy.stats import ks_2samp

    pvals: dict[str, np.ndarray] = {}
    tests = 0
    for k in STATS:
        a_all, b_all = np.asarray(ours[k], np.float64), np.asarray(theirs[k], np.float64)
        p = np.full(len(names), np.nan)
        for i in range(len(names)):
            a, b = a_all[:, i], b_all[:, i]
            a, b = a[np.isfinite(a)], b[np.isfinite(b)]
            if min(len(a), len(b)) < MIN_DEFINED:
                continue
            tests += 1
            same = a.min() == a.max() == b.min() == b.max()
            with warnings.catch_warnings():  # where the exact p-value fails, scipy's asymptotic one serves
                warnings.simplefilter("ignore", RuntimeWarning)
                p[i] = 1.0 if same else float(ks_2samp(a, b).pvalue)
        pvals[k] = p
    return Comparison(list(names), pvals, tests, ALPHA / max(tests, 1))
