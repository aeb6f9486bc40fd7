"""lsl_inlet and lsl_outlet against plain pylsl peers, LSL confined to loopback (lsl_confine.py).

The clock mapping is checked against the truth the sim mode knows; the metadata, the bad-input
paths (NaN, a stream that disappears, a stream that is not there) and the outlet's stream kinds
against real LSL streams of other processes (tests/blocks/devices/lsl_peers.py) or of this one.
"""

from __future__ import annotations

import os
import select
import subprocess
import sys
import uuid
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from lsl_confine import confined_env, write_config

import flowtact.api as ft
from flowtact.blocks.devices.lsl_inlet import LslInlet
from flowtact.blocks.devices.lsl_outlet import LslOutlet
from flowtact.testing import run_source

PEERS = Path(__file__).with_name("lsl_peers.py")
BOUND_S = 120.0  # hang bounds only


@pytest.fixture
def lsl_env(tmp_path, monkeypatch):
    """LSLAPICFG for this process (read when liblsl first loads here) and its children."""
    cfg = write_config(tmp_path)
    monkeypatch.setenv("LSLAPICFG", str(cfg))
    return confined_env(cfg)


def _line(proc: subprocess.Popen[bytes]) -> str:
    assert proc.stdout is not None
    ready, _, _ = select.select([proc.stdout], [], [], BOUND_S)
    assert ready, "the peer said nothing"
    return proc.stdout.readline().decode().strip()


@pytest.fixture
def sender(lsl_env):
    """Start ``lsl_peers.py send`` with the given arguments; stopped (killed) after the test."""
    procs = []

    def start(name: str, n: int, nan_at: int = -1) -> subprocess.Popen[bytes]:
        argv = [sys.executable, str(PEERS), "send", name, str(n), "1000", str(nan_at)]
        p = subprocess.Popen(
            argv, env=lsl_env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL
        )
        procs.append(p)
        assert _line(p) == "ready"
        return p

    yield start
    for p in procs:
        if p.poll() is None:
            p.kill()
        p.wait()
        for f in (p.stdin, p.stdout):
            if f is not None:
                f.close()


def _go(p: subprocess.Popen[bytes]) -> None:
    assert p.stdin is not None
    p.stdin.write(b"go\n")
    p.stdin.flush()


def _name() -> str:
    return f"ft_test_{uuid.uuid4().hex[:8]}"


# -- time: the sim's truth as the oracle ---------------------------------------------------------


def _validate(graph, env) -> subprocess.CompletedProcess:
    """``flowtact validate GRAPH`` in a fresh interpreter with ``env``."""
    return subprocess.run(
        [sys.executable, "-m", "flowtact.cli", "validate", str(graph)],
        env=env,
        capture_output=True,
        text=True,
        timeout=BOUND_S,
        check=False,
    )


def test_sim_stamps_map_onto_graph_time_with_offset_and_drift():
    """A remote clock 0.5 s ahead and 50 ppm fast, its offset read once a second with 20 µs noise:
    the mapped times match the true sampling times (i / rate). Tolerances from that noise: the
    slope of 20 readings over 19 s has σ = 20 µs / sqrt(Σ(t − t̄)²) = 0.78 ppm (5σ: 4 ppm); a mapped
    stamp is off by the fitted line's error, ≤ 4 · 20 µs / sqrt(k) + the unfitted drift of the first
    2 s (50 ppm · 2 s = 100 µs) at worst. Ignoring the offset is 0.5 s off; ignoring the drift, 1 ms
    at the end."""
    block = LslInlet(sim=True, sim_rate_hz=100.0, sim_offset_s=0.5, sim_drift_ppm=50.0, sim_latency_s=0.002)
    out = run_source(block, 20.0, tick_s=0.01)["x"]
    truth = np.arange(len(out)) / 100.0
    err = np.abs(out.t - truth)
    assert len(out) >= 1990
    assert err.max() < 200e-6, err.max()
    assert err[truth > 10].max() < 4 * 20e-6 / np.sqrt(10) + 5e-6, err[truth > 10].max()
    assert abs(block._fit.drift_ppm - 50.0) < 4.0  # noqa: SLF001 - the estimate the summary reports
    np.testing.assert_allclose(out.data[:, 0], np.sin(2 * np.pi * truth).astype(np.float32), atol=2e-6)


