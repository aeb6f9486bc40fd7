"""serial_io: the in-process simulator, and the real thing on a pty against the emulator process."""

import contextlib
import os
import signal
import time

import numpy as np
import pytest

from flowtact.blocks.teleop.exo_protocol import Command, parse_line
from flowtact.blocks.teleop.serial_io import SerialIo
from flowtact.chunk import Chunk, StreamSpec, concat
from flowtact.errors import SpecError
from flowtact.testing import run_source

CMD_SPEC = StreamSpec("float64", (3, 2), "us", 100.0)


def cmd_chunk(t, engage, dev_us):
    sample = np.column_stack([np.broadcast_to(engage, 3), np.broadcast_to(dev_us, 3)]).astype(np.float64)
    return Chunk(np.array([t]), sample[None])


def collect(outs, block):
    return {p: concat([o[p] for o in outs], block.output_specs[p]) for p in block.output_specs}


def drive_sim(block, duration_s, cmd=None, tick_s=0.01):
    """Tick a sim-mode block in graph time; ``cmd(now)`` gives (engage, dev_us) or None."""
    block.bind({"cmd": CMD_SPEC} if cmd else {})
    outs, k = [], 0
    while (now := (k + 1) * tick_s) <= duration_s + 1e-9:
        k += 1
        kw = {}
        if cmd is not None and (c := cmd(now)) is not None:
            kw["cmd"] = cmd_chunk(now - tick_s, *c)
        outs.append(block(now, **kw))
    return collect(outs, block)


def drive_live(block, duration_s, cmd=None, at=None, until=None, timeout_s=30.0):
    """Step an opened block every ~5 ms of wall time (as the real-time executor would).

    Runs ``duration_s``, and then on until ``until(out)`` (called with each step's output) has
    returned True once: data that must arrive is waited for, not expected by a fixed time, as a
    loaded machine may deliver it late. ``timeout_s`` more is the limit.
    """
    outs, ends = [], []
    t0 = time.monotonic()
    done = set()
    arrived = until is None
    while True:
        time.sleep(0.005)
        now = time.monotonic() - t0
        if now > duration_s and arrived:
            break
        assert now < duration_s + timeout_s, "the awaited data never came"
        for when, action in (at or {}).items():
            if now >= when and when not in done:
                done.add(when)
                action()
        kw = {}
        if cmd is not None and (c := cmd(now)) is not None:
            kw["cmd"] = cmd_chunk(now - 0.005, *c)
        out = block(now, **kw)  # never raises, whatever the device does
        outs.append(out)
        ends.append((now, out["fsr"].end))
        arrived = arrived or until(out)
    return collect(outs, block), ends


def spy_read_times(block) -> list[tuple[float, float]]:
    """(true sampling time, read time), host monotonic s, of each data packet the block handles.

    The emulator's ``--truth`` puts the sampling time in each packet. A clock estimate rests on the
    least-delayed packets, so it cannot beat the least read delay the machine allowed: about 0 on an
    idle machine, milliseconds on a loaded one.
    """
    seen: list[tuple[float, float]] = []
    handle = block._packet  # noqa: SLF001 — a spy on the block's packet handler

    def spy(p, arrival, after):
        seen.append((p.host_ns * 1e-9, arrival))
        return handle(p, arrival, after)

    block._packet = spy  # noqa: SLF001 — as above
    return seen


def least_delay(seen, start: float, stop: float, latency_s: float = 0.0) -> float:
    """The least read delay, beyond a known ``latency_s``, of the packets sampled in [start, stop] (host s)."""
    return min(read - sampled - latency_s for sampled, read in seen if start <= sampled <= stop)


# -- port: sim ----------------------------------------------------------------------------------


