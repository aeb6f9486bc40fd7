"""Runs that fail are seen and told truly; runs that end well are never told as failures.

Every test drives real worker processes through ``flowtact run`` as a user would, and waits for
events (a worker appears, the recording holds data, the emulator logs a command) rather than for a
fixed time, so the bounds hold on a loaded machine. Wall-clock bounds are the issue's promises
(a stall is reported within ``stall_s`` + 2 s; a stop ends within ``stop_grace_s`` + 2 s).
"""

from __future__ import annotations

import json
import os
import select
import signal
import time
from pathlib import Path

import pytest
from runs import ROOT, alive, flowtact, wait_children, wait_for_line, wait_recorded, worker_of

from flowtact.recording.hdf5 import read_recording

pytestmark = pytest.mark.slow

SLIP_GROUPS = {
    "sensing": "sensor, force",
    "encoding": "dforce, sa1_drive, fa1_drive",
    "afferents": "sa1, fa1, sa1_stim",
}


@pytest.mark.parametrize("group", sorted(SLIP_GROUPS))
def test_a_stopped_worker_of_slip_is_reported_within_two_seconds(group, tmp_path):
    out = tmp_path / "slip.h5"
    proc = flowtact("run", str(ROOT / "graphs" / "slip.yaml"), "--duration", "120", "--record", str(out))
    kids = wait_children(proc.pid, 3)
    wait_recorded(out, "sa1.spikes", 1)  # every group is running
    victim = worker_of(kids, group)
    t_stop = time.monotonic()
    os.kill(victim, signal.SIGSTOP)
    try:
        _, stderr = proc.communicate(timeout=60)
    finally:
        if alive(victim):
            os.kill(victim, signal.SIGCONT)
    elapsed = time.monotonic() - t_stop
    assert proc.returncode == 1, stderr
    assert f"process '{group}' (nodes {SLIP_GROUPS[group]}) stalled at tick" in stderr, stderr
    assert elapsed < 1.0 + 2.0, elapsed  # stall_s (1 s in real time) + 2 s
    assert not [k for k in kids if alive(k)]
    assert "stalled" in read_recording(out).summary["error"]


HANG = """
name: hang
nodes:
  src:  {block: "toyblocks:Ramp", process: source}
  hang: {block: "toyblocks:Hang", process: worker, params: {at_s: AT}}
edges: [src.y -> hang.x]
processes:
  worker: {RESTART stall_s: 0.5}
record: [hang.y]
"""


def test_a_step_that_never_returns_is_named_by_node_and_tick(tmp_path):
    path = tmp_path / "hang.yaml"
    path.write_text(HANG.replace("AT", "1.5").replace("RESTART", ""))
    proc = flowtact("run", str(path), "--duration", "30")
    _, stderr = proc.communicate(timeout=90)
    assert proc.returncode == 1, stderr
    assert "process 'worker' (nodes hang) stalled at tick" in stderr
    assert "node 'hang' has not returned from its step" in stderr


def test_a_stalled_group_restarts_under_on_failure(tmp_path):
    path = tmp_path / "hang.yaml"
    path.write_text(HANG.replace("AT", "1.5").replace("RESTART", "restart: on-failure,"))
    out = tmp_path / "hang.h5"
    proc = flowtact("run", str(path), "--duration", "4", "--json", "--record", str(out))
    stdout, stderr = proc.communicate(timeout=90)
    assert proc.returncode == 0, stderr
    assert "stalled" in stderr and "restarting it (1/3)" in stderr
    assert json.loads(stdout)["processes"]["worker"]["restarts"] == 1
    t = read_recording(out).streams["hang.y"].t
    assert t[0] < 1.0 and t[-1] > 3.5  # data from before the stall and after the restart


def _commands(log: Path) -> list[tuple[float, str]]:
    out = []
    for line in log.read_text().splitlines():
        t, what = line.split(" ", 1)
        out.append((float(t), what))
    return out


def test_a_stopped_teleop_controller_leaves_the_exoskeleton_safe(tmp_path):
    """The controller's process stops: the device watchdog releases every servo, nothing else is sent."""
    log = tmp_path / "device.log"
    # the device log is a file, which a graph may not name: the emulator runs here, told on its command line
    emulator = flowtact("sim", "exo", "--link", str(tmp_path / "exo"), "--log", str(log))
    try:
        _stopped_controller(emulator, log)
    finally:
        emulator.terminate()
        _, err = emulator.communicate(timeout=30)
        assert emulator.returncode == 0, err
    assert not (tmp_path / "exo").exists()


