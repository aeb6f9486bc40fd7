"""Is every value of an array finite? The test every block's bad-data screen runs on every step.

A compiled loop for the small chunks of real-time steps: one call that stops at the first bad
value, against numpy's ``isfinite(a).all()`` (two calls, a temporary, a Python-level reduction)
that costs 3-8x more when a step runs with cold caches after a sleep. Large arrays (frames, long
``--fast`` chunks) keep numpy's vectorised test, which is faster per value.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["all_finite", "all_finite_kernel"]

COMPILED_MAX = 4096
"""Up to this many values the compiled loop is faster; above, numpy's vectorised test is."""


@njit(cache=True)
def all_finite_kernel(a: np.ndarray) -> bool:
    """The compiled loop itself: for other kernels, which call it inside their own pass."""
    for x in a.ravel():  # noqa: SIM110 (a loop numba compiles; stops at the first bad value)
        if not math.isfinite(x):
            return False
    return True


def all_finite(a: np.ndarray) -> bool:
    """True when no value of the float array ``a`` is NaN or ±inf (True for an empty array)."""
    if a.size <= COMPILED_MAX and a.dtype.char in "df":  # float64, float32: what numba compiles
        return bool(all_finite_kernel(a))
    return bool(np.isfinite(a).all())
