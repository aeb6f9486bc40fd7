"""Write graphs/touchsim_currents.npz: the synthetic input current the shipped graph
graphs/touchsim_currents.yaml plays when no --replay is given.

One column per TouchSim model (SA1.0–3, RA.0–8, PC.0–3, the graph's ``models:`` order), 0.5 s at
5 kHz: a 20 Hz rectified-sine current (40 bumps/s) ramped in over 0.1 s, scaled per class to the size of
TouchSim's currents on the development set's 50 Hz sine (SA1 ~0.03, RA ~0.15, PC ~3), so that every
model fires. Arrays ``t`` (s) and ``y`` (samples × afferents), the layout ``--replay current=FILE.npz``
expects.

    python scripts/touchsim_synthetic_current.py
"""

from pathlib import Path

import numpy as np

FS = 5000.0
MODELS = [f"SA1.{i}" for i in range(4)] + [f"RA.{i}" for i in range(9)] + [f"PC.{i}" for i in range(4)]
SCALE = {"SA1": 0.08, "RA": 0.3, "PC": 6.0}


def synthetic_current(duration_s: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(round(duration_s * FS)) / FS
    wave = np.abs(np.sin(2 * np.pi * 20 * t)) * np.minimum(t / 0.1, 1.0)
    amp = np.array([SCALE[m.split(".")[0]] for m in MODELS])
    return t, np.ascontiguousarray(wave[:, None] * amp[None, :])


if __name__ == "__main__":
    out = Path(__file__).resolve().parent.parent / "graphs" / "touchsim_currents.npz"
    t, y = synthetic_current()
    np.savez_compressed(out, t=t, y=y)
    print(f"wrote {out} ({len(t)} samples x {y.shape[1]} afferents)")
