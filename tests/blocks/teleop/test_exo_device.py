"""The exoskeleton's line protocol, its device model, and the `flowtact sim exo` emulator on a pty."""

import os
import select
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from flowtact.blocks.teleop.exo import ExoKinematics, FsrForce, GripperCommand
from flowtact.blocks.teleop.exo_device import (
    CLOSED_PHI,
    FSR_A,
    FSR_B,
    OPEN_PHI,
    THETA_CLOSED,
    THETA_OPEN,
    US_PER_RAD,
    ExoDevice,
    ExoParams,
    closure_of_phi1,
    phi_of_closure,
)
from flowtact.blocks.teleop.exo_protocol import (
    DEVICE_MAX_DEV_US,
    TICK_WRAP,
    Command,
    DataPacket,
    DeviceError,
    Hello,
    ProtocolError,
    Query,
    checksum,
    frame,
    parse_line,
    unframe,
)
from flowtact.testing import run_offline

QUIET = ExoParams(encoder_noise_rad=0.0, fsr_noise_adc=0.0)

# -- protocol -------------------------------------------------------------------------------------


def test_checksum_is_nmea_xor():
    assert checksum(b"GPGLL,5300.97914,N,00259.98174,E,125926,A") == 0x28  # a textbook NMEA sentence
    assert frame("V") == b"$V*56\n"
    # the examples of docs/serial-protocol.md
    assert parse_line(b"$H,flowtact-exo,1,100*2B") == Hello("flowtact-exo", 1, 100.0)
    assert parse_line(b"$C,17,1,-120,0,0,1,250*40") == Command(17, (1, 0, 1), (-120, 0, 250))


@pytest.mark.parametrize(
    "msg",
    [
        DataPacket(4294967295, (21, -17, 0, 74, -68, 940, 80, -62, 959), (0, 512, 1023), 11, 65535),
        DataPacket(0, (0,) * 9, (641, 640, 639), 0, 0, host_ns=123456789012345),
        Command(7, (1, 0, 1), (-500, 0, 800)),
        Hello("flowtact-exo", 1, 100.0),
        Query(),
        DeviceError("badsum"),
    ],
)
def test_round_trip(msg):
    line = msg.format()
    assert line.endswith(b"\n") and line.startswith(b"$") and line.isascii()
    assert parse_line(line) == msg


def test_data_line_is_short_enough_for_115200_baud():
    worst = DataPacket(4294967295, (-3141,) * 9, (1023,) * 3, 15, 65535).format()
    assert len(worst) <= 100  # 100 packets/s × 100 bytes × 10 bits = 100 kbit/s < 115.2 kbit/s


def test_corruption_is_detected():
    line = DataPacket(123456, (1, 2, 3, 4, 5, 6, 7, 8, 9), (10, 11, 12), 0, 3).format()
    for i in range(1, line.index(b"*")):  # any single changed character before the checksum
        bad = bytearray(line)
        bad[i] = ord("7") if bad[i] != ord("7") else ord("8")
        with pytest.raises(ProtocolError):
            parse_line(bytes(bad))
    with pytest.raises(ProtocolError, match="no checksum"):
        parse_line(line[: line.index(b"*")])
    assert parse_line(line[: line.index(b"*")], require_checksum=False) == parse_line(line)


def test_garbage_before_a_line_and_crlf_are_tolerated():
    line = Hello("flowtact-exo", 1, 100.0).format()
    assert parse_line(b"\x00\xff12,3,4" + line[:-1] + b"\r\n") == Hello("flowtact-exo", 1, 100.0)
    assert unframe(b"$V*56") == "V"


@pytest.mark.parametrize(
    "body",
    [
        "D,1,2,3",  # too few fields
        "D,4294967296,0,0,0,0,0,0,0,0,0,0,0,0,0,0",  # tick beyond uint32
        "D,1,0,0,0,0,0,0,0,0,0,0,0,1024,0,0",  # FSR beyond 10 bits
        "D,1,0,0,0,0,0,0,0,0,0,x,0,0,0,0",  # not a number
        "C,1,2,0,0,0,0,0",  # engage must be 0/1
        "C,1,1,0,1,0",  # too few fields
        "H,flowtact-exo,1",
        "Z,1",
    ],
)
def test_malformed_messages_are_rejected(body):
    with pytest.raises(ProtocolError):
        parse_line(frame(body))
    with pytest.raises(ProtocolError):
        parse_line(b"no dollar sign at all\n")


