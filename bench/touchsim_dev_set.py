"""TouchSim's development set (68 traces made by TouchSim with noise off) as arrays: the one loader
of it, for the bench, the scripts and the tests.

It ships in a source checkout as tests/data/touchsim_dev.npz (not in the wheel: 4.8 MB), the only
copy; ``FLOWTACT_TOUCHSIM_DEV`` names another. Per trace ``STIM|CLASS|IDX`` it holds TouchSim's
inputs ``s`` and ``d``, its current ``I``, its spikes ``spk`` as sample indices (spike time × 5000
− 1) and the model's parameters ``p`` (p0 … p12).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["CHECKOUT_COPY", "DevSet", "dev_set_path", "load_dev_set"]

CLASS_INDEX = {"SA1": 0, "RA": 1, "PC": 2}


@dataclass
class DevSet:
    """The traces ``STIM|CLASS|IDX`` in sorted order; s, d, I are samples × traces (5 kHz), spikes
    TouchSim's sample indices per trace, params its model's p0 … p12 per trace (traces × 13)."""

    names: list[str]
    s: np.ndarray
    d: np.ndarray
    current: np.ndarray
    spikes: list[np.ndarray]
    params: np.ndarray

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

    def trace(self, name: str) -> dict[str, np.ndarray]:
        """One trace's arrays by their names in the file: ``s``, ``d``, ``I``, ``p``, ``spk``."""
        k = self.names.index(name)
        return {
            "s": self.s[:, k],
            "d": self.d[:, k],
            "I": self.current[:, k],
            "p": self.params[k],
            "spk": self.spikes[k],
        }


CHECKOUT_COPY = Path(__file__).resolve().parents[1] / "tests" / "data" / "touchsim_dev.npz"
"""Where a source checkout (an editable install) holds the set."""


def dev_set_path() -> Path | None:
    """``FLOWTACT_TOUCHSIM_DEV``, else the checkout's tests/data/touchsim_dev.npz; None if absent."""
    env = os.environ.get("FLOWTACT_TOUCHSIM_DEV")
    path = Path(env) if env else CHECKOUT_COPY
    return path if path.is_file() else None


def load_dev_set(path: Path) -> DevSet:
    """The 68 traces of ``path``."""
    with np.load(path) as z:
        names = sorted({k.rsplit("|", 1)[0] for k in z.files})
        col = lambda f: np.stack([z[f"{n}|{f}"] for n in names], axis=1)  # noqa: E731
        spikes = [z[f"{n}|spk"] for n in names]
        return DevSet(names, col("s"), col("d"), col("I"), spikes, np.stack([z[f"{n}|p"] for n in names]))