def test_sim_samples_arrive_late_but_come_out_in_order_and_never_ahead_of_now():
    block = LslInlet(sim=True, sim_rate_hz=1000.0, sim_latency_s=0.02)
    out = run_source(block, 1.0, tick_s=0.005)["x"]
    assert np.all(np.diff(out.t) > 0)
    assert 900 <= len(out) <= 1000  # the last ~5 × 20 ms are still on their way at the end


# -- the stream's metadata onto the port -----------------------------------------------------------


def test_the_streams_metadata_becomes_the_ports_spec(sender):
    name = _name()
    sender(name, 10)
    spec = LslInlet(name=name, type="Force").specs({})["x"]
    assert spec == ft.StreamSpec("float64", (3,), "N", 1000.0, labels=("Fx", "Fy", "Fz"))


def test_a_declared_stream_checks_offline_and_a_live_stream_that_differs_is_refused_at_open(sender):
    name = _name()
    block = LslInlet(name=name, channels=2, rate_hz=1000.0, units="N", node="force")
    assert block.specs({})["x"] == ft.StreamSpec("float64", (2,), "N", 1000.0)  # no stream needed
    sender(name, 10)  # but the live one has 3 channels
    block.bind({})
    with pytest.raises(RuntimeError) as e:
        block.open()
    block.close()
    assert str(e.value) == (
        f"force (lsl_inlet): the LSL stream with name='{name}' is float64[3] N @ 1000 Hz [Fx, Fy, Fz], "
        "not as declared: float64[2] N @ 1000 Hz"
    )


def test_a_stream_not_found_is_a_located_one_line_error(tmp_path, lsl_env):
    graph = tmp_path / "g.yaml"
    graph.write_text(
        "nodes:\n"
        "  src: {block: lsl_inlet, params: {name: no_such_stream_here, resolve_timeout_s: 0.5}}\n"
        "  out: {block: lsl_outlet}\n"
        "edges:\n  - src.x -> out.x\n"
    )
    done = _validate(graph, lsl_env)
    assert done.returncode == 2, done.stderr
    first = next(ln for ln in done.stderr.splitlines() if str(graph) in ln)
    assert first.startswith(
        f"{graph}:2:3: node 'src' (lsl_inlet): no LSL stream with name='no_such_stream_here'"
    )
    assert "Traceback" not in done.stderr


# -- bad input: NaN, a stream that disappears --------------------------------------------------------


def _until(ready: Callable[[], bool]) -> bool:
    """Poll ``ready`` until it holds (True) or the hang bound passed (False)."""
    import pylsl

    deadline = pylsl.local_clock() + BOUND_S
    while not ready():
        if pylsl.local_clock() > deadline:
            return False
    return True


def _drive(block: LslInlet, until: int) -> tuple[list[ft.Chunk], BaseException | None]:
    """Step the opened block in real time (now: the LSL clock since the start) until ``until``
    samples came out or it raised; a hang bound, no sleeps (each step polls)."""
    import pylsl

    chunks: list[ft.Chunk] = []
    t0 = pylsl.local_clock()
    while sum(len(c) for c in chunks) < until:
        now = pylsl.local_clock() - t0
        assert now < BOUND_S, f"{sum(len(c) for c in chunks)} of {until} samples"
        try:
            chunks.append(block(now)["x"])
        except (RuntimeError, ft.BadDataError) as e:
            return chunks, e
    return chunks, None


def test_nan_samples_follow_the_policy_and_a_lost_stream_raises_after_emitting_everything(sender):
    """The sender pushes all its samples, liblsl receives them all, the sender is killed before the
    block pulled any: every sample liblsl received still comes out (an inlet without liblsl's recovery would raise at once and
    lose all 300), then the error names the node and the stream."""
    name = _name()
    n = 300
    peer = sender(name, n, nan_at=100)
    block = LslInlet(name=name, on_bad_data="drop", node="force", lost_after_s=0.5)
    block.bind({})
    block.open()
    try:
        _go(peer)
        assert _line(peer).startswith(f"sent {n}")  # pushed: liblsl sends them from its own thread
        received = _until(lambda: block._inlet.samples_available() >= n)  # noqa: SLF001 - in liblsl, not pulled
        assert received, "liblsl did not receive every sample"
        peer.kill()  # the sender dies: its outlet vanishes, every sample received, none pulled yet
        peer.wait()
        chunks, raised = _drive(block, 10**9)
    finally:
        block.close()
    got = ft.concat(chunks)
    assert len(got) == n - 1 and block.counters["nonfinite_drop"] == 1
    np.testing.assert_array_equal(np.round(got.data[:, 1] * 1e6), np.delete(np.arange(n), 100))
    assert isinstance(raised, RuntimeError)
    msg = str(raised)
    assert msg.startswith(f"force (lsl_inlet): LSL stream '{name}'") and "lost after 300 samples" in msg
    assert "\n" not in msg