# -- the model --------------------------------------------------------------------------------------


def test_poses_match_the_host_kinematics():
    # the device's angles at the open/closed poses invert (host IK) to the simulated finger poses
    out = run_offline(ExoKinematics(), phi=np.stack([OPEN_PHI, CLOSED_PHI]), units={"phi": "rad"})
    theta = out["theta"].data
    assert np.allclose(theta[0], THETA_OPEN, atol=1e-9)
    assert np.allclose(theta[1], THETA_CLOSED, atol=1e-9)
    assert np.allclose(phi_of_closure(np.zeros(3)), OPEN_PHI, atol=1e-12)
    assert np.allclose(phi_of_closure(np.ones(3)), CLOSED_PHI, atol=1e-12)
    c = np.array([0.2, 0.5, 0.9])
    assert np.allclose(closure_of_phi1(phi_of_closure(c)[:, 0]), c, atol=1e-9)
    assert (CLOSED_PHI[:, 0] > OPEN_PHI[:, 0]).all()  # φ1 grows as the hand closes


def test_clock_ticks_wrap_and_drift():
    dev = ExoDevice(ExoParams(drift_ppm=100.0), tick0_us=(1 << 32) - 25_000)
    ticks = [dev.sample().tick_us for _ in range(5)]
    assert ticks == [(1 << 32) - 25_000, (1 << 32) - 15_000, (1 << 32) - 5_000, 5_000, 15_000]
    assert dev.next_time() == pytest.approx(0.05 / 1.0001)  # a fast clock ticks early in true time


def run_device(dev, duration_s, engage_at=None, release_at=None, dev_us=0):
    """Step the device; while engaged, send a command every tick. Returns per-tick arrays."""
    rows, seq = [], 0
    while dev.next_time() < duration_s:
        t = dev.next_time()
        if engage_at is not None and engage_at <= t < (release_at or np.inf):
            seq += 1
            dev.receive(Command(seq, (1, 1, 1), (dev_us,) * 3).format())
        elif release_at is not None and t >= release_at and dev.engaged.any():
            seq += 1
            dev.receive(Command(seq, (0, 0, 0), (0, 0, 0)).format())
        p = dev.sample()
        rows.append((dev.t, *p.phi_mrad, *p.fsr_adc, p.status, p.ack))
    a = np.array(rows, np.float64)
    return {"t": a[:, 0], "phi": a[:, 1:10].reshape(-1, 3, 3) * 1e-3, "fsr": a[:, 10:13], "status": a[:, 13]}


def push_from_fsr(fsr, f_rest):
    return FSR_A * np.exp(FSR_B * fsr) - f_rest


def test_disengaged_finger_moves_freely():
    dev = ExoDevice(QUIET, seed=3)
    r = run_device(dev, 5.0)
    phi1 = r["phi"][:, :, 0]
    assert phi1.min(axis=0) == pytest.approx(OPEN_PHI[:, 0], abs=2e-3)
    assert phi1.max(axis=0) == pytest.approx(CLOSED_PHI[:, 0], abs=2e-3)  # a full grasp
    push = push_from_fsr(r["fsr"], dev.f_rest)
    assert np.abs(push).max() < 0.15  # only the linkage friction (cf. thesis Fig. 4.3, < 0.2 N)
    assert (r["status"] == 0).all()


def test_engaged_servo_stops_the_finger_and_the_fsr_sees_the_push():
    dev = ExoDevice(QUIET, seed=4)
    r = run_device(dev, 4.2, engage_at=1.0)  # engaged during the grasp, held while the user opens
    t, phi1 = r["t"], r["phi"][:, 1, 0]
    contact = phi1[np.searchsorted(t, 1.0)]
    held = (t > 1.02) & (t < 4.2)
    assert np.abs(phi1[held] - contact).max() < 1e-3  # the finger is stopped at the contact
    assert OPEN_PHI[1, 0] + 0.1 < contact < CLOSED_PHI[1, 0] - 0.1
    push = push_from_fsr(r["fsr"][:, 1], dev.f_rest[1])
    squeeze = (t > 1.5) & (t < 3.0)
    assert push[squeeze].min() > 2.5  # the user squeezes against the servo: up to max_push_n
    assert push[(t > 1.0) & (t < 1.3)].max() > push[np.searchsorted(t, 1.0)] + 1.0  # rising
    pulling = (t > 3.7) & (t < 4.2)
    assert push[pulling].max() < -1.0  # opening against the held servo: negative FSR force
    assert (r["status"][held] == 7).all()


