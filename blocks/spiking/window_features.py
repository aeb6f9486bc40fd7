"""Features of a spike train in time windows: what the naive Bayes decoder and its trainer share.

``counts``: spikes per unit in each of ``n_bins`` equal sub-bins of the window (time-normalised, so
a window read slowly and one read fast put the same dot in the same sub-bin), flattened bin-major
(index ``b·n_units + u``). ``latency``: each unit's first spike after the window start as a fraction
of the window length, 1.0 when the unit is silent in the window. A window is ``[t0, t1)``.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

__all__ = ["window_features"]


def window_features(
    spike_t: np.ndarray,
    spike_i: np.ndarray,
    windows: np.ndarray,
    *,
    n_units: int,
    n_bins: int = 1,
    kind: Literal["counts", "latency"] = "counts",
) -> np.ndarray:
    """Feature rows of the windows ``(n, 2)`` [t0, t1) from spikes sorted by time → (n, F)."""
    spike_t = np.asarray(spike_t, np.float64)
    spike_i = np.asarray(spike_i, np.int64)
    windows = np.asarray(windows, np.float64).reshape(-1, 2)
    n_feat = n_units * n_bins if kind == "counts" else n_units
    out = np.zeros((len(windows), n_feat)) if kind == "counts" else np.ones((len(windows), n_feat))
    lo = np.searchsorted(spike_t, windows[:, 0], side="left")
    hi = np.searchsorted(spike_t, windows[:, 1], side="left")
    for w, (a, b) in enumerate(zip(lo, hi, strict=True)):
        if b <= a:
            continue
        t0, t1 = windows[w]
        frac = (spike_t[a:b] - t0) / (t1 - t0)
        units = spike_i[a:b]
        if kind == "counts":
            b_idx = np.minimum((frac * n_bins).astype(np.int64), n_bins - 1)
            out[w] = np.bincount(b_idx * n_units + units, minlength=n_feat)
        else:
            first = np.ones(n_units)
            np.minimum.at(first, units, frac)  # spikes come in time order; min keeps the first
            out[w] = first
    return out
