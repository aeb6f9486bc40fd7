"""Rager et al.'s afferent model weights (Table I), the single source of these numbers.

The drive of a population is ``I = w1..3 · [Fx, Fy, Fz] + w4..6 · F' + w7..9 · F''`` with forces
in newtons, first derivatives in N/s and second derivatives in N/s² (derivatives taken with the
sampling interval in seconds). The paper does not state the derivative units; the tiny first-
derivative weights (|w| ≈ 1e-3 … 2e-2) only give a drive comparable to the force terms with
derivatives per second, so that is the convention, decided once here.

FA1's w5 is printed as "−9.912e4"; read as −9.912e-4 (a drive 10⁸ times larger than every other
term is not a fitted weight, and the neighbouring weights are all O(1e-3)).
The second-derivative weights w7..w9 are zero for both populations, so a graph built on these
weights never needs F'' (the compiler prunes it).
"""

from __future__ import annotations

__all__ = ["TABLE_I", "table_i_weights"]

#: (w1 … w9) per population: Fx, Fy, Fz, Fx', Fy', Fz', Fx'', Fy'', Fz''.
TABLE_I: dict[str, tuple[float, ...]] = {
    "SA1": (0.405, 8.908, 0.382, -0.001, 0.001, 5.422e-4, 0.0, 0.0, 0.0),
    "FA1": (1.417, 2.359, 0.452, -0.012, -9.912e-4, 0.024, 0.0, 0.0, 0.0),
}


def table_i_weights(population: str) -> tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]:
    """Table I weights of ``population`` split per input: (force, first, second derivative)."""
    w = TABLE_I[population]
    return w[0:3], w[3:6], w[6:9]