def _stopped_controller(emulator, log: Path) -> None:
    ready, _, _ = select.select([emulator.stdout], [], [], 30.0)
    assert ready, "the emulator did not start"
    link = emulator.stdout.readline().strip().removeprefix("PORT ")
    proc = flowtact(
        "run",
        str(ROOT / "graphs" / "teleop.yaml"),
        "--duration",
        "120",
        "--quiet",
        "--set",
        f"exo.port={link}",
    )
    kids = wait_children(proc.pid, 3)
    wait_for_line(log, "engage=1", timeout=120)  # the controller is driving a servo
    victim = worker_of(kids, "exo")
    os.kill(victim, signal.SIGSTOP)
    t_stop = time.monotonic()
    try:
        _, stderr = proc.communicate(timeout=60)
    finally:
        if alive(victim):
            os.kill(victim, signal.SIGCONT)
    assert time.monotonic() - t_stop < 1.0 + 2.0
    assert proc.returncode == 1, stderr
    assert "process 'exo' (nodes exo, " in stderr and "stalled at tick" in stderr, stderr
    events = _commands(log)
    # commands already on the wire may still arrive; none is sent after that
    assert not [t for t, what in events if what.startswith("cmd") and t > t_stop + 0.1]
    trips = [t for t, what in events if what == "watchdog" and t > t_stop - 0.1]
    assert trips and trips[0] < t_stop + 1.0  # the device's 0.5 s watchdog released the servos
    assert not [k for k in kids if alive(k)]


@pytest.mark.parametrize("after", ["start-up", "running"])
def test_ctrl_c_on_teleop_exits_0_every_time(after, tmp_path):
    """Ten stops in a row at each moment (twenty in all), during start-up and while running, by
    Ctrl-C, by SIGTERM and by SIGINT to the whole process group (as a terminal sends it)."""
    for i in range(10):
        out = tmp_path / f"teleop{i}.h5"
        proc = flowtact(
            "run",
            str(ROOT / "graphs" / "teleop.yaml"),
            "--duration",
            "60",
            "--record",
            str(out),
            start_new_session=True,
        )
        kids = wait_children(proc.pid, 3)
        if after == "running":
            wait_recorded(out, "exo.angles", 50)
        else:
            time.sleep(0.05 * i)
        how = ("SIGINT", "SIGTERM", "group")[i % 3]
        if how == "group":
            os.killpg(proc.pid, signal.SIGINT)
        else:
            proc.send_signal(signal.Signals[how])
        stdout, stderr = proc.communicate(timeout=60)
        assert proc.returncode == 0, f"try {i} ({how}): {stderr}"
        assert "interrupted" in stdout
        assert "error" not in stderr, stderr
        assert not [k for k in kids if alive(k)]
        if after == "running":
            assert "error" not in read_recording(out).summary


SLOW_BLOCK = """
name: slow
nodes:
  src:  {block: "toyblocks:Ramp", process: source, params: {rate_hz: 1000, channels: 64}}
  sink: {block: "toyblocks:SlowSink", process: sink, params: {delay_s: 0.01}}
edges:
  - {from: src.y, to: sink.x, policy: block}
processes:
  sink: {stop_grace_s: 3, stall_s: 30}  # the test sink sleeps, as a hung call would
record: [src.y]
"""


def test_a_stop_that_cannot_drain_is_aborted_after_its_grace(tmp_path):
    """A 10x slow consumer on a lossless edge: Ctrl-C ends within stop_grace_s + 2 s, told and recorded."""
    path = tmp_path / "slow.yaml"
    path.write_text(SLOW_BLOCK)
    out = tmp_path / "slow.h5"
    proc = flowtact("run", str(path), "--duration", "120", "--record", str(out))
    wait_recorded(out, "src.y", 1000)  # a backlog has built up
    t_int = time.monotonic()
    proc.send_signal(signal.SIGINT)
    _, stderr = proc.communicate(timeout=60)
    assert time.monotonic() - t_int < 3.0 + 2.0
    assert proc.returncode == 1, stderr
    assert "did not finish within stop_grace_s (3 s)" in stderr
    assert "process 'sink' (nodes sink) still at tick" in stderr
    rec = read_recording(out)
    assert "stop_grace_s" in rec.summary["error"] and len(rec.streams["src.y"].t) >= 1000


