"""REPORT.md as a person reads it: a one-screen summary first (every suite, its headline ratio, every
failed check, how long and at what load), one ratio convention (a speed-up, > 1: flowtact better), no
internal issue numbers, and a suite that fails leaves the others and the report intact. The reports
here are generated from synthetic results: no timing is measured or asserted."""

from __future__ import annotations

import ast
import json
import re
from pathlib import Path
from typing import Any

import pytest

from flowtact.bench import transport
from flowtact.benchmark import Suite, registry
from flowtact.benchmark.report import RATIO_CONVENTION, RATIO_HEADER, write_report
from flowtact.benchmark.runner import estimate_minutes
from flowtact.benchmark.suite import Context
from flowtact.cli import main

ROOT = Path(__file__).resolve().parents[2]
ISSUE = re.compile(r"\bissues?\s*#?\d+|\bthe issue\b", re.IGNORECASE)
"""An internal issue reference: 'issue 14', 'issues 3', 'the issue's range'."""
OTHER_CONVENTIONS = re.compile(
    r"_over_raw|flowtact\s*/\s*raw|\w+ / (?:raw|plain|steps|kernel)\b|> 1:[^)]*\b(?:slower|worse)\b"
)
"""A ratio written the other way round (flowtact ÷ reference: 'flowtact_over_raw', 'executor / plain'),
or a '> 1' that means flowtact is worse."""
MACHINE = {
    "cpu": "Toy CPU 3000",
    "cores": 2,
    "cores_usable": 2,
    "platform": "Linux-toy",
    "versions": {"python": "3.11.7", "flowtact": "0.1.0"},
    "git_commit": "abc123",
    "threads": {"NUMBA_NUM_THREADS": "1"},
}


def _transport_res() -> dict[str, Any]:
    """One round of the transport suite, flowtact slower than raw on latency and CPU."""
    lat = {"p50": 100.0, "p99": 300.0, "max": 900.0, "n": 10}
    return {
        "raw": {
            "small_1khz": {"latency_us": lat, "cpu_pct": {"source": 10.0, "stage": 10.0, "sink": 10.0}},
            "floor_small_1khz": {"latency_us": lat},
            "small_flat": {"throughput": {"delivered_msg_s": 20_000.0}},
            "image_flat": {"throughput": {"bytes_s": 1e8}},
        },
        "chain": {
            "latency_us": {**lat, "p50": 150.0, "p99": 420.0},
            "cpu_max_pct": 15.0,
            "cpu_pct": {"source": 14.0, "filter": 15.0, "sink": 15.0},
            "supervisor_cpu_pct": 1.5,
        },
        "fast": {"small": {"samples_s": 15_000.0}, "image": {"bytes_s": 0.9e8}},
    }


def _record(name: str, measure, status: str = "ok", wall_s: float = 61.0, **extra: Any) -> dict[str, Any]:
    """A suite's results/<name>.json as the runner writes it, from a Context filled by ``measure``."""
    ctx = Context(Suite(name, f"{name} title", "What it measures.", "a reference", measure), quick=True)
    measure(ctx)
    return {
        "suite": name,
        "status": status,
        "command": f"flowtact bench {name} --quick",
        "wall_s": wall_s,
        "load_before": [1.5, 1.2, 1.0],
        "load_after": [6.25, 3.0, 2.0],
        "title": f"{name} title",
        "measures": "What it measures.",
        "baseline": "a reference",
        **ctx.to_dict(),
        **extra,
    }


def _transport_like(ctx: Context) -> None:
    ctx.figure("raw p50 latency", [100.0, 110.0, 105.0], "µs", "lower", is_baseline=True, reference=True)
    ctx.figure("flowtact p50 latency", [150.0, 160.0, 155.0], "µs", "lower", baseline="raw p50 latency")
    ctx.figure("raw msg/s", [20e3, 21e3, 19e3], "msg/s", "higher", is_baseline=True, reference=True)
    ctx.figure("flowtact msg/s", [15e3, 16e3, 14e3], "msg/s", "higher", baseline="raw msg/s")
    ctx.headline("flowtact msg/s")
    for name, t in transport.ratios_and_targets(_transport_res())["targets"].items():
        ctx.check(name, t["pass"], "detail")
    ctx.note(transport.round_by_round([_transport_res()]))


def _stress_like(ctx: Context) -> None:
    ctx.check("tau much smaller than dt stays finite", True)
    ctx.check("NaN under on_bad_data=raise raises", False, "it returned NaN")