def test_a_live_stream_refuses_a_fast_run(sender):
    name = _name()
    sender(name, 10)
    block = LslInlet(name=name, node="force")
    block.bind({})
    block.open()
    try:
        block(0.0)
        with pytest.raises(
            RuntimeError, match=r"^force \(lsl_inlet\): graph time runs .* ahead of the wall clock"
        ):
            block(5.0)  # 5 s of graph time at once: --fast
    finally:
        block.close()


def test_a_late_first_step_that_catches_up_is_not_taken_for_a_fast_run(sender, monkeypatch):
    """A loaded worker whose first tick comes 2.3 s after graph time 0 merges ticks to catch up:
    its steps jump to graph times the wall clock has passed, never beyond the time since open
    (the LSL clock is moved 2.3 s on after open, as if the worker had been that late)."""
    import pylsl

    name = _name()
    sender(name, 10)
    block = LslInlet(name=name, node="force")
    block.bind({})
    block.open()
    clock = pylsl.local_clock
    monkeypatch.setattr(pylsl, "local_clock", lambda: clock() + 2.3)
    try:
        block(0.01)  # its first tick, 2.3 s late
        block(2.25)  # caught up in one merged tick: behind the wall clock, not ahead of it
    finally:
        block.close()


def test_nan_samples_stop_the_run_by_default_naming_node_and_port(sender):
    name = _name()
    peer = sender(name, 50, nan_at=10)
    block = LslInlet(name=name, node="force")
    block.bind({})
    block.open()
    try:
        _go(peer)
        _, raised = _drive(block, 50)
    finally:
        block.close()
    assert isinstance(raised, ft.BadDataError)
    assert "force" in str(raised) and "'x'" in str(raised)


# -- the outlet: categories as strings, NaN screened ------------------------------------------------------


def test_a_categorical_stream_leaves_as_strings_and_events_as_unit_indices(lsl_env):  # noqa: ARG001
    import pylsl

    name = _name()
    spec = ft.StreamSpec("int64", (), "1", 10.0, categories=("rest", "grasp", "slip"))
    block = LslOutlet(name=name, node="state")
    block.bind({"x": spec})
    block.open()
    try:
        hits = pylsl.resolve_byprop("name", name, 1, BOUND_S)
        inlet = pylsl.StreamInlet(hits[0])
        inlet.open_stream(BOUND_S)
        assert block.config.wait_for_consumers_s == 0 and block._outlet.have_consumers()  # noqa: SLF001
        t = np.arange(4) / 10.0
        block.step(x=ft.Chunk(t, np.array([0, 1, 2, 1])))
        got: list[list[str]] = []
        while len(got) < 4:
            x, _ = inlet.pull_sample(timeout=BOUND_S)  # returns as soon as one sample is there
            assert x is not None, got
            got.append(x)
        info = inlet.info(BOUND_S)
        inlet.close_stream()
    finally:
        block.close()
    assert got == [["rest"], ["grasp"], ["slip"], ["grasp"]]
    assert info.type() == "Markers" and info.nominal_srate() == 0.0
    cats = info.desc().child("flowtact").child("categories").child("category")
    assert cats.child_value() == "rest"


def test_the_outlet_refuses_nan_by_default_naming_node_and_port():
    block = LslOutlet(node="out")
    block.bind({"x": ft.StreamSpec("float64", (2,), "N", 100.0)})
    with pytest.raises(ft.BadDataError, match=r"out.*'x'"):
        block.step(x=ft.Chunk(np.array([0.0, 0.01]), np.array([[1.0, 2.0], [np.nan, 1.0]])))


def test_an_outlet_needs_exactly_one_input(tmp_path, lsl_env):
    graph = tmp_path / "g.yaml"
    graph.write_text(
        "nodes:\n  src: {block: lsl_inlet, params: {sim: true}}\n  out: {block: lsl_outlet}\nedges: []\n"
    )
    done = _validate(graph, lsl_env)
    assert done.returncode == 2
    assert f"{graph}:3:3: node 'out' (lsl_outlet): connect exactly one of x" in done.stderr


