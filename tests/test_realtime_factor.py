"""The real-time factor reads with two significant digits wherever a run's speed is shown."""

import io
import math

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
    console.print(render({"graph": "g", "now": 1.3, "duration": 10.0, "wall": 10.0}))
    assert "0.13× real time" in console.export_text()
