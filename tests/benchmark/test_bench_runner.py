"""``flowtact bench``: the harness (flowtact/benchmark/) on toy suites registered here, and one real suite
end to end. No timing is asserted: only that what is measured is recorded, compared and reported."""

from __future__ import annotations

import json
import math
import subprocess
import sys
import time

import pytest

from flowtact.benchmark import Suite, register, unregister
from flowtact.benchmark.suite import Context
from flowtact.cli import main


def _toy(ctx: Context) -> None:
    ctx.speed("loop", lambda: sum(range(2000)), 2000, "items/s", is_baseline=True)
    ctx.speed("builtin", lambda: sum(range(200)), 200, "items/s", baseline="loop")
    ctx.figure("latency base", [10.0, 12.0, 11.0], "µs", "lower", is_baseline=True, reference=True)
    ctx.figure("latency ours", [20.0, 22.0, 21.0], "µs", "lower", baseline="latency base")
    ctx.figure("latency fine", [30.0, 31.0, 32.0], "µs", "lower", baseline="latency ours")
    ctx.table("a toy table", ["setting", "error"], [["a", 0.5], ["b", 0.25]])
    ctx.check("toy bar", True, "met")
    ctx.plot("line", lambda fig: fig.add_subplot(1, 1, 1).plot([0, 1], [1, 2]), "a toy line")
    t = ctx.tradeoff("cost", "toy trade-off", "time per sample (µs)", "RMS error (N)")
    t.add(1.0, 0.1, "fine")
    t.add(0.1, 1.0, "coarse", default=True)


TOY = Suite("toy_suite", "a toy", "Sums of ranges.", "a plain Python loop", _toy)


def _broken(ctx: Context) -> None:
    ctx.figure("before the crash", 1.0, "s", "lower")
    raise ZeroDivisionError("the toy divided by zero")


BROKEN = Suite("broken_suite", "raises", "Nothing.", "none", _broken)


@pytest.fixture
def suites():  # the toy and the broken suite, registered for one test
    register(TOY)
    register(BROKEN)
    yield
    unregister(TOY.name)
    unregister(BROKEN.name)


@pytest.mark.usefixtures("suites")
def test_a_run_records_machine_load_samples_ratios_and_writes_the_report(tmp_path, capsys):
    assert main(["bench", "toy_suite", "--quick", "--out", str(tmp_path)]) == 0
    res = json.loads((tmp_path / "results" / "toy_suite.json").read_text())
    assert res["status"] == "ok"
    for key in ("cpu", "cores", "versions", "git_commit"):
        assert key in json.loads((tmp_path / "results" / "run.json").read_text())["machine"]
    run = json.loads((tmp_path / "results" / "run.json").read_text())
    assert {"numpy", "numba", "flowtact", "python"} <= set(run["machine"]["versions"])
    assert len(res["load_before"]) == len(res["load_after"]) == len(run["load_before"]) == 3
    loop, ours = res["figures"]["loop"], res["figures"]["builtin"]
    assert len(loop["samples"]) == len(loop["seconds"]) == 5  # quick: 5 repeats after the warm-up
    assert loop["median"] == pytest.approx(sorted(loop["samples"])[2])
    assert len(ours["ratio_samples"]) == 5  # timed in pairs with its baseline, one ratio per pair
    assert ours["ratio"] == pytest.approx(sorted(ours["ratio_samples"])[2])
    assert ours["ratio_range"] == pytest.approx([min(ours["ratio_samples"]), max(ours["ratio_samples"])])
    lat = res["figures"]["latency ours"]
    assert lat["ratio"] == pytest.approx(11.0 / 21.0)  # lower is better: > 1 would mean faster than the base
    assert lat["ratio_range"] == pytest.approx([10.0 / 22.0, 12.0 / 20.0])  # worst to best pairing
    report = (tmp_path / "REPORT.md").read_text()
    assert "`flowtact bench toy_suite --quick`" in report
    assert "| a | 0.5 |" in report and "PASS toy bar" in report
    refs = report.index("slower or worse than an outside reference")
    own = report.index("Settings slower or worse than the flowtact setting")
    assert refs < report.index("**latency ours** is slower than latency base: 0.524×") < own
    assert own < report.index("**latency fine** is slower than latency ours")
    for png in ("toy_suite-line.png", "toy_suite-cost.png"):
        assert (tmp_path / "plots" / png).stat().st_size > 1000
        assert f"(plots/{png})" in report
    assert "shipped default (coarse)" in report
    assert "load average" in report.lower()
    assert "toy_suite: ok" in capsys.readouterr().out  # one line per suite off a terminal


