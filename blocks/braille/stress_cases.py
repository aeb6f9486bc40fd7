"""Numerical stress cases for ``braille_scan``: hostile speed and lateral commands (NaN, inf, 0, < 0, huge).

Each function runs the real block and returns a :class:`flowtact.verify.stress.Outcome`; ``CASES`` lists
them for the tests (tests/blocks/braille/test_scan_stress.py), the outcome table
(scripts/stress_outcomes.py) and the benchmark suite.
"""

from __future__ import annotations

from functools import partial

import numpy as np

import flowtact.api as ft
from flowtact.testing import run_source
from flowtact.verify.stress import Outcome, StressCase

from .controller_stress import CASES as CONTROLLER_STRESS
from .scan import BrailleScan

__all__ = ["CASES"]

RATE = 250.0
N = 500  # 2 s of commands at the scan's rate


def _scan(speed: np.ndarray, lateral: np.ndarray | None = None, **params: object) -> tuple[dict, BrailleScan]:
    blk = BrailleScan(text="abc", rate_hz=RATE, **params)  # type: ignore[arg-type]
    inputs = {"speed": speed} if lateral is None else {"speed": speed, "lateral": lateral}
    units = {"speed": "mm/s", "lateral": "mm"}
    out = run_source(blk, N / RATE, tick_s=0.04, inputs=inputs, rate_hz=RATE, units=units)
    return out, blk


def _steps(out: dict) -> np.ndarray:
    """Speeds the finger actually moved at, from its positions (mm/s)."""
    return np.diff(out["position"].data) * RATE


def speed_value(value: float) -> Outcome:
    """A speed command of ``value`` (0, negative, huge, ±inf with on_bad_data: hold) from t = 0.4 s."""
    speed = np.full(N, 30.0)
    speed[100:] = value
    finite = np.isfinite(value)
    out, blk = _scan(speed, **({} if finite else {"on_bad_data": "hold"}))
    v = _steps(out)
    late = v[101:]  # moves from sample 101 on use the command stamped at sample 100
    lo, hi = blk.config.min_speed_mm_s, blk.config.max_speed_mm_s
    want = min(max(value, lo), hi) if finite else 30.0
    ok = bool(np.allclose(late, want, rtol=1e-9)) and bool(np.isfinite(out["taxels"].data).all())
    counted = blk.counters.get("speed_clamped" if finite else "nonfinite_hold", 0)
    ok = ok and counted == (N - 100 if (finite and not lo <= value <= hi) or not finite else 0)
    return Outcome(
        f"speed_{value:g}", "braille_scan", f"speed command {value:g} mm/s from t = 0.4 s"
        + ("" if finite else " (on_bad_data: hold)"),
        f"finger moves at {late.min():g}..{late.max():g} mm/s, counted {counted}",
        f"clamped into [{lo:g}, {hi:g}] mm/s (non-finite: the last finite command held), counted, "
        "taxels finite", ok, f"expected {want:g} mm/s",
        {"v_min": float(late.min()), "v_max": float(late.max()), "counted": float(counted)},
    )  # fmt: skip


def speed_nan_raises() -> Outcome:
    """NaN speed with the default policy: the run stops with one line naming node and port."""
    speed = np.full(N, 30.0)
    speed[50] = np.nan
    try:
        _scan(speed)
    except ft.BadDataError as e:
        msg = str(e)
        ok = "'speed'" in msg and "\n" not in msg
        return Outcome("speed_nan_raise", "braille_scan", "one NaN speed, on_bad_data: raise",
                       f"stopped: “{msg}”", "one-line error naming the port", ok)  # fmt: skip
    return Outcome("speed_nan_raise", "braille_scan", "one NaN speed", "ran on", "stopped", False)


def speed_nan_dropped() -> Outcome:
    """NaN speeds dropped: the previous command stays in force."""
    speed = np.full(N, 30.0)
    speed[100:] = 60.0
    speed[150:200] = np.nan
    out, blk = _scan(speed, on_bad_data="drop")
    v = _steps(out)
    ok = bool(np.allclose(v[101:], 60.0, rtol=1e-9)) and blk.counters.get("nonfinite_drop") == 50
    return Outcome("speed_nan_drop", "braille_scan", "50 NaN speeds among 60 mm/s, on_bad_data: drop",
                   f"speed stays {v[101:].min():g}..{v[101:].max():g} mm/s",
                   "previous command kept, NaNs counted", ok)  # fmt: skip


def lateral_huge() -> Outcome:
    """Lateral corrections of ±1e300 mm and inf: clamped to ±max_lateral_mm (inf held)."""
    lateral = np.zeros(N)
    lateral[100:200] = 1e300
    lateral[200:300] = -1e300
    lateral[300:] = np.inf
    out, blk = _scan(np.full(N, 30.0), lateral, on_bad_data="hold")
    y = out["y"].data
    cap = blk.config.max_lateral_mm
    ok = (
        bool(np.all(np.abs(y) <= cap))
        and y[150] == cap
        and y[250] == -cap
        and bool(np.isfinite(out["taxels"].data).all())
        and blk.counters.get("lateral_clamped") == 200
    )
    return Outcome("lateral_huge", "braille_scan", "lateral ±1e300 mm then inf (hold)",
                   f"y within [{y.min():g}, {y.max():g}] mm", f"|y| ≤ max_lateral_mm = {cap:g}, counted", ok)  # fmt: skip


CASES: tuple[StressCase, ...] = (
    *(StressCase(f"speed_{v:g}", "braille_scan", partial(speed_value, v)) for v in (0.0, -30.0, 1e300, np.inf, -np.inf)),
    StressCase("speed_nan_raise", "braille_scan", speed_nan_raises),
    StressCase("speed_nan_drop", "braille_scan", speed_nan_dropped),
    StressCase("lateral_huge", "braille_scan", lateral_huge),
    *CONTROLLER_STRESS,  # the room's other blocks (controller_stress.py)
)  # fmt: skip
