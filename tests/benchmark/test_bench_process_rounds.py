"""Figures measured in several fresh processes (flowtact/benchmark/process_rounds.py): repeats are
shared out, a child's raw samples merge into the runner's figures (ratios and their ranges over
every process), and a failing child costs its samples, not the suite."""

from __future__ import annotations

import json
import sys
import textwrap

import pytest

from flowtact.benchmark import Suite, register, unregister
from flowtact.benchmark.process_rounds import measure_children, share
from flowtact.benchmark.suite import Context

SUITE_MODULE = """
import os
from flowtact.benchmark import Suite

def run(ctx):
    if os.environ.get("TOY_CHILD_FAILS") and ctx.partial:
        raise RuntimeError("the child broke")
    base = 100.0 + ctx.part  # a per-process offset, as a different memory layout would give
    ctx.figure("base", [base] * max(1, 3 - 2 * ctx.part), "µs", "lower", is_baseline=True)
    ctx.figure("ours", [2 * base] * max(1, 3 - 2 * ctx.part), "µs", "lower", baseline="base", paired=True)
    ctx.speed("loop", lambda: sum(range(500)), 500, "items/s", is_baseline=True)

SUITE = Suite("toy_rounds", "toy", "Toy figures.", "a toy baseline", run)
"""


@pytest.fixture
def toy_module(tmp_path, monkeypatch):
    (tmp_path / "toy_rounds_mod.py").write_text(textwrap.dedent(SUITE_MODULE))
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("PYTHONPATH", str(tmp_path))
    return "toy_rounds_mod:SUITE"


@pytest.mark.parametrize("total,parts", [(5, 2), (9, 3), (3, 2), (1, 3), (10, 1)])
def test_repeats_are_shared_out_without_losing_any(total, parts):
    shares = [share(total, p, parts) for p in range(parts)]
    assert min(shares) >= 1 and max(shares) - min(shares) <= 1
    assert sum(shares) == max(total, parts)


def test_a_childs_samples_merge_into_the_runners_figures(toy_module):
    steps: list[str] = []
    prior, failures = measure_children(toy_module, True, False, 2, steps.append)
    assert failures == []
    assert prior["base"]["samples"] == [100.0] * 3 and prior["base"]["processes"] == 1
    assert prior["ours"]["pairs"] == [[200.0, 100.0]] * 3
    assert len(prior["loop"]["samples"]) == share(5, 0, 2) == 3  # its share of the 5 quick repeats
    assert any(s.startswith("process 1/2: ") for s in steps)  # the child's progress reached the runner

    import toy_rounds_mod

    ctx = Context(toy_rounds_mod.SUITE, True, part=1, parts=2, prior=prior)
    toy_rounds_mod.SUITE.run(ctx)
    base, ours, loop = (ctx.figures[k] for k in ("base", "ours", "loop"))
    assert base.samples == [100.0] * 3 + [101.0] and base.processes == 2
    assert ours.ratio_samples == pytest.approx([0.5] * 4)  # pairs from both processes
    assert len(loop.samples) == len(loop.seconds) == 5  # 3 from the child, 2 here
    assert base.median == pytest.approx(100.0)


def test_a_lone_process_with_too_few_samples_is_still_refused_a_ratio():
    def run(ctx):
        ctx.figure("base", [1.0], "µs", "lower", is_baseline=True)
        ctx.figure("ours", [2.0], "µs", "lower", baseline="base")

    with pytest.raises(ValueError, match=">= 3 samples"):
        run(Context(Suite("t", "t", "t", "t", run), True))
    run(Context(Suite("t", "t", "t", "t", run), True, part=0, parts=2))  # a child's share: merged later


def test_a_failing_child_costs_its_samples_and_says_so(toy_module, monkeypatch):
    monkeypatch.setenv("TOY_CHILD_FAILS", "1")
    prior, failures = measure_children(toy_module, True, False, 3, print)
    assert prior == {}
    assert len(failures) == 2 and "process 1 of 3 failed (RuntimeError: the child broke)" in failures[0]


def test_the_runner_measures_entry_point_suites_in_processes_not_in_process_registrations(tmp_path):
    from flowtact.cli import main

    register(Suite("toy_local", "t", "t", "t", lambda ctx: ctx.figure("x", [1.0], "s", "lower")))
    try:
        assert main(["bench", "toy_local", "--quick", "--out", str(tmp_path)]) == 0
    finally:
        unregister("toy_local")
    res = json.loads((tmp_path / "results" / "toy_local.json").read_text())
    assert res["processes"] == 1 and res["figures"]["x"]["processes"] == 1  # a child could not find it


def test_the_child_entry_point_writes_raw_samples(toy_module, tmp_path):
    import subprocess

    out = tmp_path / "f.json"
    cmd = [sys.executable, "-m", "flowtact.benchmark.round_child", toy_module, "--part", "0", "--parts", "2",
           "--out", str(out), "--quick"]  # fmt: skip
    subprocess.run(cmd, check=True, capture_output=True, timeout=120)
    figs = json.loads(out.read_text())
    assert figs["ours"] == {"samples": [200.0] * 3, "seconds": None, "pairs": [[200.0, 100.0]] * 3}
