"""How closely two implementations agree: largest differences, in absolute terms and in units of
float64 rounding (eps × the conditioning of the computation), for the side-by-side suites."""

from __future__ import annotations

import numpy as np

__all__ = ["EPS", "fir_agreement", "max_abs_diff"]

EPS = float(np.finfo(np.float64).eps)


def max_abs_diff(got: np.ndarray, want: np.ndarray) -> float:
    """Largest |got − want| over all elements (inf if either has a non-finite value where the other differs)."""
    got, want = np.asarray(got, np.float64), np.asarray(want, np.float64)
    if got.shape != want.shape:
        raise ValueError(f"shapes differ: {got.shape} vs {want.shape}")
    if not got.size:
        return 0.0
    same = (got == want) | (np.isnan(got) & np.isnan(want))
    d = np.where(same, 0.0, np.abs(got - want))
    return float(np.max(np.nan_to_num(d, nan=np.inf)))


def fir_agreement(got: np.ndarray, want: np.ndarray, coef: np.ndarray, x: np.ndarray, pos: int) -> dict:
    """Agreement of two outputs of the FIR ``y[i] = Σ_k coef[k]·x[i − pos + k]`` (zeros outside ``x``).

    Returns ``max_abs`` (largest |got − want|) and ``eps_units``: the largest |got − want| at an
    output divided by ``eps · Σ_k |coef[k]·x[i − pos + k]|``, that output's conditioning (the
    scale of the rounding error of the dot product: units to hundreds is rounding, in the
    output or in the coefficients; a different filter is ~1e10 and more). An output whose conditioning is 0 counts only if the outputs differ there
    (then ``eps_units`` is inf).
    """
    got, want, x = (np.asarray(a, np.float64) for a in (got, want, x))
    coef = np.asarray(coef, np.float64)
    n, m = len(x), len(coef)
    if got.shape != (n,) or want.shape != (n,):
        raise ValueError(f"need 1-D outputs as long as x ({n}); got {got.shape}, {want.shape}")
    if not 0 <= pos < m:
        raise ValueError(f"pos must be in [0, {m - 1}], got {pos}")
    padded = np.concatenate([np.zeros(pos), np.abs(x), np.zeros(m - 1 - pos)])
    cond = np.correlate(padded, np.abs(coef), "valid")  # cond[i] = Σ_k |c_k|·|x[i − pos + k]|
    diff = np.abs(got - want)
    with np.errstate(divide="ignore", invalid="ignore"):
        units = np.where(diff == 0, 0.0, diff / (EPS * cond))
    return {"max_abs": float(diff.max(initial=0.0)), "eps_units": float(units.max(initial=0.0))}
