"""Numerical stress cases: a case runs a real block on hostile numbers and reports what it did.

The cases themselves live next to the blocks they stress (``flowtact.blocks.<room>.stress_cases``,
each exposing ``CASES``), because the framework never imports the block library and the benchmark
runner must find them in an installed wheel, where ``tests/`` does not exist. The tests, the
outcome table (``python scripts/stress_outcomes.py`` → docs/numerical-stress.md) and the benchmark
suite all call the same functions.
"""

from __future__ import annotations

import importlib
import traceback
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

__all__ = ["EPS", "Outcome", "StressCase", "collect", "markdown_table", "run_case"]

#: float64 machine epsilon, the unit every derived tolerance is a multiple of.
EPS = float(np.finfo(np.float64).eps)


@dataclass(frozen=True)
class Outcome:
    """What one stress case saw: the block's behaviour in words, pass/fail and the measured figure.

    ``passed`` is the case's own criterion (stated in ``criterion``); ``metrics`` holds the raw
    numbers behind ``measured`` (tests assert on them).
    """

    case: str
    block: str
    condition: str
    behaviour: str
    criterion: str
    passed: bool
    measured: str = ""
    metrics: Mapping[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class StressCase:
    """A named case: ``run()`` returns its :class:`Outcome`. A long case also has ``full``, its
    full-length variant (``run`` is then the shorter one the default test suite runs)."""

    name: str
    block: str
    run: Callable[[], Outcome]
    full: Callable[[], Outcome] | None = None

    @property
    def slow(self) -> bool:
        return self.full is not None


def run_case(case: StressCase, full: bool = False) -> Outcome:
    """Run one case (its full-length variant if asked and there is one); an exception escaping
    the case (a crash of the block) becomes a failed outcome naming where it was raised."""
    fn = case.full if full and case.full is not None else case.run
    try:
        return fn()
    except Exception as e:  # noqa: BLE001 - a crash is exactly what the table must record
        last = traceback.extract_tb(e.__traceback__)[-1]
        return Outcome(
            case=case.name,
            block=case.block,
            condition="(see case)",
            behaviour=f"CRASH: {type(e).__name__}: {e} ({last.filename.rsplit('/', 1)[-1]}:{last.lineno})",
            criterion="no crash",
            passed=False,
        )


def collect(modules: Iterable[str]) -> list[StressCase]:
    """The ``CASES`` of each named module, in order (e.g. ``flowtact.blocks.spiking.stress_cases``)."""
    out: list[StressCase] = []
    for name in modules:
        out.extend(importlib.import_module(name).CASES)
    return out


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def markdown_table(outcomes: Sequence[Outcome]) -> str:
    """The outcomes as one markdown table (block, case, condition, behaviour, criterion, result, figure)."""
    head = "| block | case | input | what the block does | criterion | result | measured |"
    rows = [head, "|---|---|---|---|---|---|---|"]
    for o in outcomes:
        cells = [o.block, o.case, o.condition, o.behaviour, o.criterion, "pass" if o.passed else "**FAIL**"]
        rows.append("| " + " | ".join(_cell(c) for c in [*cells, o.measured]) + " |")
    return "\n".join(rows) + "\n"