SLOW_LATEST = """
name: fresh
tick_s: 0.005
nodes:
  src:  {block: "toyblocks:Ramp", process: source, params: {rate_hz: 1000, channels: 4}}
  sink: {block: "toyblocks:SlowSink", process: sink, params: {delay_s: 0, step_delay_s: 0.05}}
edges:
  - {from: src.y, to: sink.x, policy: latest, queue: 4}
"""


def test_latest_delivers_fresh_data_to_a_slow_consumer(tmp_path):
    """One message per 5 ms tick into a consumer that takes 50 ms a step (10x too slow)."""
    path = tmp_path / "fresh.yaml"
    path.write_text(SLOW_LATEST)
    proc = flowtact("run", str(path), "--duration", "8", "--json")
    stdout, stderr = proc.communicate(timeout=90)
    assert proc.returncode == 0, stderr
    stream = json.loads(stdout)["streams"]["src.y"]
    period_us = 50_000
    assert stream["dropped"] > 500
    # data age on arrival at the consumer: at most (queue + 2) consumer periods
    assert stream["latency_us"]["p99"] <= (4 + 2) * period_us, stream


def _groups_graph(n: int) -> str:
    nodes = "\n".join(
        f'  g{i}: {{block: "toyblocks:Scale", process: p{i}}}'
        if i
        else '  g0: {block: "toyblocks:Ramp", process: p0}'
        for i in range(n)
    )
    edges = "\n".join(f"  - g{i - 1}.y -> g{i}.x" for i in range(1, n))
    return f"name: many\nnodes:\n{nodes}\nedges:\n{edges}\nrecord: [g{n - 1}.y]\n"


def test_too_many_process_groups_are_refused_before_anything_starts(tmp_path):
    path = tmp_path / "many.yaml"
    path.write_text(_groups_graph(200))
    proc = flowtact("validate", str(path))
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 2
    assert "the graph places 200 process groups on this host; flowtact runs at most 64" in stderr
    assert stderr.startswith(f"{path}:")


def test_many_process_groups_start_and_finish(tmp_path):
    """Workers that are ready early wait for the slow starters (no self-inflicted timeout)."""
    path = tmp_path / "many.yaml"
    path.write_text(_groups_graph(16))
    proc = flowtact("run", str(path), "--fast", "--duration", "2", "--json")
    stdout, stderr = proc.communicate(timeout=300)
    assert proc.returncode == 0, stderr
    summary = json.loads(stdout)
    assert len(summary["processes"]) == 16 and summary["samples"]["g15.y"] == 2000


OVERLOAD = """
name: overload
tick_s: 0.005
nodes:
  src:  {block: "toyblocks:Ramp", process: source, params: {rate_hz: 1000}}
  slow: {block: "toyblocks:SlowSink", params: {delay_s: 0.0016}}
edges:
  - src.y -> slow.x
"""


def test_a_run_that_falls_behind_real_time_says_so_once(tmp_path):
    """A node that needs 1.6 s for every second of data, in the source's process."""
    path = tmp_path / "overload.yaml"
    path.write_text(OVERLOAD)
    proc = flowtact("run", str(path), "--duration", "3")
    stdout, stderr = proc.communicate(timeout=90)
    assert proc.returncode == 0, stderr
    assert stderr.count("falling behind real time") == 1, stderr
    assert "busiest nodes" in stderr and "slow " in stderr
    assert "NOT real time" in stdout


DEADLINE = """
name: deadline
nodes:
  src:  {block: "toyblocks:Ramp", process: a}
  gain: {block: "toyblocks:Scale", process: b}
edges: [src.y -> gain.x]
deadlines:
  - {from: src, to: gain, budget: 1us}
"""


def test_fast_runs_neither_warn_about_nor_report_wall_clock_deadlines(tmp_path):
    path = tmp_path / "deadline.yaml"
    path.write_text(DEADLINE)
    proc = flowtact("run", str(path), "--fast", "--duration", "5", "--json")
    stdout, stderr = proc.communicate(timeout=90)
    assert proc.returncode == 0, stderr
    assert "deadline" not in stderr
    assert json.loads(stdout)["paths"] == {}  # wall-clock budgets mean nothing on a virtual clock


SHIPPED = {
    "touch": "force.f",
    "slip": "force.f",
    "touch_rectified": "force.f",
    "teleop": "exo.angles",
    "teleop_cnn": "exo.angles",
    "tactip_dataset": "sim.force",
    "braille_open": "scan.position",
    "braille": "scan.position",
    "touchsim_afferents": "current.y",
    "touchsim_currents": "afferents.spikes",
    "hand": "afferents.spikes",
}