def test_release_lets_the_finger_open():
    dev = ExoDevice(QUIET, seed=5)
    r = run_device(dev, 5.0, engage_at=1.0, release_at=3.5)
    t, phi1 = r["t"], r["phi"][:, 2, 0]
    assert (r["status"][t > 3.52] == 0).all()
    assert phi1[-1] == pytest.approx(OPEN_PHI[2, 0], abs=2e-3)  # free again: back open


def test_deviation_moves_the_servo_at_its_slew_rate():
    dev = ExoDevice(QUIET, seed=6)
    r = run_device(dev, 2.0, engage_at=1.0, dev_us=300)
    t, phi1 = r["t"], r["phi"][:, 1, 0]
    i0 = np.searchsorted(t, 1.0)
    target = phi1[i0 - 1] + 300 / US_PER_RAD
    speed = np.abs(np.diff(phi1[i0 : i0 + 5])) / 0.01
    assert speed.max() <= QUIET.slew_rad_s + 0.05
    assert phi1[-1] == pytest.approx(target, abs=0.02)  # positive deviation: closed further


def test_device_clamps_deviation_and_watchdog_disengages():
    dev = ExoDevice(QUIET, seed=7)
    for _ in range(100):
        dev.sample()
    dev.receive(Command(1, (1, 1, 1), (5000, -5000, 0)).format())
    assert dev.dev_us.tolist() == [DEVICE_MAX_DEV_US, -DEVICE_MAX_DEV_US, 0]
    assert dev.engaged.all()
    statuses = [dev.sample().status for _ in range(60)]  # 0.6 s without a command
    assert statuses[40] == 7 and statuses[-1] == 8  # disengaged, watchdog bit set
    dev.receive(Command(2, (0, 0, 0), (0, 0, 0)).format())
    assert dev.sample().status == 0 and dev.sample().ack == 2


def test_device_rejects_bad_lines():
    dev = ExoDevice(QUIET)
    good = Command(9, (1, 1, 1), (0, 0, 0)).format()
    bad = good.replace(b",1,", b",0,", 1)
    assert dev.receive(bad) == [DeviceError("badsum").format()]
    assert not dev.engaged.any()
    assert dev.receive(frame("X,1")) == [DeviceError("badcmd").format()]
    assert dev.receive(Query().format()) == [dev.hello()]
    assert dev.bad_lines == 2


def test_standalone_virtual_object():
    soft = ExoDevice(ExoParams(object_stiffness_n=10.0, encoder_noise_rad=0.0, fsr_noise_adc=0.0), seed=8)
    firm = ExoDevice(ExoParams(object_stiffness_n=100.0, encoder_noise_rad=0.0, fsr_noise_adc=0.0), seed=8)
    rs, rf = run_device(soft, 3.5), run_device(firm, 3.5)
    # the finger settles where the user's push (10 N per unit of closure short of an intent of 1.3)
    # balances the object's spring from closure 0.6 on
    for r, k in ((rs, 10.0), (rf, 100.0)):
        expected = (10.0 * 1.3 + k * 0.6) / (10.0 + k)
        assert closure_of_phi1(r["phi"][:, :, 0].max(axis=0)) == pytest.approx([expected] * 3, abs=0.01)
    push = push_from_fsr(rf["fsr"], firm.f_rest)
    assert push.max() == pytest.approx(3.0, abs=0.1)  # the FSR sees the push (6.4 N, capped at max_push_n)


