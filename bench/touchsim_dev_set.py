"""TouchSim's development set (68 traces made by TouchSim with noise off) as arrays, for the bench.

It ships in a source checkout as tests/data/touchsim_dev.npz (not in the wheel);
``FLOWTACT_TOUCHSIM_DEV`` names another copy.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["DevSet", "dev_set_path", "load_dev_set"]

CLASS_INDEX = {"SA1": 0, "RA": 1, "PC": 2}


@dataclass
class DevSet:
    """The traces ``STIM|CLASS|IDX`` in sorted order; s, d, I are samples × traces (5 kHz)."""

    names: list[str]
    s: np.ndarray
    d: np.ndarray
    current: np.ndarray
    spikes: list[np.ndarray]

    @property
    def models(self) -> list[str]:
        """Each trace's model, ``"SA1.0"`` … ``"PC.3"``."""
        return [".".join(n.split("|")[1:]) for n in self.names]

    @property
    def cls(self) -> np.ndarray:
        """TouchSim's class index of each trace (0 SA1, 1 RA, 2 PC)."""
        return np.array([CLASS_INDEX[n.split("|")[1]] for n in self.names])

    @property
    def idx(self) -> np.ndarray:
        """The model's index within its class."""
        return np.array([int(n.split("|")[2]) for n in self.names])


def dev_set_path() -> Path | None:
    """``FLOWTACT_TOUCHSIM_DEV``, else the checkout's tests/data/touchsim_dev.npz; None if absent."""
    env = os.environ.get("FLOWTACT_TOUCHSIM_DEV")
    path = Path(env) if env else Path(__file__).resolve().parents[1] / "tests" / "data" / "touchsim_dev.npz"
    return path if path.is_file() else None


def load_dev_set(path: Path) -> DevSet:
    """The 68 traces of ``path``."""
    with np.load(path) as z:
        names = sorted({k.rsplit("|", 1)[0] for k in z.files})
        col = lambda f: np.stack([z[f"{n}|{f}"] for n in names], axis=1)  # noqa: E731
        return DevSet(names, col("s"), col("d"), col("I"), [z[f"{n}|spk"] for n in names])