def test_sim_streams_are_stamped_at_the_sample_times():
    out = run_source(SerialIo(port="sim", sim_drift_ppm=-300.0), 3.0, tick_s=0.005)
    t = out["fsr"].t
    assert 295 <= len(t) <= 300
    assert (np.diff(t) > 0).all() and t[-1] < 3.0
    steps = np.diff(t)[10:]
    assert steps.min() > 0.0088 and steps.max() < 0.0112  # no gaps; only the estimate's updates
    err = t - out["send_t"].data
    assert np.abs(err[100:]).max() < 1e-3  # stamps ≈ sampling times, not arrival times
    phi = out["angles"].data
    assert phi.shape == (len(t), 3, 3) and np.isfinite(phi).all()
    assert out["fsr"].data.min() > 400 and out["fsr"].data.max() < 800  # free motion: near the preload
    assert (out["engaged"].data == 0).all()
    assert np.isnan(out["rtt"].data).all()  # no command sent yet
    dev_t = out["device_t"].data
    assert np.diff(dev_t) == pytest.approx(0.01, abs=1e-6)  # the device's clock, unwrapped


def test_sim_commands_engage_the_servos_and_are_clamped():
    block = SerialIo(port="sim", max_us=200.0)
    out = drive_sim(block, 3.0, cmd=lambda now: (1.0, 5000.0) if 1.0 <= now < 2.0 else (0.0, 0.0))
    t, eng = out["engaged"].t, out["engaged"].data
    assert (eng[(t > 1.05) & (t < 1.98)] == 1).all()  # the sample at ≈ 2.0 s may see the release
    assert (eng[(t < 0.98) | (t > 2.05)] == 0).all()
    assert block.counters["cmd_clamped"] == 3 * 100  # every engaged finger's deviation, every tick
    assert block._dev.dev_us.tolist() == [0.0, 0.0, 0.0]  # noqa: SLF001 — what the sim device's servos got
    rtt = out["rtt"].data[t > 1.1]
    assert np.isfinite(rtt).all() and (rtt > 0).all() and (rtt < 0.03).all()


def test_sim_nonfinite_commands_disengage():
    block = SerialIo(port="sim")
    out = drive_sim(block, 2.0, cmd=lambda now: (1.0, 100.0) if now < 1.0 else (np.nan, np.inf))
    t, eng = out["engaged"].t, out["engaged"].data
    assert (eng[(t > 0.5) & (t < 0.98)] == 1).all()
    assert (eng[t > 1.05] == 0).all()
    assert block.counters["cmd_nonfinite"] == 3 * 101  # ticks at 1.00, 1.01, …, 2.00 s


def test_sim_without_commands_the_device_watchdog_disengages():
    block = SerialIo(port="sim")
    out = drive_sim(block, 2.0, cmd=lambda now: (1.0, 0.0) if now < 0.5 else None)
    t, eng = out["engaged"].t, out["engaged"].data
    assert (eng[(t > 0.1) & (t < 0.9)] == 1).all()  # held 0.5 s past the last command
    assert (eng[t > 1.1] == 0).all()


def test_watermark_advances_and_samples_stay_before_now():
    block = SerialIo(port="sim")
    block.bind({})
    ends = []
    for k in range(1, 101):
        now = k * 0.005
        out = block(now)
        assert (out["fsr"].t < now).all()
        ends.append(out["fsr"].end)
        assert ends[-1] <= now
    assert np.all(np.diff(ends) >= 0) and ends[-1] > 0.5 - 0.02


def test_cmd_spec_is_checked():
    with pytest.raises(SpecError, match="us"):
        SerialIo().bind({"cmd": StreamSpec("float64", (3, 2), "rad", 100.0)})
    with pytest.raises(SpecError, match=r"\(3, 2\)"):
        SerialIo().bind({"cmd": StreamSpec("float64", (3,), "us", 100.0)})
    specs = SerialIo(rate_hz=50.0).bind({})
    assert specs["fsr"].rate_hz == 50.0 and specs["fsr"].labels == ("thumb", "index", "middle")
    assert specs["angles"].units == "rad" and specs["fsr"].units == "ADC"


