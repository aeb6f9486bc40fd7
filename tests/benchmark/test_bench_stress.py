"""The ``stress`` benchmark suite: one check per stress case, a crash is a failed check, and the runner end to end."""

from __future__ import annotations

import json

import pytest

from flowtact.bench import stress
from flowtact.benchmark.suite import Context
from flowtact.cli import main
from flowtact.verify.stress import Outcome, StressCase


def _crash() -> Outcome:
    raise ZeroDivisionError("boom")


def _fine() -> Outcome:
    return Outcome("fine", "toy", "x = 1", "returns 1", "equals 1", True, "1")


def test_a_crashing_case_is_a_failed_check_and_the_suite_goes_on(monkeypatch):
    cases = [StressCase("crash", "toy", _crash), StressCase("fine", "toy", _fine)]
    monkeypatch.setattr("flowtact.verify.stress.collect", lambda: cases)
    ctx = Context(stress.SUITE, quick=True)
    stress.SUITE.run(ctx)
    assert [c.passed for c in ctx.checks] == [False, True]
    assert "CRASH: ZeroDivisionError: boom" in ctx.checks[0].detail
    assert ctx.data["outcomes"][0]["crashed"] and not ctx.data["outcomes"][1]["crashed"]
    assert ctx.notes == ["2 stress cases: 1 pass, 1 fail (1 of them crashed); 0 long runs at 1e7 steps."]
    assert len(ctx.tables) == 1 and len(ctx.tables[0].rows) == 2


def test_the_full_run_takes_each_case_s_full_variant(monkeypatch):
    short = StressCase("long", "toy", _crash, full=_fine)
    monkeypatch.setattr("flowtact.verify.stress.collect", lambda: [short])
    ctx = Context(stress.SUITE, quick=False)
    stress.SUITE.run(ctx)
    assert [c.passed for c in ctx.checks] == [True] and "1e8" in ctx.notes[0]


@pytest.mark.slow
def test_the_stress_suite_runs_every_case_through_the_runner(tmp_path, capsys):
    assert main(["bench", "stress", "--quick", "--json", "--out", str(tmp_path)]) == 0
    assert json.loads(capsys.readouterr().out)["suites"] == {"stress": "ok"}
    res = json.loads((tmp_path / "results" / "stress.json").read_text())
    from flowtact.verify.stress import collect

    assert len(res["checks"]) == len(collect()) >= 40
    assert all(c["passed"] for c in res["checks"]), [c for c in res["checks"] if not c["passed"]]
    assert "Numerical stress outcomes" in (tmp_path / "REPORT.md").read_text()


TOY_CASES = (StressCase("fine", "toy", _fine),)


def test_every_room_with_stress_cases_is_registered_and_a_toy_room_is_found(monkeypatch):
    """The rooms are found through the ``flowtact.stress_cases`` entry-point group, not a hand list:
    every ``blocks/<room>/stress_cases.py`` is registered, and a package's own room joins in."""
    from importlib import import_module, metadata
    from pathlib import Path

    from flowtact.verify.stress import GROUP, collect

    rooms = sorted(p.parent.name for p in (Path(__file__).parents[2] / "blocks").glob("*/stress_cases.py"))
    expected = [c for r in rooms for c in import_module(f"flowtact.blocks.{r}.stress_cases").CASES]
    assert len(rooms) >= 5 and collect() == expected
    real = metadata.entry_points

    def with_toy(*, group: str):
        toy = metadata.EntryPoint(name="aaa_toy", value=f"{__name__}:TOY_CASES", group=GROUP)
        return [*real(group=group), toy] if group == GROUP else real(group=group)

    monkeypatch.setattr(metadata, "entry_points", with_toy)
    assert collect() == [*TOY_CASES, *expected]
