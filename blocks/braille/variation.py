"""How a robot's fingertip varies from trial to trial and within one: the draws and the slow drifts.

``braille_scan`` reads a line in *trials* of ``trial_cells`` cells (the robot placing its finger
afresh on a stretch of text). Each trial draws its own press offset, lateral offset and yaw of the
line, and sensor gain; within a trial the press and the gain drift slowly (Ornstein–Uhlenbeck
processes of correlation time ``drift_tau_s``), the actual speed jitters around the command
(another, faster one), and the cover wears (its spread grows with the distance slid). Each dot's
height is drawn once, uniformly within a tolerance. Every draw comes from the node's seed.

Everything here is pure numpy on given generators: :class:`Trials` (the per-trial draws and their
lookup by finger position), :func:`dot_scales`, :class:`Drift` (one exact OU step per sample).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["CONDITION_LABELS", "ROBOT", "Drift", "Trials", "dot_scales"]

#: The ``conditions`` output's channels (stream units mm; a suffix names another unit).
CONDITION_LABELS = ("press", "lateral", "spread", "dot_scale_1", "yaw_deg", "gain_1")

#: The calibrated variation graphs/braille_open.yaml and graphs/braille.yaml turn on (docs/braille.md,
#: "A fingertip that varies"); a test checks both graphs hold exactly these.
ROBOT: dict[str, float | int] = {
    "trial_cells": 1,
    "press_sd_mm": 0.03,
    "press_drift_mm": 0.02,
    "drift_tau_s": 2.0,
    "dot_height_min": 1.0,
    "dot_height_max": 1.4,
    "lateral_sd_mm": 0.8,
    "yaw_sd_deg": 2.0,
    "speed_jitter": 0.05,
    "speed_jitter_tau_s": 0.1,
    "gain_sd": 0.1,
    "gain_drift": 0.05,
    "wear_per_m": 0.1,
    "cover_tau_s": 0.03,
}


def dot_scales(rng: np.random.Generator, n_dots: int, lo: float, hi: float) -> np.ndarray:
    """Each dot's height as a factor of the nominal one, uniform in [lo, hi] (all ``lo`` when equal)."""
    if hi == lo:
        return np.full(n_dots, lo)
    return rng.uniform(lo, hi, n_dots)


@dataclass(frozen=True)
class Trials:
    """Per-trial draws: trial k covers cells [k·cells, (k + 1)·cells) (all cells when ``cells`` is 0)."""

    cells: int
    cell_pitch: float
    press: np.ndarray
    lateral: np.ndarray
    yaw_rad: np.ndarray
    log_gain: np.ndarray

    @classmethod
    def draw(
        cls,
        rng: np.random.Generator,
        n_cells: int,
        cells: int,
        cell_pitch: float,
        press_sd: float,
        lateral_sd: float,
        yaw_sd_deg: float,
        gain_sd: float,
    ) -> Trials:
        """Independent normal draws per trial, in a fixed order (press, lateral, yaw, gain), each
        drawn even when its sd is 0 (giving zeros), so turning one variation off leaves the others'
        draws as they were."""
        n = max(math.ceil(n_cells / cells), 1) if cells else 1

        def normal(sd: float) -> np.ndarray:
            return rng.standard_normal(n) * sd

        press, lateral = normal(press_sd), normal(lateral_sd)
        yaw = normal(math.radians(yaw_sd_deg))
        return cls(cells, cell_pitch, press, lateral, yaw, normal(gain_sd))

    def index(self, x: float) -> int:
        """The trial the finger centre at ``x`` reads (before the line: the first; after it: the last)."""
        if not self.cells:
            return 0
        k = math.floor(x / self.cell_pitch) // self.cells
        return min(max(k, 0), len(self.press) - 1)

    def start(self, k: int) -> float:
        """x (mm) where trial k begins: the line's yaw turns it about this point."""
        return k * self.cells * self.cell_pitch

    def line_y(self, k: int, x: float) -> float:
        """y (mm) of the line's middle dot row under the finger at ``x`` in trial k."""
        return float(self.lateral[k] + (x - self.start(k)) * math.tan(self.yaw_rad[k]))


class Drift:
    """A stationary Ornstein–Uhlenbeck process of sd ``sd`` and correlation time ``tau_s``, sampled
    every ``dt`` exactly: ``z_i = a·z_{i−1} + sd·√(1 − a²)·ε_i``, ``a = e^{−dt/τ}``; ``z_0 = sd·ε_0``."""

    def __init__(self, sd: float, tau_s: float, dt: float) -> None:
        self.sd = sd
        self.a = math.exp(-dt / tau_s)
        self.b = sd * math.sqrt(1.0 - self.a * self.a)
        self.z: float | None = None

    def step(self, eps: float) -> float:
        """The next value from one standard normal draw."""
        self.z = self.sd * eps if self.z is None else self.a * self.z + self.b * eps
        return self.z