def _nothing(_ctx: Context) -> None:
    """A suite that measured nothing (it failed, or was skipped, before its first figure)."""


def _records() -> list[dict[str, Any]]:
    return [
        _record("transport", _transport_like, wall_s=1367.0),
        _record("stress", _stress_like, wall_s=20.0),
        _record("brokenish", _nothing, "failed", 3.0, error="RuntimeError: it broke\nsecond line"),
        _record("peerless", _nothing, "skipped", 0.0, reason="needs brian2 (pip install 'flowtact[dev]')"),
    ]


def _report(tmp_path: Path) -> str:
    run = {"command": "flowtact bench --quick", "quick": True, "peers": False, "machine": MACHINE,
           "load_before": [1.5, 1.2, 1.0], "load_after": [7.5, 4.0, 3.0], "started": "2026-11-27T18:00:00",
           "wall_s": 1367.4, "estimate_min": 10.0}  # fmt: skip
    return write_report(tmp_path, run, _records()).read_text()


def _summary(report: str) -> str:
    return report[report.index("## Summary") : report.index("## How to read it")]


def test_the_report_opens_with_a_summary_of_every_suite_and_every_failed_check(tmp_path):
    report = _report(tmp_path)
    summary = _summary(report)
    assert report.index("## Summary") < report.index("## transport")  # first, before any suite's section
    assert len(summary.splitlines()) <= 30  # one screen
    for suite in ("transport", "stress", "brokenish", "peerless"):
        assert f"[{suite}](#{suite})" in summary
    failed = [c["name"] for r in _records() for c in r["checks"] if not c["passed"]]
    assert "NaN under on_bad_data=raise raises" in failed and len(failed) >= 4  # transport's FAILs too
    for name in failed:
        assert name in summary
    assert "**FAILED**: RuntimeError: it broke |" in summary  # the error's first line, not the rest
    assert "skipped: needs brian2" in summary
    assert "Took 22 min 47 s" in summary and "add to 10 min" in summary
    assert "1.50 before, 7.50 after, 7.5 at the busiest: above 2 the machine was busy" in summary
    assert "Toy CPU 3000, 2 cores" in summary and "abc123" in summary
    # the named headline, not the first figure: 15 000 against 20 000 msg/s
    assert "**0.75×** flowtact msg/s, vs raw msg/s" in summary
    # the stress suite has no ratio: its row says so rather than inventing one
    assert re.search(r"\| \[stress\]\(#stress\) \| ok \| — \| 1 pass, \*\*1 FAIL\*\*", summary)
    assert "4 suites: 2 ran, **1 failed to run (brokenish)**, 1 skipped" in summary


def test_a_suite_without_a_named_headline_shows_its_first_ratio_against_an_outside_reference(tmp_path):
    def measure(ctx: Context) -> None:
        ctx.figure("own setting", [1.0, 1.0, 1.0], "s", "lower", is_baseline=True)
        ctx.figure("other setting", [2.0, 2.0, 2.0], "s", "lower", baseline="own setting")
        ctx.figure("scipy", [1.0, 1.0, 1.0], "s", "lower", is_baseline=True, reference=True)
        ctx.figure("block", [4.0, 4.0, 4.0], "s", "lower", baseline="scipy")

    run = {"command": "c", "quick": True, "machine": MACHINE, "load_before": None, "load_after": None,
           "started": "now", "wall_s": 5.0}  # fmt: skip
    summary = _summary(write_report(tmp_path, run, [_record("s", measure)]).read_text())
    assert "**0.25×** block, vs scipy" in summary and "other setting" not in summary
    assert "load average (1 min) n/a before" in summary
    assert "6.2 at the busiest: above 2" in summary  # the suites' own load figures still count


def test_no_internal_issue_number_in_a_generated_report(tmp_path):
    report = _report(tmp_path)
    assert "speed-up vs raw pyzmq" in report  # transport's checks are in it
    assert not ISSUE.findall(report)


def _user_strings(path: Path) -> list[tuple[int, str]]:
    """Every string literal of a module that can reach a user (f-strings' text parts included);
    docstrings and comments are for developers and may name issues."""
    tree = ast.parse(path.read_text())
    docs = {
        id(node.body[0].value)
        for node in ast.walk(tree)
        if isinstance(node, (ast.Module, ast.FunctionDef, ast.ClassDef, ast.AsyncFunctionDef))
        and node.body
        and isinstance(node.body[0], ast.Expr)
    }
    docs |= {
        id(n.value) for n in ast.walk(tree) if isinstance(n, ast.Expr) and isinstance(n.value, ast.Constant)
    }
    return [
        (n.lineno, n.value)
        for n in ast.walk(tree)
        if isinstance(n, ast.Constant) and isinstance(n.value, str) and id(n) not in docs
    ]