@pytest.mark.usefixtures("suites")
def test_list_names_registered_and_installed_suites(capsys):
    assert main(["bench", "--list"]) == 0
    listed = {line.split()[0] for line in capsys.readouterr().out.splitlines()}
    assert {
        "toy_suite",
        "savgol",
        "nlif",
        "ssim",
        "teleop",
        "force_estimation",
        "transport",
        "executor",
    } <= listed
    assert {"record", "hostile_input"} <= listed
    assert not listed & {"ezmsg_pipe", "timeflux_pipe", "raw", "measure", "transport_blocks", "hostile_cases"}


@pytest.mark.usefixtures("suites")
def test_an_unknown_suite_is_a_usage_error_with_a_suggestion(tmp_path, capsys):
    assert main(["bench", "toy_suit", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "unknown benchmark suite 'toy_suit'" in err and "toy_suite" in err
    assert not (tmp_path / "REPORT.md").exists()


@pytest.mark.usefixtures("suites")
def test_a_failing_suite_is_reported_and_the_others_still_run(tmp_path):
    assert main(["bench", "broken_suite", "toy_suite", "--quick", "--out", str(tmp_path)]) == 1
    broken = json.loads((tmp_path / "results" / "broken_suite.json").read_text())
    assert broken["status"] == "failed" and "ZeroDivisionError: the toy divided by zero" in broken["error"]
    assert "before the crash" in broken["figures"]  # what it measured before failing is kept
    assert json.loads((tmp_path / "results" / "toy_suite.json").read_text())["status"] == "ok"
    report = (tmp_path / "REPORT.md").read_text()
    assert "Status: **FAILED**" in report and "the toy divided by zero" in report
    assert "| [toy_suite](#toy_suite) | ok |" in report


def test_a_suite_missing_a_package_is_skipped_not_failed(tmp_path):
    register(Suite("needy_suite", "needs", "Nothing.", "none", _toy, needs=("no_such_module_xyz",)))
    try:
        assert main(["bench", "needy_suite", "--out", str(tmp_path)]) == 0
    finally:
        unregister("needy_suite")
    res = json.loads((tmp_path / "results" / "needy_suite.json").read_text())
    assert res["status"] == "skipped" and "no_such_module_xyz" in res["reason"]
    assert "Skipped: needs no_such_module_xyz" in (tmp_path / "REPORT.md").read_text()


def test_a_figure_naming_a_missing_baseline_fails_the_suite(tmp_path):
    def bad(ctx: Context) -> None:
        ctx.figure("x", 1.0, "s", "lower", baseline="nothing")

    register(Suite("bad_baseline", "bad", "Nothing.", "none", bad))
    try:
        assert main(["bench", "bad_baseline", "--out", str(tmp_path)]) == 1
    finally:
        unregister("bad_baseline")
    assert (
        "names baseline 'nothing'"
        in json.loads((tmp_path / "results" / "bad_baseline.json").read_text())["error"]
    )


def test_a_figure_naming_a_timed_baseline_is_timed_alternately_with_it():
    calls = []
    ctx = Context(TOY, quick=True)
    ctx.duration("base", lambda: calls.append("b"), is_baseline=True, repeats=3)
    assert calls == ["b"] * 4  # one warm-up, three repeats
    calls.clear()
    fig = ctx.duration("ours", lambda: calls.append("f"), baseline="base", repeats=3)
    assert calls == ["b", "f"] * 4  # warm-up pair, then three pairs
    assert len(fig.ratio_samples) == 3 and fig.ratio_range == (min(fig.ratio_samples), max(fig.ratio_samples))


def test_paired_rounds_give_per_round_ratios():
    ctx = Context(TOY, quick=True)
    ctx.figure("raw", [100.0, 200.0, 100.0], "µs", "lower", is_baseline=True)
    ours = ctx.figure("ours", [200.0, 400.0, 200.0], "µs", "lower", baseline="raw", paired=True)
    assert ours.ratio_samples == [0.5, 0.5, 0.5] and ours.ratio_range == (0.5, 0.5)
    crossed = ctx.figure("unpaired", [200.0, 400.0, 200.0], "µs", "lower", baseline="raw")
    assert crossed.ratio_range == (0.25, 1.0)  # every pairing of the samples: worst to best
    with pytest.raises(ValueError, match="as many samples"):
        ctx.figure("short", [1.0, 2.0], "µs", "lower", baseline="raw", paired=True)


def test_a_ratio_from_a_single_run_is_refused_because_it_has_no_spread(tmp_path):
    def single(ctx: Context) -> None:
        ctx.figure("base", [1.0, 1.1, 0.9], "s", "lower", is_baseline=True)
        ctx.figure("ours", 2.0, "s", "lower", baseline="base")

    register(Suite("single_run", "single", "Nothing.", "none", single))
    try:
        assert main(["bench", "single_run", "--out", str(tmp_path)]) == 1
    finally:
        unregister("single_run")
    error = json.loads((tmp_path / "results" / "single_run.json").read_text())["error"]
    assert ">= 3 samples each" in error and "['ours']" in error


@pytest.mark.slow
@pytest.mark.cli
def test_a_real_suite_runs_end_to_end_from_the_installed_package(tmp_path):
    cmd = [
        sys.executable,
        "-m",
        "flowtact.cli",
        "bench",
        "savgol",
        "--quick",
        "--json",
        "--out",
        str(tmp_path),
    ]
    start = time.monotonic()
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600, cwd=tmp_path)  # not the checkout
    assert proc.returncode == 0, proc.stderr[-3000:]
    summary = json.loads(proc.stdout)
    assert summary["suites"] == {"savgol": "ok"} and summary["quick"]
    assert "savgol: ok" in proc.stderr  # progress goes to stderr with --json
    res = json.loads((tmp_path / "results" / "savgol.json").read_text())
    assert res["baseline"].startswith("`scipy.signal.lfilter`")
    measured = [f for f in res["figures"].values() if not f["is_baseline"]]
    assert measured and all(f["ratio"] > 0 for f in measured)
    assert res["processes"] == 2  # quick: a child process measured part of every figure
    assert all(f["processes"] == 2 for f in res["figures"].values())
    assert res["wall_s"] <= time.monotonic() - start
    report = (tmp_path / "REPORT.md").read_text()
    assert (
        "(plots/savgol-error_vs_latency.png)" in report
        and (tmp_path / "plots" / "savgol-error_vs_latency.png").exists()
    )
    assert "`flowtact bench savgol --quick`" in report


def _fig(ratio, lo, hi):
    return {"ratio": ratio, "ratio_range": [lo, hi]}


def test_compare_holds_a_run_to_the_ratio_ranges_an_earlier_run_reported():
    from flowtact.benchmark.compare import compare_records, shift_percentiles

    before = {"s": {"figures": {"a": _fig(2.0, 1.8, 2.2), "b": _fig(0.5, 0.45, 0.55), "c": _fig(1, 1, 1)}}}
    now = [
        {"suite": "s", "figures": {"a": _fig(2.1, 2.0, 2.3), "b": _fig(0.6, 0.58, 0.7), "d": _fig(3, 3, 3)}}
    ]
    checks = {c.figure: c for c in compare_records(before, now)}
    assert set(checks) == {"a", "b"}  # only figures with a ratio in both runs
    assert checks["a"].within and checks["a"].overlaps
    assert not checks["b"].within and not checks["b"].overlaps  # 0.58-0.7 misses 0.45-0.55
    assert checks["a"].shift == pytest.approx(math.log(2.1 / 2.0))
    shift = shift_percentiles(list(checks.values()))
    assert shift["median"] == pytest.approx(math.log(2.1 / 2.0))  # the lower of two shifts
    assert shift["p90"] == pytest.approx(math.log(0.6 / 0.5))


@pytest.mark.usefixtures("suites")
def test_a_second_run_compares_its_ratios_with_the_first(tmp_path, capsys):
    first, second = tmp_path / "first", tmp_path / "second"
    assert main(["bench", "toy_suite", "--quick", "--out", str(first)]) == 0
    assert main(["bench", "toy_suite", "--quick", "--out", str(second), "--compare", str(first)]) == 0
    out = capsys.readouterr().out
    run = json.loads((second / "results" / "run.json").read_text())
    repro = run["reproducibility"]
    assert repro["ratios"] == 3 and repro["compared_with"] == str(first)  # builtin/loop and the two latencies
    assert repro["within_earlier_range"] <= repro["ranges_overlap"] <= 3
    # the fixed figures (latency) reproduce exactly: at least those ratios are inside the earlier range
    assert repro["within_earlier_range"] >= 2
    report = (second / "REPORT.md").read_text()
    assert "## Reproducibility" in report and f"Against the run in `{first}`" in report
    assert f"ratios inside the range of {first}" in out


@pytest.mark.usefixtures("suites")
def test_compare_with_a_folder_that_is_not_a_run_is_a_usage_error(tmp_path, capsys):
    assert main(["bench", "toy_suite", "--out", str(tmp_path / "o"), "--compare", str(tmp_path)]) == 2
    assert "no results/ folder" in capsys.readouterr().err
