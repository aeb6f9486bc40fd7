"""Nominal constants of the gold-nanoparticle (AuNP) strain-gauge sensor of Rager et al.

Shared by the synthetic sensor (which turns forces into gauge signals) and the calibration
blocks (which turn them back), so that the default graph recovers the true force.
Gauge layout (eq. 2): gauges 1 and 3 lie on the x axis, 2 and 4 on the y axis, so
Fx = (r3 − r1)/Xs, Fy = (r2 − r4)/Ys, Fz = (r1 + r2 + r3 + r4)/Zs.
The paper gives no sensitivities; these are order-of-magnitude values for AuNP gauges (relative
resistance change of a few percent per newton) and only set the scale of the gauge signals.
"""

from __future__ import annotations

__all__ = ["SENSITIVITY_PER_N", "reduced_matrix"]

#: (Xs, Ys, Zs): relative resistance change ΔR/R per newton in eq. 2.
SENSITIVITY_PER_N: tuple[float, float, float] = (0.02, 0.02, 0.04)


def reduced_matrix(xs: float, ys: float, zs: float) -> tuple[tuple[float, ...], ...]:
    """Eq. 2 written as the 3×4 matrix A of eq. 1 (F = A·r)."""
    return (
        (-1.0 / xs, 0.0, 1.0 / xs, 0.0),
        (0.0, 1.0 / ys, 0.0, -1.0 / ys),
        (1.0 / zs, 1.0 / zs, 1.0 / zs, 1.0 / zs),
    )