# -- flowtact lsl list, and what it sends where ---------------------------------------------------------


def test_lsl_list_shows_the_stream_and_its_packets_go_to_loopback_only(sender, lsl_env, tmp_path):
    name = _name()
    sender(name, 10)
    argv = [sys.executable, "-m", "flowtact.cli", "lsl", "list", "--timeout", "1"]
    strace = "/usr/bin/strace"
    trace = tmp_path / "strace.txt"
    traced = os.access(strace, os.X_OK)
    if traced:
        argv = [strace, "-f", "-qq", "-e", "trace=connect,sendto,sendmsg", "-o", str(trace), *argv]
    done = subprocess.run(argv, env=lsl_env, capture_output=True, text=True, timeout=BOUND_S, check=False)
    assert done.returncode == 0, done.stderr
    row = next(ln for ln in done.stdout.splitlines() if ln.startswith(name + "\t"))
    assert row.split("\t")[1:7] == ["Force", f"peer/{name}", "3", "double64", "1000 Hz", "N"]
    if not traced:
        pytest.skip("strace is not installed: the socket-level check of test_lsl_interop.py stands alone")
    import re

    dests = re.findall(r'sin6?_addr=inet_(?:addr|pton)\((?:AF_INET6, )?"([^"]+)"\)', trace.read_text())
    assert dests, "strace saw no destination: the check looked at nothing"
    assert set(dests) == {"127.0.0.1"}, sorted(set(dests))


# -- the anchor: the least lateness seen, not the first step's (a late first step) ----------------

LATE_S = 2.3  # a loaded worker's first step (seen in CI)
TICK_S = 0.005  # the graphs' tick: the error allowed to a mapping once the anchor has settled


def test_the_anchor_comes_down_to_the_least_lateness_after_a_late_first_step():
    """A fake LSL clock: graph time 0 at 100 s; the first step runs 2.3 s late, the next ones on
    time (1 µs late). The anchor is the truth within that 1 µs once an on-time step ran (the first
    step's measurement would be 2.3 s off), it reports the move, and a new run measures anew."""
    from flowtact.blocks.devices.lsl_clock import Anchor

    t0, wall = 100.0, [99.5]
    a = Anchor(lambda: wall[0])
    a.acquire()  # open: 0.5 s before graph time 0
    wall[0] = t0 + 0.01 + LATE_S
    assert a.at(0.01) == pytest.approx(t0 + LATE_S, abs=1e-9)
    for now in (2.32, 2.33, 2.5):
        wall[0] = t0 + now + 1e-6
        a.at(now)
    assert abs(a.at(2.5) - t0) <= 1e-6 + 1e-9
    assert a.moved == pytest.approx(LATE_S - 1e-6, abs=1e-9)
    assert a.late_at_most == pytest.approx(0.5 + 1e-6, abs=1e-9)  # the open bounds the rest
    a.release()
    wall[0] = t0 + 7.0
    assert a.at(0.0) == pytest.approx(t0 + 7.0) and a.moved == 0.0  # the next run's own


def test_an_inlets_samples_after_a_late_first_step_map_to_their_true_time(sender, monkeypatch):
    """A live sender (2000 samples at 1 kHz, stamped i/1000 after its first); graph time 0 is the
    LSL clock just after open. The inlet's first step runs 2.3 s late as the anchor sees it (its
    clock is moved on for that step only), after at least one sample arrived; later steps run on
    time. Oracle: sample i's true graph time is its stamp minus graph time 0 (one machine: offset
    ~0). The samples the late step mapped come out 2.3 s early (emitted before the anchor moved:
    kept), every later one within a tick of the truth (the first step's anchor: 2.3 s off), and
    the times increase throughout."""
    import pylsl

    from flowtact.blocks.devices import lsl_clock

    name, n = _name(), 2000
    peer = sender(name, n)
    block = LslInlet(name=name, node="force")
    block.bind({})
    block.open()
    t0 = pylsl.local_clock()  # graph time 0: after open
    extra = [LATE_S]
    clock = lsl_clock.anchor._clock  # noqa: SLF001 - the anchor's view of the LSL clock
    monkeypatch.setattr(lsl_clock.anchor, "_clock", lambda: clock() + extra[0])
    chunks: list[ft.Chunk] = []
    try:
        _go(peer)
        assert _until(lambda: block._inlet.samples_available() >= 1)  # noqa: SLF001
        chunks.append(block(pylsl.local_clock() - t0)["x"])  # the late first step
        early = len(chunks[0])
        extra[0] = 0.0
        while sum(len(c) for c in chunks) < n:
            now = pylsl.local_clock() - t0
            assert now < BOUND_S, f"{sum(len(c) for c in chunks)} of {n} samples"
            chunks.append(block(now)["x"])
        first = float(_line(peer).split()[2])
        summary = block.summary()
    finally:
        block.close()
    got = ft.concat(chunks)
    i = np.round(got.data[:, 1] * 1e6).astype(int)
    truth = first + i / 1000.0 - t0
    err = got.t - truth
    assert 1 <= early < n, early  # samples on both sides of the move
    assert np.all(np.diff(got.t) > 0)
    np.testing.assert_allclose(err[:early], -LATE_S, atol=TICK_S)
    assert np.abs(err[early:]).max() < TICK_S, np.abs(err[early:]).max()
    moved = float(summary.split("anchor moved ")[1].split(" ms")[0])  # the first step's excess
    assert abs(moved - LATE_S * 1e3) < TICK_S * 1e3, summary


