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

``NEURON_PRESETS`` holds the parameters of the ``nlif`` block per population. The paper fits τ,
V_leak, σ and h by maximum likelihood but does not print them, so these are documented choices, to
be tuned against the touch/slip scenarios (change the values, keep the structure: one flat dict of
``nlif`` parameter values per population; explicit ``nlif`` parameters override them):

Values tuned (phase 2) so that the touch and slip trials of the synthetic sensor (``aunp_sensor``,
defaults) → ``gauge_force`` → ``savgol`` (5/4, centred) → ``weighted_sum`` (Table I) → ``nlif``
reproduce Fig. 4's behaviour (tests/test_rager_behaviour.py). The Table I drives on that touch:
SA1 0.046 at rest (0.12 N), 0.19 on the plateau; FA1 0.054 at rest, 0.37 on the plateau (its large
static weights on Fx and Fz), peaks 0.85 / 1.09 at onset / offset (force-derivative terms).

* ``tau_s`` 10 ms (SA1) / 5 ms (FA1): membrane constants of fitted GLM/LIF afferent models are in
  the 5–20 ms range; FA1's shorter one keeps the 5–10 ms derivative transients of a touch from
  being averaged away (at 8 ms the onset transient no longer reaches threshold). dt/τ ≥ 0.1 at 1 kHz.
* ``v_leak`` + ``gain`` place the threshold on the drive axis (v∞ = v_leak + gain·I = 1 at
  I = (1 − v_leak)/gain). SA1: ``gain`` 30, ``v_leak`` −0.8 → threshold at I = 0.06, just above the
  0.12 N holding force (v∞ 0.58 at rest: silent, 4 noise sd below threshold) and far below the
  touch plateau (v∞ 4.8 → sustained firing, ~50 spikes/s once adapted). FA1: ``gain`` 5,
  ``v_leak`` −1.5 → threshold at I = 0.5, above the plateau's 0.37 (v∞ 0.35: silent on a held
  touch, 9 noise sd below threshold) and below the onset/offset transients: FA1 fires only on
  changes, as Table I's large static weights would otherwise make it fire on every plateau.
* ``sigma`` 1.5 /√s: stationary membrane sd σ·sqrt(τ/2) ≈ 0.11 (SA1) / 0.075 (FA1): the population
  is not phase-locked, without spontaneous firing at rest.
* ``refractory_s`` 3.5 ms: enforces the paper's "rates ≤ 300 spikes/s" in the model itself
  (≤ 1/3.5 ms = 285 spikes/s continuous, ≤ 250 spikes/s on a 1 kHz grid), whatever the drive.
* post-spike current (raised-cosine basis, peaks 2 … 50 ms, offset 5 ms, support ≈ 140 ms). SA1:
  weights (0, 0, −0.5, −0.5) act only at lags ≳ 15 ms, so they do not limit the first spikes but
  build up over a burst: slow adaptation, ~100 spikes/s in the first 40 ms of a touch falling to
  ~50 spikes/s on the plateau (the "extra activity at onset" of Fig. 4; Table I's SA1 derivative
  weights are too small to give it). FA1: strong (−1.5, −1.0, −0.6, −0.3): one spike per neuron per
  transient.
* ``integrator`` ``exp`` (exact for input held over the 1 ms sample, unconditionally stable).
"""

from __future__ import annotations

from typing import Any

from flowtact.blocks.touch.hand import hand_presets
from flowtact.blocks.touch.touchsim import TOUCHSIM_PRESETS

__all__ = ["NEURON_PRESETS", "PRESETS", "TABLE_I", "table_i_weights"]

#: (w1 … w9) per population: Fx, Fy, Fz, Fx', Fy', Fz', Fx'', Fy'', Fz''.
TABLE_I: dict[str, tuple[float, ...]] = {
    "SA1": (0.405, 8.908, 0.382, -0.001, 0.001, 5.422e-4, 0.0, 0.0, 0.0),
    "FA1": (1.417, 2.359, 0.452, -0.012, -9.912e-4, 0.024, 0.0, 0.0, 0.0),
}


def table_i_weights(population: str) -> tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]:
    """Table I weights of ``population`` split per input: (force, first, second derivative)."""
    w = TABLE_I[population]
    return w[0:3], w[3:6], w[6:9]


def rectified_table_i(population: str) -> dict[str, Any]:
    """``rectified_gain`` parameters of Table I on magnitudes: per axis ``w·|F| + w'·|F'|``.

    x1 = F (N), x2 = F' (N/s); a gain g on both the positive and the negative part is g·|x|. The
    three per-axis outputs are then summed (``weighted_sum`` with ``w1: [1, 1, 1]``) into the drive.
    """
    (f1, f2, f3), (d1, d2, d3), _ = table_i_weights(population)
    return {"pos1": (f1, f2, f3), "neg1": (f1, f2, f3), "pos2": (d1, d2, d3), "neg2": (d1, d2, d3)}


#: ``nlif`` parameter values per population (see the module docstring for each choice).
NEURON_PRESETS: dict[str, dict[str, Any]] = {
    "SA1": {
        "tau_s": 0.010,
        "v_leak": -0.8,
        "gain": 30.0,
        "sigma": 1.5,
        "refractory_s": 0.0035,
        "integrator": "exp",
        "h_weights": (0.0, 0.0, -0.5, -0.5),
        "h_peaks_s": (0.002, 0.05),
        "h_offset_s": 0.005,
    },
    "FA1": {
        "tau_s": 0.005,
        "v_leak": -1.5,
        "gain": 5.0,
        "sigma": 1.5,
        "refractory_s": 0.0035,
        "integrator": "exp",
        "h_weights": (-1.5, -1.0, -0.6, -0.3),
        "h_peaks_s": (0.002, 0.05),
        "h_offset_s": 0.005,
    },
}


#: This domain's presets, published through the ``flowtact.presets`` entry point ``touch``: a graph
#: writes ``preset: touch.SA1`` (explicit parameters override the preset's values).
PRESETS: dict[str, dict[str, dict[str, Any]]] = {
    "savgol": {"rager": {"window": 5, "order": 4}},  # Fig. 3: 4th order over a frame of 5 samples
    "weighted_sum": {
        pop: {
            "w1": table_i_weights(pop)[0],
            "w2": table_i_weights(pop)[1],
            "w3": table_i_weights(pop)[2],
            "expect_units": ("N", "N/s", "N/s^2"),  # the convention the weights are read in (above)
        }
        for pop in TABLE_I
    },
    "nlif": {**NEURON_PRESETS, **TOUCHSIM_PRESETS},  # Rager's SA1/FA1, TouchSim's SA1.0 … PC.3
    "rectified_gain": {f"{pop}.rectified": rectified_table_i(pop) for pop in TABLE_I},
}

for _block, _params in hand_presets().items():  # the whole hand's ≈ 17 000 afferents (touch.hand)
    PRESETS.setdefault(_block, {})["hand"] = _params
