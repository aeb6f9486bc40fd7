"""TouchSim's 17 afferent models (Saal, Delhaye et al., PNAS 2017) as ``nlif`` presets.

The 13 fitted parameters of each model (SA1.0–3, RA.0–8, PC.0–3) ship in ``touchsim_models.json``
(copied from the published parameter file; the numbers are facts, no code of TouchSim's is used).
The neuron part of a model maps onto ``nlif`` exactly, at TouchSim's 5 kHz::

    V[n] = V[n−1] − V[n−1]/p9 + I[n] + H[n]      (explicit Euler in samples)
    →  integrator euler, tau_s = p9/5000, gain p9, v_leak 0, threshold 1

``H`` is the most recent spike's kernel only (``history: last``), ``p10·B0 + p11·B1`` on TouchSim's
basis: columns 0 and 3 of a 4-column raised-cosine basis, which in nlif's lag convention (lag k = k·dt
after the spike's step) is ``h_peaks_s [0.0002, 0.0082]``, ``h_offset_s 0.0008``, so
``h_weights = p9·[p10, 0, 0, p11]`` (nlif's drive is divided by p9 with tau). A spike needs ≥ 6 steps
since the last: ``threshold_block_s`` 1.2 ms (blocked for 5 steps). The current ``I`` (prefilter,
rectified gains p1–p6, noise p8 before saturation p7) is made by the stages before the neuron, so
``sigma`` is 0 here. Spikes: nlif stamps a spike with its input sample's time ``t[n] = n/fs``;
TouchSim stamps ``(n + 1)/fs``: the same sample index ``n``, one sample apart in seconds.
"""

from __future__ import annotations

import json
from functools import cache
from importlib.resources import files
from typing import Any

__all__ = ["TOUCHSIM_PRESETS", "TOUCHSIM_RATE_HZ", "nlif_params", "touchsim_models"]

#: TouchSim's sampling rate (its parameters τ = p9 are in samples of it).
TOUCHSIM_RATE_HZ = 5000.0


@cache
def touchsim_models() -> dict[str, tuple[float, ...]]:
    """The 13 parameters of each model, ``"SA1.0"`` … ``"PC.3"``, from the package's data file."""
    data = json.loads(files(__package__).joinpath("touchsim_models.json").read_text())
    return {name: tuple(float(x) for x in p) for name, p in data["models"].items()}


def nlif_params(p: tuple[float, ...]) -> dict[str, Any]:
    """The ``nlif`` parameters of the neuron part of the model with parameters ``p``."""
    tau = p[9]
    return {
        "integrator": "euler",
        "history": "last",
        "tau_s": tau / TOUCHSIM_RATE_HZ,
        "v_leak": 0.0,
        "gain": tau,
        "sigma": 0.0,
        "threshold": 1.0,
        "threshold_block_s": 6 / TOUCHSIM_RATE_HZ,
        "h_weights": (tau * p[10], 0.0, 0.0, tau * p[11]),
        "h_peaks_s": (1 / TOUCHSIM_RATE_HZ, 41 / TOUCHSIM_RATE_HZ),
        "h_offset_s": 4 / TOUCHSIM_RATE_HZ,
    }


#: ``nlif`` presets of the touch domain, one per TouchSim model: ``preset: touch.RA.3`` or
#: ``models: [SA1.0, RA.3, …]``.
TOUCHSIM_PRESETS: dict[str, dict[str, Any]] = {name: nlif_params(p) for name, p in touchsim_models().items()}