def test_an_outlet_after_the_anchor_moved_stamps_the_true_lsl_time(lsl_env):  # noqa: ARG001
    """The anchor's clock is faked: graph time 0 at 50 s; the first chunk is pushed 2.3 s late, the
    next on time. A plain pylsl inlet in this process receives the second sample stamped exactly
    50 s + its graph time (the first step's anchor: 2.3 s later) — what a sample read by an inlet
    of this process and republished leaves with once the anchor has settled."""
    import pylsl

    from flowtact.blocks.devices import lsl_clock

    t0, wall = 50.0, [0.0]
    name = _name()
    spec = ft.StreamSpec("float64", (), "N", 10.0)
    block = LslOutlet(name=name, node="out")
    block.bind({"x": spec})
    block.open()
    orig = lsl_clock.anchor._clock  # noqa: SLF001
    lsl_clock.anchor._clock = lambda: wall[0]  # noqa: SLF001
    try:
        hits = pylsl.resolve_byprop("name", name, 1, BOUND_S)
        inlet = pylsl.StreamInlet(hits[0])
        inlet.open_stream(BOUND_S)
        wall[0] = t0 + 0.1 + LATE_S
        block.step(x=ft.Chunk(np.array([0.1]), np.array([1.0])))  # late by 2.3 s
        wall[0] = t0 + 1.0 + 1e-3
        block.step(x=ft.Chunk(np.array([1.0]), np.array([2.0])))  # on time (1 ms on its way)
        got = []
        while len(got) < 2:
            x, ts = inlet.pull_sample(timeout=BOUND_S)
            assert x is not None, got
            got.append((x[0], ts))
        inlet.close_stream()
    finally:
        lsl_clock.anchor._clock = orig  # noqa: SLF001
        block.close()
    assert got[0] == (1.0, pytest.approx(t0 + LATE_S + 0.1))  # sent before the move: as it was
    assert got[1][0] == 2.0 and abs(got[1][1] - (t0 + 1.0)) <= 1e-3 + 1e-9


def test_samples_an_inlet_still_holds_move_with_the_anchor_and_times_stay_increasing():
    """A declared stream, no LSL needed: two samples mapped with an anchor at 10 s (LSL 12.0 and
    12.5 → 2.0, 2.5); ``now`` 2.2 emits the first and holds the second. The anchor comes down by
    1 s: the held one moves with it (3.5: its mapping with the settled anchor), the one emitted
    keeps 2.0, and a sample mapped after (12.6 → 3.6) follows in order."""
    block = LslInlet(name="held", channels=1, format="float64", rate_hz=10.0, node="force")
    block.bind({})
    x = np.zeros((1, 1))
    block._settle(10.0)  # noqa: SLF001 - the anchor a step takes
    block._take(np.array([12.0, 12.5]), np.zeros((2, 1)))  # noqa: SLF001 - what a step pulls
    first = block._emit(2.2)["x"]  # noqa: SLF001
    block._settle(9.0)  # noqa: SLF001
    block._take(np.array([12.6]), x)  # noqa: SLF001
    second = block._emit(4.0)["x"]  # noqa: SLF001
    np.testing.assert_allclose(first.t, [2.0])
    np.testing.assert_allclose(second.t, [3.5, 3.6])
    assert "stamp_nudged" not in block.counters