SOURCES = sorted([*(ROOT / "bench").rglob("*.py"), *(ROOT / "flowtact" / "benchmark").glob("*.py")])


def test_no_report_text_in_the_bench_sources_names_an_issue_or_writes_a_ratio_the_other_way():
    """Check names, notes, table headers and captions are all string literals: none may name an
    internal issue, or write a ratio as flowtact ÷ reference beside the report's speed-ups."""
    assert len(SOURCES) > 20
    found = [
        f"{p.relative_to(ROOT)}:{line}: {text!r}"
        for p in SOURCES
        for line, text in _user_strings(p)
        if ISSUE.search(text) or OTHER_CONVENTIONS.search(text)
    ]
    assert not found, "\n".join(found)


def test_no_suite_introduces_itself_with_an_issue_number():
    """A suite's title, what it measures and its baseline open its section of the report (some come
    from a module docstring, which the source scan above leaves out)."""
    texts = {
        name: " ".join((s.title, s.measures, s.baseline))
        for name, s in registry.suites().items()
        if isinstance(s, Suite)
    }
    assert len(texts) >= 16
    assert not {name: t for name, t in texts.items() if ISSUE.search(t) or OTHER_CONVENTIONS.search(t)}


def test_one_ratio_convention_in_a_generated_report(tmp_path):
    report = _report(tmp_path)
    assert RATIO_CONVENTION in _summary(report)  # stated once, at the top
    assert not OTHER_CONVENTIONS.findall(report)
    headers = [line for line in report.splitlines() if line.startswith("| figure | median |")]
    assert headers and all(h.endswith(f"| {RATIO_HEADER} |") for h in headers)
    # every ratio reads as a speed-up: flowtact slower than raw on latency and rate gives < 1
    assert "0.677× (0.625–0.733) vs raw p50 latency" in report  # 105 µs raw ÷ 155 µs flowtact
    assert "round 1: p50 0.67, p99 0.71" in report  # the round-by-round note: raw ÷ flowtact too


# -- a suite that fails, registered through the entry-point group ---------------------------------


class _EntryPoint:
    """Stands in for an installed package's ``flowtact.bench`` entry point."""

    def __init__(self, name: str, obj: Any = None, error: Exception | None = None):
        self.name, self.value, self._obj, self._error = name, f"toypkg.{name}:SUITE", obj, error

    def load(self) -> Any:
        if self._error is not None:
            raise self._error
        return self._obj


def _good(ctx: Context) -> None:
    ctx.figure("base", [1.0, 1.1, 0.9], "s", "lower", is_baseline=True, reference=True)
    ctx.figure("ours", [2.0, 2.1, 1.9], "s", "lower", baseline="base")
    ctx.check("a bar the good suite meets", True)


def _raises(ctx: Context) -> None:
    ctx.figure("measured before the crash", [3.0], "s", "lower")
    raise RuntimeError("the device went away")


@pytest.fixture
def installed_suites(monkeypatch):
    """Three installed suites: one good, one raising while it runs, one whose module fails to load."""
    eps = [
        _EntryPoint("alpha_good", Suite("alpha_good", "good", "M.", "B.", _good, processes=(1, 1))),
        _EntryPoint("beta_raises", Suite("beta_raises", "raises", "M.", "B.", _raises, processes=(1, 1))),
        _EntryPoint("gamma_broken", error=SyntaxError("invalid syntax (gamma.py, line 3)")),
    ]
    monkeypatch.setattr(registry, "entry_points", lambda group: eps if group == registry.GROUP else [])


