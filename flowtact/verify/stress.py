"""Numerical stress cases: a case runs a real block on hostile numbers and reports what it did.

The cases themselves live next to the blocks they stress (``flowtact.blocks.<room>.stress_cases``,
each exposing ``CASES``), because the framework never imports the block library and the benchmark
runner must find them in an installed wheel, where ``tests/`` does not exist. Each room lists its
``CASES`` in the entry-point group ``flowtact.stress_cases`` (``room = "module:CASES"``), and
:func:`collect` finds them there: another package's blocks add their cases the same way. The tests, the
outcome table (``python scripts/stress_outcomes.py`` → docs/numerical-stress.md) and the benchmark
suite all call the same functions.
"""

from __future__ import annotations

import traceback
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

__all__ = ["EPS", "GROUP", "Outcome", "StressCase", "collect", "markdown_table", "run_case"]

GROUP = "flowtact.stress_cases"
"""The entry-point group naming each room's list of stress cases."""

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


def collect() -> list[StressCase]:
    """Every registered stress case: each entry point of :data:`GROUP` (a room's list of
    :class:`StressCase`), rooms in name order, each room's cases in its own order."""
    from importlib.metadata import entry_points

    out: list[StressCase] = []
    for ep in sorted(entry_points(group=GROUP), key=lambda ep: ep.name):
        out.extend(ep.load())
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
