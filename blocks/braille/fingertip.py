"""The artificial fingertip: 24 capacitive taxels (6 × 4) under a neoprene cover, read over Braille dots.

Physics, from the dots to a reading (every length in mm):

1. **Height field.** Each dot is a paraboloid dome ``H·(1 − ρ²/R²)`` (:func:`cells.height_field`).
2. **Indentation.** The fingertip is pressed flat on the paper with a uniform compression
   ``press_mm``; a dot under it compresses the cover further by its height.
3. **Spread through the cover.** An elastic layer spreads a local indentation over about its own
   thickness: the compression reaching the electrodes is the surface one convolved with a
   Gaussian of sd ``σ = spread · cover_mm``.
4. **Taxel.** Each electrode averages that over its square (side ``taxel_mm``) and a fraction
   ``transmission`` of it closes the dielectric gap ``gap_mm``. A parallel-plate capacitor then
   changes by ``ΔC/C0 = u/(gap − u)`` (dimensionless, the reading's unit).

Averaging a Gaussian over a square is a product of two erf differences, so step 3–4 for one dot
is ``∫∫_dot h(p)·B(p_x − X)·B(p_y − Y) dp`` with ``B(z) = (erf((s/2 + z)/(√2σ)) + erf((s/2 − z)/
(√2σ))) / (2s)``; the integral over the dot's square is a tensor Gauss–Legendre rule (16 × 16
nodes; the dome's rim kink limits it to ~1e-3 relative, far below the sensor noise).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from .cells import Geometry

__all__ = ["COLS", "ROWS", "Fingertip", "taxel_offsets"]

#: Taxel rows (across the line, ±Y) and columns (along the scan, X).
ROWS, COLS = 6, 4
_NODES = 16


def taxel_offsets(pitch_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """x and y (mm) of each taxel from the fingertip's centre; taxel ``j = row·4 + col``, row 0 the
    top (+Y), column 0 the trailing one (−X: the finger moves towards +X)."""
    row, col = np.divmod(np.arange(ROWS * COLS), COLS)
    return (col - (COLS - 1) / 2) * pitch_mm, ((ROWS - 1) / 2 - row) * pitch_mm


@njit(cache=True)
def _box_gauss(z: float, half: float, k: float, inv2s: float) -> float:
    """Mean over [z − half, z + half] of a unit Gaussian (k = 1/(√2σ))."""
    return (math.erf((half + z) * k) + math.erf((half - z) * k)) * inv2s


@njit(cache=True)
def _compress(
    xf: np.ndarray,
    yf: np.ndarray,
    dots_x: np.ndarray,
    dots_y: np.ndarray,
    ox: np.ndarray,
    oy: np.ndarray,
    qx: np.ndarray,
    qw: np.ndarray,
    radius: float,
    heights: np.ndarray,
    half: float,
    sigmas: np.ndarray,
    reach: float,
) -> np.ndarray:
    """Mean compression (mm, above the uniform press) under each taxel, for each finger position
    (dot d of height ``heights[d]``; the cover's spread ``sigmas[i]`` at finger position i)."""
    n, m, q = len(xf), len(ox), len(qx)
    out = np.zeros((n, m))
    inv2s = 1.0 / (4.0 * half)
    bx = np.empty((q, m))
    by = np.empty((q, m))
    for i in range(n):
        k = 1.0 / (math.sqrt(2.0) * sigmas[i])
        # dots sorted by x: scan only the window [xf − reach, xf + reach]
        lo = np.searchsorted(dots_x, xf[i] - reach)
        hi = np.searchsorted(dots_x, xf[i] + reach)
        for d in range(lo, hi):
            if abs(dots_y[d] - yf[i]) > reach:
                continue
            for a in range(q):
                for j in range(m):
                    bx[a, j] = _box_gauss(dots_x[d] + qx[a] - xf[i] - ox[j], half, k, inv2s)
                    by[a, j] = _box_gauss(dots_y[d] + qx[a] - yf[i] - oy[j], half, k, inv2s)
            for a in range(q):
                for b in range(q):
                    rho2 = (qx[a] * qx[a] + qx[b] * qx[b]) / (radius * radius)
                    if rho2 >= 1.0:
                        continue
                    w = qw[a] * qw[b] * heights[d] * (1.0 - rho2)
                    for j in range(m):
                        out[i, j] += w * bx[a, j] * by[b, j]
    return out


@dataclass(frozen=True)
class Fingertip:
    """The sensor's constants (mm) and its reading of a line of dots at given finger positions."""

    geometry: Geometry
    taxel_mm: float = 1.6
    pitch_mm: float = 2.0
    cover_mm: float = 1.0
    spread: float = 0.6
    press_mm: float = 0.1
    transmission: float = 0.3
    gap_mm: float = 0.5

    @property
    def sigma_mm(self) -> float:
        return self.spread * self.cover_mm

    def compression(
        self,
        x: np.ndarray,
        y: np.ndarray,
        dots: np.ndarray,
        *,
        height_scale: np.ndarray | None = None,
        sigma_mm: np.ndarray | None = None,
        press_mm: np.ndarray | None = None,
    ) -> np.ndarray:
        """(n, 24) mean cover compression (mm) under each taxel, finger centre at (x[i], y[i]).

        The fingertip's variations, all optional (None: the nominal constant): ``height_scale``
        multiplies each dot's height (one per row of ``dots``), ``sigma_mm`` is the cover's spread
        at each finger position (its wear) and ``press_mm`` the uniform press there."""
        g = self.geometry
        order = np.argsort(dots[:, 0], kind="stable")
        dx = np.ascontiguousarray(dots[order, 0])
        dy = np.ascontiguousarray(dots[order, 1])
        heights = np.full(len(dots), g.dot_height)
        if height_scale is not None:
            heights = g.dot_height * np.asarray(height_scale, np.float64)
        sigmas = np.full(len(x), self.sigma_mm)
        if sigma_mm is not None:
            sigmas = np.asarray(sigma_mm, np.float64).reshape(len(x))
        ox, oy = taxel_offsets(self.pitch_mm)
        nodes, weights = np.polynomial.legendre.leggauss(_NODES)
        r = g.dot_radius
        widest = float(sigmas.max()) if len(sigmas) else self.sigma_mm
        reach = r + 0.5 * self.taxel_mm + 6.0 * widest + max(np.abs(ox).max(), np.abs(oy).max())
        out = _compress(
            np.ascontiguousarray(x, np.float64),
            np.ascontiguousarray(y, np.float64),
            dx,
            dy,
            ox.astype(np.float64),
            oy.astype(np.float64),
            nodes * r,
            weights * r,
            r,
            np.ascontiguousarray(heights[order]),
            0.5 * self.taxel_mm,
            np.ascontiguousarray(sigmas),
            reach,
        )
        if press_mm is None:
            return out + self.press_mm
        return out + np.asarray(press_mm, np.float64).reshape(len(x), 1)

    def reading(self, compression: np.ndarray) -> np.ndarray:
        """ΔC/C0 of a parallel-plate taxel whose gap closes by ``transmission · compression``."""
        u = self.transmission * compression
        return u / (self.gap_mm - u)