# -- a real tty ---------------------------------------------------------------------------------


@pytest.fixture
def pty_pair():
    master, slave = os.openpty()
    name = os.ttyname(slave)
    os.set_blocking(master, False)
    yield master, name
    for fd in (master, slave):
        with contextlib.suppress(OSError):
            os.close(fd)


def read_master(master):
    time.sleep(0.02)
    try:
        return os.read(master, 65536)
    except BlockingIOError:
        return b""


def test_commands_on_the_line_are_clamped_and_close_disengages(pty_pair):
    pytest.importorskip("serial")
    master, name = pty_pair
    block = SerialIo(port=name, min_us=-100.0, max_us=250.0)
    block.bind({"cmd": CMD_SPEC})
    block.open()
    try:
        assert parse_line(read_master(master)).__class__.__name__ == "Query"  # asks for the hello
        block(0.005, cmd=cmd_chunk(0.0, 1.0, 900.0))
        block(0.010, cmd=cmd_chunk(0.005, [1.0, np.nan, 0.2], [-300.0, 0.0, 50.0]))
        lines = read_master(master).splitlines()
        assert [parse_line(x) for x in lines] == [
            Command(1, (1, 1, 1), (250, 250, 250)),
            Command(2, (1, 0, 0), (-100, 0, 0)),
        ]
        os.write(master, b"garbage\n$D,1,2*00\n")
        block(0.015)
        assert block.counters["bad_lines"] == 2
    finally:
        block.close()
    assert parse_line(read_master(master)) == Command(3, (0, 0, 0), (0, 0, 0))  # all disengaged


def test_a_fast_run_is_refused_for_a_real_port(pty_pair):
    pytest.importorskip("serial")
    _, name = pty_pair
    block = SerialIo(port=name)
    block.bind({})
    with pytest.raises(RuntimeError, match="not open"):
        block(0.005)
    block.open()
    try:
        block(0.005)
        with pytest.raises(RuntimeError, match="real-time run"):
            block(5.0)
    finally:
        block.close()


def test_a_late_first_step_that_catches_up_is_not_taken_for_a_fast_run(pty_pair, monkeypatch):
    """A loaded worker whose first tick comes 2.3 s after graph time 0 merges ticks to catch up:
    its steps jump to graph times the wall clock has passed, never beyond the time since open
    (the monotonic clock is moved 2.3 s on after open, as if the worker had been that late)."""
    pytest.importorskip("serial")
    _, name = pty_pair
    block = SerialIo(port=name)
    block.bind({})
    block.open()
    clock = time.monotonic
    monkeypatch.setattr(time, "monotonic", lambda: clock() + 2.3)
    try:
        block(0.005)  # its first tick, 2.3 s late
        block(2.25)  # caught up in one merged tick: behind the wall clock, not ahead of it
    finally:
        monkeypatch.undo()
        block.close()


def test_a_missing_port_is_retried_then_given_up(tmp_path):
    pytest.importorskip("serial")
    block = SerialIo(port=str(tmp_path / "ttyNONE"), reconnect_s=0.02)
    block.bind({})
    block.open()  # does not raise: the device may be plugged in later
    try:
        out, ends = drive_live(block, 0.3)
        assert len(out["fsr"]) == 0
        assert ends[-1][1] > ends[0][1]  # the watermark moves on: consumers are not stalled
        assert "connects" not in block.counters
    finally:
        block.close()
    block = SerialIo(port=str(tmp_path / "ttyNONE"), reconnect_s=0.02, give_up_s=0.1)
    block.bind({})
    block.open()
    try:
        with pytest.raises(RuntimeError, match="unavailable"):
            drive_live(block, 1.0)
    finally:
        block.close()