@pytest.mark.usefixtures("installed_suites")
def test_a_failing_suite_leaves_the_others_and_the_report_and_the_exit_code_names_it(tmp_path, capsys):
    assert main(["bench", "--quick", "--out", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    assert "suite 'beta_raises' failed: RuntimeError: the device went away" in err
    assert "suite 'gamma_broken' failed: toypkg.gamma_broken:SUITE failed to load: SyntaxError" in err
    assert "alpha_good" not in err
    results = {p.stem: json.loads(p.read_text()) for p in (tmp_path / "results").glob("*.json")}
    assert {results[n]["status"] for n in ("beta_raises", "gamma_broken")} == {"failed"}
    assert results["alpha_good"]["status"] == "ok" and "ours" in results["alpha_good"]["figures"]
    assert results["run"]["suites"] == {"alpha_good": "ok", "beta_raises": "failed", "gamma_broken": "failed"}
    report = (tmp_path / "REPORT.md").read_text()
    summary = _summary(report)
    assert "**1 failed to run" not in summary and "**2 failed to run (beta_raises, gamma_broken)**" in summary
    assert "| [alpha_good](#alpha_good) | ok | **0.5×** ours, vs base | 1 pass |" in summary
    assert "## alpha_good" in report and "PASS a bar the good suite meets" in report
    assert "measured before the crash" in report  # what the failing suite measured is kept


@pytest.mark.usefixtures("installed_suites")
def test_only_good_suites_exit_zero_even_when_a_check_fails(tmp_path, monkeypatch, capsys):
    def failing_check(ctx: Context) -> None:
        ctx.check("a bar this machine misses", False, "too busy")

    good = Suite("alpha_good", "good", "M.", "B.", failing_check, processes=(1, 1))
    monkeypatch.setattr(registry, "entry_points", lambda **_: [_EntryPoint("alpha_good", good)])
    assert main(["bench", "--quick", "--out", str(tmp_path)]) == 0  # a FAIL is a finding, not a crash
    assert "**1 FAIL**: a bar this machine misses" in _summary((tmp_path / "REPORT.md").read_text())
    assert "1 failed check: see its summary" in capsys.readouterr().out


@pytest.mark.usefixtures("installed_suites")
def test_list_adds_up_the_budgets(capsys):
    assert main(["bench", "--list"]) == 0
    out = capsys.readouterr().out
    assert "(every suite)      ~1 min quick, ~4 min full" in out  # 2 × 0.5 and 2 × 2.0 (defaults)


# -- the time a run takes, as the pages state it ----------------------------------------------------

STATED = re.compile(r"about\s+(\d+)\s+min(?:utes)?\b.*?about\s+(\d+)", re.DOTALL)


def _stated(text: str) -> tuple[int, int]:
    """The quick and full run times a text states ("about 10 minutes ... about 40")."""
    m = STATED.search(text)
    assert m, f"no 'about N minutes ... about M' in {text[:200]!r}"
    return int(m.group(1)), int(m.group(2))


def _text(where: str, capsys) -> str:
    if where == "README":
        readme = (ROOT / "README.md").read_text()
        return readme[readme.index("## Speed") :][:600]
    if where == "bench/README":
        return (ROOT / "bench" / "README.md").read_text()[:400]
    with pytest.raises(SystemExit):
        main(["bench", "--help"])
    return capsys.readouterr().out


@pytest.mark.parametrize("where", ["README", "bench/README", "bench --help"])
def test_the_stated_run_times_are_what_the_suites_estimates_add_up_to(where, capsys):
    """--list's estimates are measured budgets on an idle 2-core machine; each page states their sum,
    rounded up by less than 3 minutes (a time far above them would hide a slow suite)."""
    suites = list(registry.suites().values())
    quick, full = estimate_minutes(suites, True), estimate_minutes(suites, False)
    said_quick, said_full = _stated(_text(where, capsys))
    assert quick <= said_quick < quick + 3
    assert full <= said_full < full + 5


def _interrupt(_ctx: Context) -> None:
    raise KeyboardInterrupt


@pytest.mark.usefixtures("installed_suites")
def test_ctrl_c_during_a_suite_still_writes_the_report_of_what_ran(tmp_path, monkeypatch):
    eps = [
        _EntryPoint("alpha_good", Suite("alpha_good", "good", "M.", "B.", _good, processes=(1, 1))),
        _EntryPoint(
            "beta_stopped", Suite("beta_stopped", "stopped", "M.", "B.", _interrupt, processes=(1, 1))
        ),
        _EntryPoint("gamma_later", Suite("gamma_later", "later", "M.", "B.", _good, processes=(1, 1))),
    ]
    monkeypatch.setattr(registry, "entry_points", lambda **_: eps)
    assert main(["bench", "--quick", "--out", str(tmp_path)]) == 130
    summary = _summary((tmp_path / "REPORT.md").read_text())
    assert "| [alpha_good](#alpha_good) | ok |" in summary
    assert "**FAILED**: interrupted (Ctrl-C); not run: gamma_later" in summary
    assert json.loads((tmp_path / "results" / "alpha_good.json").read_text())["status"] == "ok"
