"""The timing helper every benchmark shares (``python bench/NAME.py`` puts bench/ on ``sys.path``; the scripts in bench/blocks/ put it there themselves)."""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from typing import Any


def median_time(fn: Callable[..., Any], repeats: int, setup: Callable[[], Any] | None = None) -> float:
    """Median wall time in s of ``fn()`` over ``repeats`` runs; with ``setup``, of ``fn(setup())``,
    the setup untimed (e.g. a fresh block for every run)."""
    times = []
    for _ in range(repeats):
        state = setup() if setup else None
        t0 = time.perf_counter()
        fn(state) if setup else fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)
