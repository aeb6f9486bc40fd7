"""Neuron and synapse parameters of the Braille pathway (Bologna et al. 2013), tuned here.

The paper models 24 first-order SA-I-like neurons (one per taxel) and 49 second-order cuneate
neurons, each sampling 1 to 3 adjacent afferents; it does not print membrane constants, so these
are documented choices (docs/braille.md, "Tuning", and scripts/braille_discrimination.py measure
them):

* ``afferent`` (nlif on each taxel's ΔC/C0 at 250 Hz): gain 30, v_leak −2 put the threshold at
  ΔC/C0 = 0.1, 3.6 sensor-noise sd above blank paper (0.064) and well below a centred dot (~0.32,
  v∞ ≈ 7); τ 10 ms; σ 1 /√s; refractory 8 ms (≤ 125 spikes/s on the 4 ms grid: never saturated at
  the sampling rate); a mild post-spike current slowing sustained firing. One dot at 30 mm/s:
  ~8 spikes from the best-placed afferent.
* ``cuneate`` (nlif on the synapse currents): a secure relay, as cuneate neurons are for their
  strong afferent inputs (a single afferent impulse fires the target: Zachariah et al. 2001,
  J. Neurophysiol. 86:900; Bengtsson et al. 2013, PLoS One 8:e56630). Gain 4, v_leak 0, τ 10 ms:
  one afferent spike (a current of 1) lifts v by 4·(1 − e^(−0.4)) = 1.32 in one 4 ms step, over
  the threshold of 1 by 6 noise sd (σ 1 /√s) — the smallest whole gain that does (3 gives 0.99);
  refractory 8 ms, like the afferents, so a train of one afferent passes spike for spike. The
  measurement (docs/braille.md, "The second-order layer") found the old setting (gain
  1, τ_syn 10 ms: 2 afferent spikes 8 ms apart fired nothing, 4 at 80 spikes/s one) silenced most 1–2-spike responses.
* ``synapse`` ``cuneate``: each of 49 targets samples 1–3 adjacent taxels on the 6 × 4 grid
  (the paper's rule), ``connect_seed`` 13 (fixed, so the connectivity does not change with the
  graph's seed; its 49 × 24 matrix has rank 24); τ_syn 4 ms, one clock tick, so a spike's current
  has decayed to e^(−2) when the refractory period ends and never fires the target twice.
"""

from __future__ import annotations

from typing import Any

__all__ = ["AFFERENT", "CUNEATE", "CUNEATE_SYNAPSE", "PRESETS"]

AFFERENT: dict[str, Any] = {
    "n": 24,
    "tau_s": 0.01,
    "v_leak": -2.0,
    "gain": 30.0,
    "sigma": 1.0,
    "refractory_s": 0.008,
    "integrator": "exp",
    "h_weights": (0.0, -0.3, -0.3, -0.2),
    "h_peaks_s": (0.004, 0.1),
    "h_offset_s": 0.005,
}

CUNEATE: dict[str, Any] = {
    "n": 49,
    "tau_s": 0.01,
    "v_leak": 0.0,
    "gain": 4.0,
    "sigma": 1.0,
    "refractory_s": 0.008,
    "integrator": "exp",
}

CUNEATE_SYNAPSE: dict[str, Any] = {
    "rate_hz": 250.0,
    "tau_s": 0.004,
    "grid": (6, 4),
    "n_targets": 49,
    "fan_in": (1, 3),
    "weight": 1.0,
    "connect_seed": 13,
}

#: This domain's presets, published through the ``flowtact.presets`` entry point ``braille``.
PRESETS: dict[str, dict[str, dict[str, Any]]] = {
    "nlif": {"afferent": AFFERENT, "cuneate": CUNEATE},
    "synapse": {"cuneate": CUNEATE_SYNAPSE},
}
