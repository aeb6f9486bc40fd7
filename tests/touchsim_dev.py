"""TouchSim's development set for the tests of its stages (read by the one loader,
flowtact.bench.touchsim_dev_set, from its one copy, tests/data/touchsim_dev.npz), TouchSim's
post-spike basis, and the error bound of scipy's (b, a) filtering that every comparison with
TouchSim's own numbers inherits."""

from functools import cache
from pathlib import Path

import numpy as np

from flowtact.bench.touchsim_dev_set import CHECKOUT_COPY, DevSet, load_dev_set

IHBASIS = Path(__file__).parent / "data" / "touchsim_ihbasis.npz"
"""TouchSim's post-spike basis ``ihbasis`` (2 × 190 taps at 5 kHz, /work/shared/touchsim/README.md)."""
EPS = np.finfo(np.float64).eps


@cache
def dev_set() -> DevSet:
    """The checkout's copy (never FLOWTACT_TOUCHSIM_DEV: the tests check against this one), read once."""
    return load_dev_set(CHECKOUT_COPY)


def touchsim_traces() -> list[tuple[str, dict[str, np.ndarray]]]:
    """The 68 traces ``STIM|CLASS|IDX`` -> {s, d, I, p, spk}, sorted."""
    dev = dev_set()
    return [(name, dev.trace(name)) for name in dev.names]


def ba_error_bound(b: np.ndarray, a: np.ndarray, x: np.ndarray, y: np.ndarray) -> float:
    """A float64 error bound for ``lfilter(b, a, x)`` (output ``y``) against the exact filter.

    The rounding of each step's products and sums (≤ (len(b)+len(a))·ε·(Σ|b|·max|x| + Σ|a|·max|y|))
    and of the coefficients themselves (ε·|a_k|, ε·|b_k|: the same sums) enter the recursion as a
    per-step error that the all-pole part 1/A(z) amplifies by at most ‖g‖₁ (g its impulse
    response): the direct form at a low cut-off is ill-conditioned exactly through ‖g‖₁ (thousands
    here). Our sos form's own error is far below it, so it bounds |ours − scipy's ba| too.
    """
    from scipy import signal

    imp = np.zeros(20000)
    imp[0] = 1.0
    g1 = np.abs(signal.lfilter([1.0], a, imp)).sum()
    per_step = (
        (len(b) + len(a) + 2) * EPS * (np.abs(b).sum() * np.abs(x).max() + np.abs(a).sum() * np.abs(y).max())
    )
    return float(2 * g1 * per_step)


def prefilter_bound(key: str, tr: dict[str, np.ndarray]) -> float:
    """How far any correct float64 prefilter + weighting may put I from another's: each filtered
    input's bound times the gains it meets (Δd counts d's error twice)."""
    from scipy import signal

    p = tr["p"]
    b, a = signal.butter(3, 0.004 * p[0])
    bd = ba_error_bound(b, a, tr["d"], signal.lfilter(b, a, tr["d"]))
    out = bd * (abs(p[3]) + abs(p[4]) + 2 * (abs(p[5]) + abs(p[6])))
    if key.split("|")[1] == "SA1":
        out += ba_error_bound(b, a, tr["s"], signal.lfilter(b, a, tr["s"])) * (abs(p[1]) + abs(p[2]))
    return out
