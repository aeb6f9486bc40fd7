"""The live status view (flowtact.runtime.live)."""

import io
import re

from rich.console import Console

from flowtact.runtime.live import LiveView, format_latency, render

FULL = {
    "graph": "touch.yaml",
    "mode": "realtime",
    "now": 3.2,
    "duration": 10.0,
    "wall": 11.4,
    "running": 1.6,
    "startup": 9.8,
    "processes": {
        "sensor": {
            "pid": 4242,
            "host": "local",
            "state": "running",
            "cpu_pct": 6.3,
            "restarts": 0,
            "nodes": ["src"],
        },
        "dsp": {
            "pid": 4243,
            "host": "local",
            "state": "restarting",
            "cpu_pct": None,
            "restarts": 2,
            "nodes": ["savgol", "nlif"],
        },
    },
    "streams": {
        "src.out": {
            "rate_hz": 1000.2,
            "samples_hz": 16003.1,
            "p50_us": 182.4,
            "p99_us": 640.0,
            "dropped": 0,
            "policy": "block",
        },
        "cam.frame": {
            "rate_hz": 40.0,
            "samples_hz": 40.0,
            "p50_us": 980.0,
            "p99_us": 12500.0,
            "dropped": 17,
            "policy": "latest",
        },
    },
    "paths": {"src -> sink": {"p50_us": 250.0, "p99_us": 5200.0, "budget_us": 4000.0, "violations": 3}},
}


class Tty(io.StringIO):
    """A captured stream that claims to be a terminal."""

    def isatty(self) -> bool:
        return True


class FakeClock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def text_of(snapshot) -> str:
    console = Console(record=True, width=120, file=io.StringIO())
    console.print(render(snapshot))
    return console.export_text()


def line_with(text: str, word: str) -> str:
    (line,) = [line for line in text.splitlines() if word in line]
    return line


def test_full_snapshot_shows_every_stream_process_and_path():
    text = text_of(FULL)
    title = text.splitlines()[0]
    assert "touch.yaml" in title and "realtime" in title
    assert "3.2/10.0 s" in title and "32%" in title and "2.0× real time" in title  # now over the running time
    assert "start-up 9.8 s" in title  # the start-up apart, never in the factor
    src = line_with(text, "src.out")
    assert "1000" in src and "16003" in src and "182 µs" in src and "640 µs" in src and "block" in src
    cam = line_with(text, "cam.frame")
    assert "980 µs" in cam and "12.5 ms" in cam and "17" in cam and "latest" in cam
    sensor = line_with(text, "sensor")
    assert "4242" in sensor and "running" in sensor and "6.3" in sensor and "src" in sensor
    dsp = line_with(text, "dsp")
    assert "restarting" in dsp and re.search(r"–\s+2\s+savgol, nlif", dsp)  # no CPU yet, 2 restarts
    path = line_with(text, "src -> sink")
    assert "250 µs" in path and "5200 µs" in path and "4000 µs" in path and path.rstrip().endswith("3")
    assert "host" not in text  # every process is local: no host column


def test_drops_and_violations_are_highlighted():
    console = Console(
        record=True, width=120, file=io.StringIO(), force_terminal=True, color_system="standard"
    )
    console.print(render(FULL))
    html = console.export_html(inline_styles=True)
    assert html.count("color: #800000") >= 3  # red: 17 drops, the p99 over budget, 3 violations
    quiet = dict(FULL, streams={"src.out": FULL["streams"]["src.out"]}, paths={})
    console.print(render(quiet))
    assert "color: #800000" not in console.export_html(inline_styles=True)


def test_nearly_empty_snapshots_render():
    assert text_of({}).strip() == "flowtact ?"
    assert text_of(None).strip() == "flowtact ?"
    text = text_of(
        {
            "graph": "slip.yaml",
            "now": None,
            "duration": None,
            "wall": 0.4,
            "processes": {"main": {"pid": None, "state": "starting"}, "far": {"host": "10.0.0.2"}},
            "streams": {"src.out": {}, "x.y": None},
            "paths": None,
        }
    )
    assert "slip.yaml" in text and "starting 0.4 s" in text
    assert "starting" in line_with(text, "main") and "10.0.0.2" in line_with(text, "far")
    assert "src.out" in text and "x.y" in text
    assert "deadline" not in text


def test_latency_units():
    assert format_latency(None) == "–"
    assert format_latency(12.3) == "12 µs"
    assert format_latency(9_999) == "9999 µs"
    assert format_latency(10_000) == "10.0 ms"
    assert format_latency(2_500_000) == "2500.0 ms"


def test_view_on_a_non_terminal_stays_disabled(monkeypatch):
    monkeypatch.setenv("FORCE_COLOR", "1")  # a CI log that asks for colour is still no terminal
    out = io.StringIO()
    view = LiveView(enabled=True, console=Console(file=out))
    assert not view.enabled
    with view:
        view.update(FULL)
    assert out.getvalue() == ""


def test_view_disabled_on_request_even_on_a_terminal():
    out = Tty()
    with LiveView(enabled=False, console=Console(file=out, force_terminal=True)) as view:
        view.update(FULL)
    assert out.getvalue() == ""


def test_view_redraws_at_most_four_times_a_second_and_close_shows_the_last():
    out = Tty()
    clock = FakeClock()
    view = LiveView(console=Console(file=out, force_terminal=True, width=120), clock=clock)
    assert view.enabled
    view.update(dict(FULL, graph="first.yaml"))
    assert "first.yaml" in out.getvalue()
    clock.t += 0.1
    view.update(dict(FULL, graph="second.yaml"))  # too soon: held back
    assert "second.yaml" not in out.getvalue()
    clock.t += 0.2
    view.update(dict(FULL, graph="third.yaml"))  # 0.3 s after the first draw
    assert "third.yaml" in out.getvalue() and "second.yaml" not in out.getvalue()
    clock.t += 0.01
    view.update(dict(FULL, graph="last.yaml"))
    assert "last.yaml" not in out.getvalue()
    view.close()
    assert "last.yaml" in out.getvalue()
    size = len(out.getvalue())
    view.update(dict(FULL, graph="after.yaml"))
    view.close()
    assert len(out.getvalue()) == size
