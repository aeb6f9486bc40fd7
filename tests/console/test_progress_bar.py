"""One progress bar (issue 32, Deliver 4): run, bench and sweep draw flowtact.console.terminal_bar.TerminalBar
on a terminal and keep their own plain lines (or silence) elsewhere."""

from __future__ import annotations

import io

from flowtact.benchmark.progress import Progress
from flowtact.commands.run import run_progress
from flowtact.console.terminal_bar import TerminalBar
from flowtact.sweeps.progress import SweepProgress


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_run_progress_shows_graph_seconds_on_a_terminal_and_nothing_elsewhere():
    tty = _Tty()
    with TerminalBar("run", None, count=False, stream=tty) as bar:
        run_progress(bar)(1.5, 3.0)
    assert "run" in tty.getvalue() and "1.5/3.0 s" in tty.getvalue()
    pipe = io.StringIO()
    with TerminalBar("run", None, count=False, stream=pipe) as bar:
        run_progress(bar)(1.5, None)
    assert pipe.getvalue() == ""


def test_run_progress_without_an_end_says_how_to_stop():
    tty = _Tty()
    with TerminalBar("run", None, count=False, stream=tty) as bar:
        run_progress(bar)(2.0, None)
    assert "2.0 s (Ctrl-C stops)" in tty.getvalue()


def test_bench_and_sweep_draw_the_same_bar_on_a_terminal_and_lines_elsewhere():
    tty, pipe = _Tty(), io.StringIO()
    with Progress(2, stream=tty) as p:
        p.begin("savgol")
        p.end("savgol: ok")
        assert isinstance(p._bar, TerminalBar) and p._bar.shown  # noqa: SLF001 - the one bar
    assert "[1/2] savgol: ok" in tty.getvalue() and "bench" in tty.getvalue()
    with Progress(2, stream=pipe) as p:
        p.begin("savgol")
        p.end("savgol: ok")
    assert pipe.getvalue() == "[1/2] savgol: ok\n"
    with SweepProgress(2, stream=tty) as s:
        s.row(True)
        assert isinstance(s._bar, TerminalBar) and s._bar.shown  # noqa: SLF001 - the one bar
