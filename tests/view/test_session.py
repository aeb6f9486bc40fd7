"""``--view`` on the command line: which streams, a plan that ships them without writing them to
the file, the tee in the recorder's place, and one-line errors (issue 34, Deliver 1 and 4)."""

from __future__ import annotations

import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from flowtact.chunk import Chunk, StreamSpec
from flowtact.errors import UsageError
from flowtact.recording.hdf5 import read_recording
from flowtact.running.launch import load_compiled
from flowtact.view.buffers import ViewBuffers
from flowtact.view.session import chosen_streams
from flowtact.view.tee import TeeSink

ROOT = Path(__file__).resolve().parents[2]
TOUCH = str(ROOT / "graphs" / "touch.yaml")

pytest.importorskip("aiohttp")


def flowtact(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "flowtact.cli", *args], capture_output=True, text=True, timeout=300
    )


@pytest.fixture(scope="module")
def touch():
    return load_compiled(TOUCH)


def test_no_names_view_the_recorded_streams_and_names_are_checked(touch):
    assert chosen_streams(touch, []) == touch.record
    assert chosen_streams(touch, ["sa1.spikes", "force.f", "sa1.spikes"]) == [
        ("sa1", "spikes"),
        ("force", "f"),
    ]
    with pytest.raises(
        UsageError, match=r"^--view force\.x: not a stream of the graph \('force' has outputs f\)$"
    ):
        chosen_streams(touch, ["force.x"])
    with pytest.raises(
        UsageError, match=r"^--view nosuch\.y: not a stream of the graph \(no node 'nosuch'\)$"
    ):
        chosen_streams(touch, ["nosuch.y"])
    with pytest.raises(UsageError, match=r"\(expected NODE\.PORT, e\.g\. force\.f\)$"):
        chosen_streams(touch, ["force"])


def test_a_viewed_stream_nothing_consumes_is_computed_for_the_view_only(touch):
    from flowtact.view.session import ViewSession

    assert "ddforce" in touch.pruned
    with ViewSession(touch, ["ddforce.y"]) as view:
        plan = view.plan_for(touch)
        assert "ddforce" in plan.order and ("ddforce", "y") in plan.record
        assert ("ddforce", "y") not in touch.record  # the graph's own plan (and file) unchanged
        assert view.plan_for(load_compiled(TOUCH)) is not touch  # recompiled only when needed
    with ViewSession(touch, ["force.f"]) as view:
        assert view.plan_for(touch) is touch


class _Recorder:
    def __init__(self) -> None:
        self.got: list[str] = []
        self.flushes = 0

    def write(self, stream: str, chunk: Chunk) -> None:
        assert len(chunk) == 1
        self.got.append(stream)

    def maybe_flush(self) -> None:
        self.flushes += 1


def test_the_tee_records_the_files_streams_and_views_the_viewed_ones():
    rec, started = _Recorder(), []
    bufs = ViewBuffers({"a.y": StreamSpec(), "b.y": StreamSpec()})
    tee = TeeSink(rec, ["a.y", "c.y"], bufs, on_first=lambda: started.append(1))
    tee.maybe_flush()
    for name in ("a.y", "b.y", "c.y"):
        tee.write(name, Chunk(np.array([0.0]), np.array([1.0])))
    tee.maybe_flush()
    assert rec.got == ["a.y", "c.y"] and rec.flushes == 2 and started == [1]
    assert set(bufs.take()) == {"a.y", "b.y"}
    TeeSink(None, ["a.y"], bufs).write("a.y", Chunk(np.array([0.0]), np.array([1.0])))  # no file: view only


@pytest.mark.cli
@pytest.mark.parametrize("where", [["--inproc"], []], ids=["inproc", "processes"])
def test_a_run_with_view_prints_its_address_and_records_only_the_graphs_streams(tmp_path, where):
    out = tmp_path / "touch.h5"
    done = flowtact(
        "run", TOUCH, "--fast", "--duration", "1", *where, "--record", str(out), "--quiet",
        "--view", "ddforce.y", "sensor.force",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "flowtact: view at http://127.0.0.1:" in done.stderr and "?token=" in done.stderr
    assert "Traceback" not in done.stderr and "Task was destroyed" not in done.stderr
    rec = read_recording(out)
    assert list(rec.streams) == [f"{n}.{p}" for n, p in load_compiled(TOUCH).record]
    assert "ddforce.y" not in rec.streams and len(rec.streams["sensor.force"].t) == 1000


@pytest.mark.cli
def test_view_usage_errors_are_one_line_with_status_2():
    bad = flowtact("run", TOUCH, "--fast", "--duration", "1", "--view", "force.x")
    assert bad.returncode == 2 and bad.stderr.strip().count("\n") == 0
    assert "--view force.x: not a stream of the graph ('force' has outputs f)" in bad.stderr
    alone = flowtact("run", TOUCH, "--fast", "--duration", "1", "--view-port", "8123")
    assert alone.returncode == 2 and "--view-port: only with --view" in alone.stderr
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = str(taken.getsockname()[1])
        busy = flowtact("run", TOUCH, "--fast", "--duration", "1", "--view", "--view-port", port)
    assert busy.returncode == 2 and busy.stderr.strip().count("\n") == 0
    assert f"--view-port {port}: cannot listen on 127.0.0.1:{port}" in busy.stderr


def test_no_thread_starts_before_the_first_write_so_workers_can_still_be_forked(touch):
    """A worker is forked only while the supervisor runs one thread (flowtact.runtime.forked):
    the view's server thread starts at the tee's first call, made by the pump after the forks."""
    import threading

    from flowtact.runtime.forked import can_fork
    from flowtact.view.session import ViewSession

    before = threading.active_count()
    with ViewSession(touch, ["force.f"], say=lambda _text: None) as view:
        tee = view.sink(None, [])
        view.plan_for(touch)
        assert threading.active_count() == before and view.server is None
        if before == 1:
            assert can_fork()
        tee.maybe_flush()  # the pump's first call
        assert view.server is not None and threading.active_count() == before + 1
    assert threading.active_count() == before  # stopped and joined at the end