def test_against_the_emulator_stamps_commands_and_replug():
    pytest.importorskip("serial")
    block = SerialIo(port="emulator", emulator_args=("--truth", "--drift-ppm", "120", "--replug-s", "0.3"))
    block.bind({"cmd": CMD_SPEC})
    block.open()
    unplugged = {}

    def unplug():
        unplugged["t"] = time.monotonic()
        os.kill(block._proc.pid, signal.SIGUSR1)  # noqa: SLF001 — the emulator's "unplug" signal

    seen = spy_read_times(block)
    replugged = []  # samples after the unplug, per step

    def enough_after_the_replug(out):
        replugged.append(int((out["fsr"].t > 2.2).sum()))
        return sum(replugged) > 200  # more than 2 s of data (it flows again, and the clock re-syncs)

    try:
        t_open = time.monotonic()
        out, ends = drive_live(
            block,
            4.0,
            cmd=lambda now: (1.0, 0.0) if 1.0 <= now < 1.8 else (0.0, 0.0),
            at={2.2: unplug},
            until=enough_after_the_replug,
        )
    finally:
        block.close()
    assert block._proc is None  # noqa: SLF001 — the emulator was stopped
    t, send_t = out["fsr"].t, out["send_t"].data
    assert (np.diff(t) > 0).all()

    # before the unplug: ≥ 90 % of the packets, stamped within 2 ms of the true sampling times beyond
    # the least read delay the machine allowed (the first ~0.5 s the estimator converges)
    before = t < 2.2
    dev_t = out["device_t"].data[before]
    expected = (dev_t[-1] - dev_t[0]) * 100.0 + 1
    assert before.sum() >= 0.9 * expected
    err = np.abs(t - send_t)
    floor = least_delay(seen, -np.inf, t_open + 0.5)
    assert err[(t > 0.5) & before].max() < 2e-3 + floor
    assert np.median(err[before]) < 1e-3 + floor

    # commands reach the device: it reports its servos engaged, and acknowledges them
    eng = out["engaged"].data
    assert (eng[(t > 1.1) & (t < 1.75)] == 1).all() and (eng[(t > 1.9) & before] == 0).all()
    rtt = out["rtt"].data[(t > 1.2) & before]
    assert np.isfinite(rtt).all() and np.median(rtt) < 0.03

    # unplug → replug: the block never raised; data flows again within 1 s of the replug
    assert block.counters["disconnects"] == 1 and block.counters["connects"] == 2
    assert block.counters.get("resyncs", 0) >= 1
    replug = unplugged["t"] - t_open + 0.3
    after = t[t > 2.2]
    assert after[0] < replug + 1.0
    # re-synced (≈ 0.5 s to converge on a loaded machine), on the packets since the replug
    floor = least_delay(seen, unplugged["t"], t_open + after[0] + 1.0)
    assert err[t > after[0] + 1.0].max() < 2e-3 + floor
    gap_ends = [e for now, e in ends if 2.3 < now < replug]
    assert np.all(np.diff(gap_ends) > 0)  # the watermark kept moving while unplugged


def test_known_device_latency_is_subtracted_and_write_jitter_filtered():
    pytest.importorskip("serial")
    args = ("--truth", "--latency-ms", "6", "--jitter-ms", "4", "--drift-ppm", "-200")
    block = SerialIo(port="emulator", emulator_args=args, latency_s=0.006)
    block.bind({})
    block.open()
    seen = spy_read_times(block)
    try:
        t_open = time.monotonic()
        out, _ = drive_live(block, 2.5)
    finally:
        block.close()
    t, send_t = out["fsr"].t, out["send_t"].data
    assert len(t) >= 0.9 * 250
    err = np.abs(t - send_t)
    # 6 ms fixed + 0–4 ms random write delay, stamped to < 2 ms beyond the least read delay the machine
    # allowed (about 0 when idle: stamping at the read time would be off by up to 4 ms more than that)
    floor = least_delay(seen, -np.inf, t_open + 1.0, latency_s=0.006)
    assert err[t > 1.0].max() < 2e-3 + floor