def test_device_stream_feeds_the_host_blocks():
    # FSR calibration (rest offset from 20 readings) and the default gripper calibration, on the
    # device's own data: free motion reads ≈ 0 N and a full grasp spans the gripper's [0, 1]
    r = run_device(ExoDevice(QUIET, seed=9), 5.0)
    force = run_offline(FsrForce(), x=r["fsr"], t=r["t"], rate_hz=100.0, units={"x": "ADC"})["y"].data
    assert np.abs(force[30:]).max() < 0.15
    theta = run_offline(ExoKinematics(), phi=r["phi"], t=r["t"], rate_hz=100.0, units={"phi": "rad"})["theta"]
    grip = run_offline(GripperCommand(), x=theta.data, t=r["t"], rate_hz=100.0, units={"x": "rad"})["y"].data
    assert grip.min() == pytest.approx(0.0, abs=0.01) and grip.max() == pytest.approx(1.0, abs=0.01)


# -- the emulator process ---------------------------------------------------------------------


def start_emulator(tmp_path, *args):
    link = str(tmp_path / "exo")
    proc = subprocess.Popen(
        [sys.executable, "-m", "flowtact.blocks.teleop.exo_emulator", "--link", link, "--seed", "1", *args],
        stdout=subprocess.PIPE,
    )
    ready, _, _ = select.select([proc.stdout], [], [], 20.0)
    assert ready, "the emulator did not start"
    first = proc.stdout.readline().decode().strip()
    proc.stdout.close()
    assert first == f"PORT {link}"
    return proc, link


class LineReader:
    """The messages a serial port delivers, read as they come (a partial line waits for its end)."""

    def __init__(self, ser) -> None:
        self.ser = ser
        self.buf = b""

    def until(self, done, timeout_s: float = 30.0) -> list:
        """Read until ``done(messages read by this call)`` holds; those messages.

        Waits for the event rather than for a fixed time: a loaded machine may schedule the emulator
        late. The bound only stops a broken emulator from hanging the test.
        """
        msgs: list = []
        deadline = time.monotonic() + timeout_s
        while not done(msgs):
            assert time.monotonic() < deadline, f"gave up after {timeout_s:g} s; read {msgs[-3:]}"
            self.buf += self.ser.read(65536)
            *lines, self.buf = self.buf.split(b"\n")
            msgs += [parse_line(line) for line in lines if line]
            time.sleep(0.01)
        return msgs


def packets(msgs: list) -> list[DataPacket]:
    return [m for m in msgs if isinstance(m, DataPacket)]


def test_emulator_serves_on_a_pty_and_survives_an_unplug(tmp_path):
    serial = pytest.importorskip("serial")
    proc, link = start_emulator(tmp_path, "--truth", "--replug-s", "0.2")
    try:
        ser = serial.Serial(link, 115200, timeout=0)
        ser.write(Query().format())
        hello = Hello("flowtact-exo", 1, 100.0)
        msgs = LineReader(ser).until(lambda ms: hello in ms and len(packets(ms)) >= 40)
        data = packets(msgs)
        assert all(m.host_ns is not None for m in data)
        # 100 Hz on the device's clock, however late the host reads: one packet per 10 ms tick, none
        # lost or repeated (counting packets per second of wall time would measure the machine's load)
        assert (np.diff([m.tick_us for m in data]) % TICK_WRAP).tolist() == [10_000] * (len(data) - 1)
        reader = LineReader(ser)
        ser.write(Command(5, (1, 0, 0), (0, 0, 0)).format())
        acked = [
            m for m in packets(reader.until(lambda ms: any(m.ack == 5 for m in packets(ms)))) if m.ack == 5
        ]
        assert acked[0].status == 1  # applied: the thumb's servo engaged
        target = os.readlink(link)
        proc.send_signal(signal.SIGUSR1)
        deadline = time.monotonic() + 30.0
        with pytest.raises(serial.SerialException):  # the device vanished under the open port
            while time.monotonic() < deadline:
                ser.read(100)
                ser.write(b"$V*56\n")
                time.sleep(0.01)
        ser.close()
        deadline = time.monotonic() + 30.0
        while not (os.readlink(link) != target or os.path.exists(target)):  # re-pointed at a live pty
            assert time.monotonic() < deadline, "the emulator did not come back"
            time.sleep(0.01)
        ser = serial.Serial(link, 115200, timeout=0)
        data = packets(LineReader(ser).until(lambda ms: len(packets(ms)) >= 20))
        assert {m.status for m in data} == {0}  # a replug power-cycles the board: servos disengaged
        ser.close()
    finally:
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=30) == 0
    assert not os.path.lexists(link)
