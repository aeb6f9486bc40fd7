"""Timing one callable: warm-up calls, then repeats, every raw sample kept (the one timing helper of the suites)."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["Spread", "spread", "time_call", "time_paired"]


@dataclass(frozen=True)
class Spread:
    """Median, quartiles and extremes of a set of samples."""

    median: float
    q1: float
    q3: float
    min: float
    max: float
    n: int


def spread(samples: list[float] | np.ndarray) -> Spread:
    """The :class:`Spread` of ``samples`` (NaN everywhere for no samples)."""
    a = np.asarray(samples, dtype=float)
    if not a.size:
        nan = float("nan")
        return Spread(nan, nan, nan, nan, nan, 0)
    q1, med, q3 = np.percentile(a, [25, 50, 75])
    return Spread(float(med), float(q1), float(q3), float(a.min()), float(a.max()), int(a.size))


def time_call(
    fn: Callable[..., Any],
    repeats: int,
    warmup: int = 1,
    setup: Callable[[], Any] | None = None,
) -> list[float]:
    """Wall seconds of ``repeats`` calls of ``fn()`` after ``warmup`` untimed ones.

    With ``setup``, each call is ``fn(setup())`` and the setup is not timed (e.g. a fresh block
    for every run).
    """
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    out = []
    for i in range(warmup + repeats):
        state = setup() if setup else None
        t0 = time.perf_counter()
        fn(state) if setup else fn()
        dt = time.perf_counter() - t0
        if i >= warmup:
            out.append(dt)
    return out


def time_paired(
    fn: Callable[..., Any],
    base: Callable[..., Any],
    repeats: int,
    warmup: int = 1,
    setup: Callable[[], Any] | None = None,
    base_setup: Callable[[], Any] | None = None,
) -> tuple[list[float], list[float]]:
    """Wall seconds of ``fn`` and of its baseline ``base``, called alternately (base, then fn) so
    each pair shares the machine's load of that moment: their ratio is what a busy machine keeps."""
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    out: tuple[list[float], list[float]] = ([], [])
    for i in range(warmup + repeats):
        b = time_call(base, 1, 0, base_setup)[0]
        f = time_call(fn, 1, 0, setup)[0]
        if i >= warmup:
            out[0].append(f)
            out[1].append(b)
    return out
