"""Spike-train distances for the NLIF accuracy study: van Rossum distance, Kistler's coincidence
factor Γ and the spike-count (rate) error, on trains given as sorted spike times in seconds."""

from __future__ import annotations

import numpy as np

__all__ = ["coincidence_factor", "count_error", "split_by_neuron", "van_rossum_sq"]


def _kernel_sum(a: np.ndarray, b: np.ndarray, tau: float) -> float:
    """Σ_ij exp(−|a_i − b_j| / τ)."""
    if not len(a) or not len(b):
        return 0.0
    return float(np.exp(-np.abs(a[:, None] - b[None, :]) / tau).sum())


def van_rossum_sq(a: np.ndarray, b: np.ndarray, tau: float) -> float:
    """Squared van Rossum distance D² = (1/τ)∫(f − g)² dt, f and g the trains convolved with a
    causal exponential of time constant ``tau`` (van Rossum 2001), in closed form.

    One spike alone gives 1/2; two spikes δ apart give 1 − exp(−|δ|/τ) ≈ |δ|/τ.
    """
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    d2 = 0.5 * (_kernel_sum(a, a, tau) + _kernel_sum(b, b, tau)) - _kernel_sum(a, b, tau)
    return max(d2, 0.0)


def _coincidences(a: np.ndarray, b: np.ndarray, window: float) -> int:
    """Spikes of ``a`` paired one-to-one (greedy, in time order) with a spike of ``b`` within ±window."""
    i = j = n = 0
    while i < len(a) and j < len(b):
        d = a[i] - b[j]
        if abs(d) <= window:
            n, i, j = n + 1, i + 1, j + 1
        elif d > 0:
            j += 1
        else:
            i += 1
    return n


def coincidence_factor(ref: np.ndarray, model: np.ndarray, window: float, duration: float) -> float:
    """Kistler et al. (1997) coincidence factor Γ of ``model`` against ``ref`` (sorted times, s):
    Γ = (N_coinc − 2νΔN_ref) / (½(N_ref + N_model)) / (1 − 2νΔ), ν = N_model / duration.

    1 for identical trains, ≈ 0 for a Poisson train of the same rate; NaN when both are empty.
    """
    ref, model = np.asarray(ref, np.float64), np.asarray(model, np.float64)
    n_ref, n_mod = len(ref), len(model)
    if n_ref + n_mod == 0:
        return float("nan")
    nu = n_mod / duration
    expected = 2.0 * nu * window * n_ref
    norm = 1.0 - 2.0 * nu * window
    return (_coincidences(ref, model, window) - expected) / (0.5 * (n_ref + n_mod)) / norm


def count_error(ref_counts: np.ndarray, counts: np.ndarray) -> float:
    """Rate error: Σ_i |N_i − N_ref,i| / Σ_i N_ref,i over the neurons of a population (a fraction)."""
    ref_counts, counts = np.asarray(ref_counts), np.asarray(counts)
    total = ref_counts.sum()
    return float(np.abs(counts - ref_counts).sum() / total) if total else float("nan")


def split_by_neuron(times: np.ndarray, idx: np.ndarray, n: int) -> list[np.ndarray]:
    """A population's spikes (times, neuron indices) as one sorted train per neuron."""
    times, idx = np.asarray(times, np.float64), np.asarray(idx)
    return [np.sort(times[idx == k]) for k in range(n)]
