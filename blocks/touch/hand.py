"""The whole hand's afferents: TouchSim's class densities over the hand's regions, one model each.

Why: graphs/hand.yaml runs ≈ 17 000 afferents; their per-afferent parameters (prefilter cut-off,
rectified gains, noise, saturation, membrane model) are lists of 17 000 values, so they live here
as presets (``preset: touch.hand``), computed from the numbers below, not written in the graph.

* Densities per cm² (palm / finger / fingertip): SA1 10 / 30 / 70, RA 25 / 40 / 140, PC 10 / 10 /
  25 — TouchSim's ``hand_density`` (touchsim/constants.py of the published code, Saal, Delhaye et
  al. 2017), used by its ``affpop_hand``.
* Region areas (cm², the glabrous skin TouchSim's hand outline covers): palm 120, fingers (middle
  and proximal phalanges) 85, fingertips (distal pads) 20. Assumed here, not read from TouchSim's
  ``hand.mat`` outlines, and chosen so that the total is the ≈ 17 000 afferents of the hand
  (Johansson & Vallbo 1979, the count TouchSim's paper uses).
* Models: each class cycles through its fitted models (SA1.0–3, RA.0–8, PC.0–3) in column order.
  Columns: every SA1, then every RA, then every PC.
* Stimulus: a synthetic ramp-and-hold (``touchsim_probe``) whose peaks per afferent are its class's
  development-set magnitudes (graphs/touchsim_afferents.yaml) scaled by 0.25–1.5 (an afferent's
  distance from the contact), a fixed low-discrepancy sequence, so the graph is reproducible.
"""

from __future__ import annotations

from functools import cache
from typing import Any

from flowtact.blocks.touch.touchsim import touchsim_models

__all__ = ["CLASSES", "DENSITY_PER_CM2", "REGION_AREA_CM2", "class_counts", "hand_models", "hand_presets"]

CLASSES = ("SA1", "RA", "PC")
#: TouchSim's ``hand_density``: afferents per cm² in (palm, finger, fingertip).
DENSITY_PER_CM2 = {"SA1": (10.0, 30.0, 70.0), "RA": (25.0, 40.0, 140.0), "PC": (10.0, 10.0, 25.0)}
#: Assumed glabrous areas of (palm, fingers, fingertips), cm².
REGION_AREA_CM2 = (120.0, 85.0, 20.0)
#: The class's (s, d) peak magnitudes on the development set's 0.3 mm ramp (touchsim_afferents.yaml).
PEAKS = {"SA1": (0.0128, 4.0), "RA": (0.0029, 0.14), "PC": (0.0019, 0.09)}
_GOLDEN = 0.6180339887498949


def class_counts() -> dict[str, int]:
    """Afferents per class: density × area summed over the regions."""
    return {
        c: round(sum(d * a for d, a in zip(DENSITY_PER_CM2[c], REGION_AREA_CM2, strict=True)))
        for c in CLASSES
    }


@cache
def hand_models() -> tuple[str, ...]:
    """One TouchSim model per column: each class's models in turn, classes in :data:`CLASSES` order."""
    names = list(touchsim_models())
    out: list[str] = []
    for c, n in class_counts().items():
        mine = [m for m in names if m.split(".")[0] == c]
        out += [mine[i % len(mine)] for i in range(n)]
    return tuple(out)


@cache
def hand_presets() -> dict[str, dict[str, Any]]:
    """The ``touch.hand`` preset of each block of graphs/hand.yaml (block name -> parameters)."""
    models = hand_models()
    p = [touchsim_models()[m] for m in models]
    col = lambda k: [q[k] for q in p]  # noqa: E731
    scale = [0.25 + 1.25 * ((i * _GOLDEN) % 1.0) for i in range(len(models))]
    cls = [m.split(".")[0] for m in models]
    cutoff = [10.0 * q[0] for q in p]
    return {
        "touchsim_probe": {
            "n": len(models),
            "s_peak": [PEAKS[c][0] * f for c, f in zip(cls, scale, strict=True)],
            "d_peak": [PEAKS[c][1] * f for c, f in zip(cls, scale, strict=True)],
            "repeat": True,
        },
        "iir": {"family": "butter", "order": 3, "cutoff_hz": cutoff},
        "rectified_gain": {
            "pos1": col(1),
            "neg1": col(2),
            "pos2": col(3),
            "neg2": col(4),
            "ahead": "x2",
            "ahead_pos": col(5),
            "ahead_neg": col(6),
            "saturation": col(7),
            "noise_sd": col(8),
        },
        "nlif": {"models": list(models)},
        "touchsim_chain": {"models": list(models)},
    }
