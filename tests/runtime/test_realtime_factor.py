"""The real-time factor reads with two significant digits wherever a run's speed is shown."""

import io
import json
import math
import subprocess
import sys
from pathlib import Path

import pytest
from rich.console import Console

from flowtact.runtime.inproc import RunSummary
from flowtact.runtime.live import render
from flowtact.runtime.stats import format_factor


@pytest.mark.parametrize(
    ("factor", "text"),
    [
        (0.13, "0.13×"),
        (0.1349, "0.13×"),
        (0.0042, "0.0042×"),
        (1.0, "1.0×"),
        (0.999, "1.0×"),
        (2.46, "2.5×"),
        (9.96, "10×"),
        (25.3, "25×"),
        (253.0, "250×"),
        (1234.0, "1,200×"),
        (0.0, "0×"),
        (math.inf, "∞×"),
    ],
)
def test_two_significant_digits(factor, text):
    assert format_factor(factor) == text


def test_a_slow_run_summary_is_not_zero_times_real_time():
    summary = RunSummary(graph="g", duration_s=0.13, wall_s=1.0, stopped_by="duration")
    first = summary.format().splitlines()[0]
    assert "(0.13× real time, duration)" in first, first
    fast = RunSummary(graph="g", duration_s=3.0, wall_s=0.12, stopped_by="duration").format()
    assert "(25× real time" in fast


def test_the_live_view_title_uses_the_same_format():
    console = Console(record=True, width=120, file=io.StringIO())
    console.print(
        render({"graph": "g", "now": 1.3, "duration": 10.0, "wall": 19.8, "running": 10.0, "startup": 9.8})
    )
    text = console.export_text()
    assert "0.13× real time" in text and "start-up 9.8 s" in text


def test_the_factor_is_over_the_running_time_with_the_start_up_apart():
    """8.1 s from launch, of which 5.1 s start-up: 3 s of graph time in 3.0 s running is 1.0×, not 0.37×."""
    summary = RunSummary(
        graph="g",
        duration_s=3.0,
        wall_s=8.113,
        running_s=3.0026,
        startup_s=5.1,
        stopped_by="duration",
        realtime=True,
    )
    assert summary.realtime_factor == pytest.approx(3.0 / 3.0026)
    first = summary.format().splitlines()[0]
    assert "in 3.003 s (1.0× real time, duration); start-up 5.1 s" in first, first
    d = summary.to_dict()
    assert d["startup_s"] == 5.1 and d["wall_s"] == 8.113 and d["running_s"] == 3.0026
    assert d["realtime_factor"] == pytest.approx(0.9991, abs=1e-4)


TOUCH = str(Path(__file__).parents[2] / "graphs" / "touch.yaml")


@pytest.mark.parametrize("where", [[], ["--inproc"]], ids=["processes", "inproc"])
def test_a_realtime_run_that_kept_up_runs_at_one_times_real_time(where):
    """The factor is a ratio of the run's own clocks (graph time over running time): 1.0 within 10 %
    for a run that kept up, whatever its start-up took; skipped only when the run itself says it
    fell behind (``realtime: false``), never on a timing guess."""
    proc = subprocess.run(
        [sys.executable, "-m", "flowtact.cli", "run", TOUCH, "--duration", "2", "--json", *where],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    s = json.loads(proc.stdout)
    if s["realtime"] is False:
        pytest.skip(f"the run fell behind real time by {s['max_lag_s']:.2f} s (a busy machine)")
    assert s["realtime"] is True and s["duration_s"] == pytest.approx(2.0)
    assert 0.9 <= s["realtime_factor"] <= 1.1, s
    assert s["realtime_factor"] == pytest.approx(s["duration_s"] / s["running_s"])
    # the start-up is told apart: it is in wall_s, never in the factor
    assert s["startup_s"] > 0 and s["wall_s"] >= s["startup_s"] + s["running_s"] - 1e-3