#: Shipped graphs that need a live device stream: run (and stopped with Ctrl-C) by their own test.
LIVE = {"lsl_touch": "tests/blocks/devices/test_lsl_interop.py"}


def test_every_shipped_graph_is_tested_here():
    assert set(SHIPPED) | set(LIVE) == {p.stem for p in (ROOT / "graphs").glob("*.yaml")}
    for test in LIVE.values():
        assert "SIGINT" in (ROOT / test).read_text()


@pytest.mark.parametrize("graph", sorted(SHIPPED))
def test_ctrl_c_on_every_shipped_graph_exits_0_with_a_closed_recording(graph, tmp_path):
    if graph == "teleop_cnn":
        pytest.importorskip("torch")
    out = tmp_path / f"{graph}.h5"
    proc = flowtact("run", str(ROOT / "graphs" / f"{graph}.yaml"), "--duration", "600", "--record", str(out))
    wait_recorded(out, SHIPPED[graph], 10, timeout=180)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 0, stderr
    assert "interrupted" in stdout and "error" not in stderr, stderr
    summary = read_recording(out).summary
    assert summary["stopped_by"] == "interrupted" and "error" not in summary


def test_the_readme_training_set_command_exits_0(tmp_path):
    """`flowtact run graphs/tactip_dataset.yaml --fast --record data.h5`, as the README shows it."""
    proc = flowtact(
        "run", str(ROOT / "graphs" / "tactip_dataset.yaml"), "--fast", "--record", "data.h5", cwd=tmp_path
    )
    _, stderr = proc.communicate(timeout=600)
    assert proc.returncode == 0, stderr
    rec = read_recording(tmp_path / "data.h5")
    assert rec.summary["stopped_by"] == "duration" and "error" not in rec.summary
    assert len(rec.streams["sim.frames"].t) == 3000


def test_a_stop_tick_is_not_pushed_ahead_by_heartbeats_that_arrive_together():
    """On a loaded machine beats queue and are read back to back: the rate comes from the times the
    worker stamped, so 50 ticks in 0.25 s is 200 ticks/s however close together the beats arrive."""
    from flowtact.runtime.protocol import Beat
    from flowtact.runtime.supervisor_liveness import tick_rate as _tick_rate

    def beat(k: int, sent_ns: int) -> Beat:
        return Beat("p", 1, k, 0, None, False, 0.0, None, 0, "running", (0, 0, 0), sent_ns)

    assert _tick_rate(beat(100, 1_000_000_000), beat(150, 1_250_000_000)) == pytest.approx(200.0)
    assert _tick_rate(beat(100, 1_000_000_000), beat(150, 1_000_000_000)) == 0.0  # no time between: no rate


def _stop_tick(*, fast: bool, behind_s: float, rates: tuple[float, ...]) -> int:
    """The stop tick named for workers at tick 100 whose last beat just came, ``behind_s`` of
    wall clock past their tick (tick 10 ms, so tick 100 is 1 s)."""
    from types import SimpleNamespace

    from flowtact.runtime.supervisor_procs import stop_tick

    now = time.monotonic()
    procs = [SimpleNamespace(last_k=100, tick_rate=r, beat_at=now) for r in rates]
    return stop_tick(procs, now, None if fast else 1.0 + behind_s, 0.01)


def test_a_stop_names_a_tick_near_workers_far_behind_the_wall_clock_not_the_clock_s():
    """Real time, workers 8 s behind (tick 100 at 9 s): they stop a margin past where they are
    (0.25 s at their 40 ticks/s: 10 ticks), not at the wall clock's tick 925 — a backlog an
    overloaded graph could not compute within its stop grace. Keeping up, the clock bounds it;
    before any rate is measured, the clock alone (no worker can be past it)."""
    behind = _stop_tick(fast=False, behind_s=8.0, rates=(40.0, 35.0))
    assert 110 <= behind <= 112, behind
    keeping_up = _stop_tick(fast=False, behind_s=0.0, rates=(400.0,))  # a fast spell: clock bounds it
    assert 125 <= keeping_up <= 127, keeping_up
    unmeasured = _stop_tick(fast=False, behind_s=8.0, rates=(40.0, 0.0))
    assert 925 <= unmeasured <= 927, unmeasured
    assert 110 <= _stop_tick(fast=True, behind_s=8.0, rates=(40.0,)) <= 112  # --fast: heartbeats alone
