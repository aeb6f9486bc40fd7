"""The serial link to the Remote Feelings exoskeleton: poses and FSR readings in, servo commands out."""

from __future__ import annotations

import contextlib
import logging
import math
import os
import select
import stat
import subprocess
import time
from collections import OrderedDict, deque
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

import flowtact.api as ft
from flowtact.blocks.devices.clocksync import ClockSync
from flowtact.blocks.teleop.exo_protocol import (
    DEVICE_MAX_DEV_US,
    PROTOCOL_VERSION,
    Command,
    DataPacket,
    DeviceError,
    Hello,
    ProtocolError,
    Query,
    parse_line,
)
from flowtact.blocks.teleop.hand import FINGERS, N_FINGERS
from flowtact.running.python_child import python_command
from flowtact.runtime.rundir import RunFolder, make_run_folder

__all__ = ["SerialIo", "SerialIoConfig"]

log = logging.getLogger("flowtact.serial_io")

#: Names of the 9 joint angles, finger by finger (the sample's C order): "thumb φ1", ...
ANGLE_LABELS = tuple(f"{finger} φ{j}" for finger in FINGERS for j in (1, 2, 3))

#: Graph time may run ahead of the wall clock by this much before a real port refuses (a --fast run).
FAST_RUN_SLACK_S = 1.0
#: Commands kept for round-trip matching.
SENT_MEMORY = 256
#: A stamp at most this much before the previous one is moved just after it (else it is dropped).
NUDGE_MAX_S = 0.005
#: Outgoing bytes kept while the device does not read; older commands are dropped beyond this.
MAX_OUT_BYTES = 1024


@dataclass(frozen=True)
class SerialIoConfig(ft.Config):
    port: str = ft.param(
        "sim",
        doc="'sim' (an emulated exoskeleton in-process, graph time: offline and --fast runs), 'emulator' "
        "(start `flowtact sim exo` on a pseudo-terminal and talk to it), or a device such as /dev/ttyACM0",
    )
    baudrate: int = ft.param(115200, gt=0, doc="serial baud rate (ignored by native-USB boards and ptys)")
    rate_hz: float = ft.param(100.0, gt=0, doc="nominal packet rate of the device (the output streams' rate)")
    min_us: float = ft.param(
        -500.0, ge=-DEVICE_MAX_DEV_US, le=DEVICE_MAX_DEV_US, doc="lowest servo deviation ever sent (µs)"
    )
    max_us: float = ft.param(
        500.0, ge=-DEVICE_MAX_DEV_US, le=DEVICE_MAX_DEV_US, doc="highest servo deviation ever sent (µs)"
    )
    reconnect_s: float = ft.param(0.1, gt=0, doc="after an unplug, retry opening the port this often")
    give_up_s: float | None = ft.param(
        None, gt=0, doc="raise if the port stays unavailable this long (None: keep trying forever)"
    )
    max_latency_s: float = ft.param(
        0.1, gt=0, doc="watermark lag while no packet comes; packets stamped before the watermark are dropped"
    )
    latency_s: float = ft.param(
        0.0, ge=0, doc="known constant device delay from sampling to sending, subtracted from the stamps"
    )
    require_checksum: bool = ft.param(True, doc="reject device lines without a '*XX' checksum")
    poll_bracket: bool = ft.param(
        True, doc="give the clock estimator the previous read time too (halves tick-locked polling bias)"
    )
    emulator_args: tuple[str, ...] = ft.param(
        (),
        doc="extra flags for `flowtact sim exo` (port: emulator), e.g. [--truth, --drift-ppm, 120]; never "
        "--link or --log (a graph names no files: run the emulator yourself for those)",
    )
    startup_timeout_s: float = ft.param(10.0, gt=0, doc="port: emulator — how long to wait for it to start")
    sim_latency_s: float = ft.param(
        0.002, ge=0, doc="port: sim — mean transport delay of a packet (exponential, capped at 5×)"
    )
    sim_drift_ppm: float = ft.param(50.0, ge=-5000, le=5000, doc="port: sim — device clock error")
    sim_user: Literal["grasp", "idle"] = ft.param("grasp", doc="port: sim — what the simulated hand does")

    def check(self) -> None:
        problem = port_problem(self.port)
        if problem:
            raise self.error("port", problem)
        if self.emulator_args or self.port == "emulator":
            self._check_emulator()
        if not self.min_us < self.max_us:
            raise self.error("max_us", f"must be > min_us ({self.min_us:g}); got {self.max_us:g}")
        if self.sim_latency_s * 5 >= self.max_latency_s:
            raise self.error(
                "sim_latency_s",
                f"must be < max_latency_s / 5 ({self.max_latency_s / 5:g}); got {self.sim_latency_s:g}",
            )

    def _check_emulator(self) -> None:
        """Only the emulator's own flags, none naming a file, and a rate it serves."""
        from flowtact.blocks.teleop.exo_emulator import MAX_RATE_HZ, graph_args_problem

        problem = graph_args_problem(self.emulator_args)
        if problem:
            raise self.error("emulator_args", problem)
        if self.port == "emulator" and self.rate_hz > MAX_RATE_HZ:
            raise self.error(
                "rate_hz", f"must be <= {MAX_RATE_HZ:g} with port: emulator; got {self.rate_hz:g}"
            )


def port_problem(port: str) -> str | None:
    """Why ``port`` names no serial port, or None: 'sim', 'emulator', or a path that is a character
    device or does not exist yet (a device plugged in later). An existing file, folder, FIFO or
    socket is refused: the block would write its commands into it.
    """
    if port in ("sim", "emulator"):
        return None
    if not port:
        return "must be 'sim', 'emulator' or a serial device such as /dev/ttyACM0; got ''"
    try:
        mode = os.stat(port).st_mode
    except OSError:  # absent (unplugged) or unreachable: the block keeps retrying, as for an unplug
        return None
    if stat.S_ISCHR(mode):
        return None
    return f"must be 'sim', 'emulator' or a serial device; {port} is not a character device"


@dataclass
class _Sample:
    t: float
    phi: tuple[int, ...]
    fsr: tuple[int, int, int]
    status: int
    device_t: float
    rtt: float
    send_t: float


class SerialIo(ft.Source):
    """Exchange packets with the exoskeleton over a serial line, stamped in graph time.

    Config
    ------
    See the field docs (``flowtact blocks serial_io``). ``port`` picks one of three back ends.

    Notes
    -----
    Protocol: ``docs/serial-protocol.md`` (ASCII lines ``$…*XX``; device → host one ``D`` line per
    device tick, host → device ``C`` lines; hello at connect and on a ``$V`` query).

    I/O happens only in ``open``, ``step`` and ``close``; reads and writes never block (timeout 0:
    each step reads what the OS has buffered, splits lines and keeps the partial one); the block
    never sleeps or starts threads. ``port: emulator`` starts the emulator as a subprocess in
    ``open`` (waiting up to ``startup_timeout_s`` for its ``PORT`` line) and stops it in ``close``.

    Time. The block reads ``time.monotonic()`` in ``open`` and ``step`` only to stamp device data
    and to pace reconnection attempts. Graph time of
    a monotonic instant is ``m − anchor``, the anchor being the least ``monotonic − now`` seen over
    the steps (a step runs at or after its graph time, so the least lateness is the best estimate of
    graph time 0 on the monotonic clock). Each packet's read time and device tick go to a
    :class:`flowtact.blocks.devices.clocksync.ClockSync` (lower-envelope drift + offset fit, robust to one-sided
    USB/polling delay; with ``poll_bracket`` also the previous read time) which estimates when the
    device took the sample; ``latency_s`` is subtracted. Accuracy: the first packets after a
    (re)connect are stamped at their read time (≤ one tick late) while the estimate converges
    (≈ 0.5 s); then within 0.5 ms of the sampling instants against the emulator on a pty. A host
    tick that divides the device period exactly and never jitters locks the read phase: stamps are
    then only known to ±tick/2 (see ``flowtact.blocks.devices.clocksync``). A real port needs a real-time run: if
    ``now`` runs ahead of the wall clock by more than 1 s (``--fast``) the block raises; use
    ``port: sim`` for fast and offline runs.

    Output order and watermark. Samples are emitted in increasing time; a stamp at or before the
    previous one is nudged 1 µs past it (``stamp_nudged``); a duplicate or reordered tick is
    dropped (``out_of_order``). A sample stamped at or after ``now`` is held for the next step (a
    source emits only t < now). Every chunk's ``end`` is ``max(last emitted t, now −
    max_latency_s)``: nothing older will come, so downstream merges never wait longer than
    ``max_latency_s`` on a silent device; a packet that arrives later than that is dropped
    (``late``). Gaps in the device ticks are counted as ``lost``.

    Unplug. A read or write that fails (the device vanished) closes the port, counts
    ``disconnects``, logs once, and from then on every step retries opening the same path every
    ``reconnect_s`` without blocking; the clock is re-synced on reconnect (``resyncs``). Commands
    that arrive meanwhile are dropped (``cmd_dropped``). Only ``give_up_s`` turns a missing port
    into an error. ``close`` sends a disengage-all command before closing.

    Safety. Deviations are clipped to [``min_us``, ``max_us``] (``cmd_clamped``) and rounded to
    whole µs; a non-finite engage or deviation disengages that finger (``cmd_nonfinite``). The
    device clamps again and disengages by itself after 0.5 s without a command, so this block
    never repeats an old command on its own: a stalled controller lets the device watchdog act.

    ``port: sim`` runs :class:`flowtact.blocks.teleop.exo_device.ExoDevice` in graph time (seeded by the
    block's rng; ``sim_drift_ppm`` clock error, ``sim_latency_s`` transport delay), with every packet
    and command going through the same text protocol and clock estimator: deterministic, and
    chunking-invariant when ``cmd`` is not connected.

    Example
    -------
    >>> from flowtact.blocks.teleop.serial_io import SerialIo
    >>> from flowtact.testing import run_source
    >>> out = run_source(SerialIo(port="sim"), 1.0, tick_s=0.005)
    >>> out["angles"].data.shape[1:], 90 <= len(out["fsr"]) <= 100
    ((3, 3), True)
    """

    config_cls = SerialIoConfig
    requires = {"serial": "serial"}
    sink = True  # it drives servos: it runs even when nothing consumes its outputs
    inputs = {
        "cmd": ft.Port(
            dtype="float64",
            shape=(N_FINGERS, 2),
            units="us",
            delay=True,
            optional=True,
            doc="per finger (thumb, index, middle): column 0 engage (≥ 0.5 engages), column 1 deviation "
            "from the contact position in µs of PWM (positive lets the finger close further). The latest "
            "sample that arrived since the last step is sent; NaN/inf never reach the line. One step "
            "delayed: it closes the control loop",
        )
    }
    outputs = {
        "angles": ft.Port(
            dtype="float64",
            shape=(N_FINGERS, 3),
            units="rad",
            rate="rate_hz",
            labels=ANGLE_LABELS,
            doc="exoskeleton joint angles φ1 (servo encoder), φ2, φ3 (passive) per finger",
        ),
        "fsr": ft.Port(
            dtype="float64",
            shape=(N_FINGERS,),
            units="ADC",
            rate="rate_hz",
            labels=FINGERS,
            doc="raw FSR readings 0..1023 (eq. 3.10 is applied downstream)",
        ),
        "engaged": ft.Port(
            dtype="float64",
            shape=(N_FINGERS,),
            units="1",
            rate="rate_hz",
            labels=FINGERS,
            doc="the device's own report of which servos are engaged (1.0): the echo of the commands",
        ),
        "device_t": ft.Port(
            dtype="float64",
            shape=(),
            units="s",
            rate="rate_hz",
            doc="the device's clock (its µs counter, unwrapped), for diagnosing the alignment",
        ),
        "rtt": ft.Port(
            dtype="float64",
            shape=(),
            units="s",
            rate="rate_hz",
            doc="round trip of the latest acknowledged command (host send → device ack read), NaN before",
        ),
        "send_t": ft.Port(
            dtype="float64",
            shape=(),
            units="s",
            rate="rate_hz",
            doc="the true sampling time in graph time when the device sends the optional ``h=`` field "
            "(emulators with ``--truth``, and ``port: sim``); NaN otherwise. For testing the alignment",
        ),
    }
    counter_docs = {
        "packets": "data packets received from the device (before any were dropped as late or out of order)",
        "connects": "times the serial port was opened: 1 normally, more after the device was unplugged",
        "disconnects": "times the port failed (device unplugged or gone); the block kept retrying: a problem",
        "resyncs": "times the device clock estimate restarted: after a reconnect, or the device's ticks "
        "jumped (a reset, or over 1 s off the estimate); stamps are coarser for ~0.5 s",
        "hellos": "hello messages from the device (at connect, or answering a version query): harmless",
        "device_errors": "error reports from the device (e.g. a command rejected for its checksum or "
        "format); see the log",
        "bad_lines": "device lines that could not be parsed (framing, checksum, unknown message, 4 KiB "
        "without a newline): ignored; a noisy link or a protocol mismatch",
        "out_of_order": "packets whose device tick repeated or stepped slightly back (duplicated or "
        "reordered); dropped",
        "lost": "packets missing between consecutive ones, from gaps in the device's ticks: lost on the "
        "link (or never sent)",
        "stamp_nudged": "packets stamped at or up to 5 ms before the previous one, moved 1 µs after it: "
        "harmless jitter of the clock estimate",
        "late": "packets stamped at or before the watermark (a sample already emitted, or now − "
        "max_latency_s): they came too late; dropped",
        "cmds_sent": "commands sent to the device (one per step that brought a new cmd)",
        "cmd_dropped": "commands not delivered (port down, or the device stopped reading and old queued "
        "ones were discarded): the device's watchdog disengages the servos if commands stop",
        "cmd_clamped": "finger deviations outside [min_us, max_us], clipped before sending (per finger and "
        "command): the controller asked for more than allowed",
        "cmd_nonfinite": "fingers whose command had a NaN/inf engage or deviation: sent disengaged",
    }

    def __init__(self, *args: Any, **kw: Any) -> None:
        super().__init__(*args, **kw)
        self._ser: Any = None  # the open serial.Serial
        self._path: str | None = None  # what to (re)open
        self._proc: subprocess.Popen[bytes] | None = None
        self._folder: RunFolder | None = None  # port: emulator — the private folder of its link
        self._opened = False
        self._logged: set[str] = set()

    # -- compile time -------------------------------------------------------------------------
    @classmethod
    def example(cls) -> ft.Example:
        return ft.Example(params={"port": "sim", "rate_hz": 100.0}, rate_hz=100.0, duration_s=1.0)

    # -- state --------------------------------------------------------------------------------
    @classmethod
    def required_modules(cls, config: SerialIoConfig) -> dict[str, str]:  # type: ignore[override]
        """pyserial, except for ``port: sim`` (the device model runs in this process, no port)."""
        return {} if config.port == "sim" else super().required_modules(config)

    def reset(self) -> None:
        c = self.config
        self._sync = ClockSync()
        self._sync_resyncs = self._sync.resyncs
        self._buf = bytearray()
        self._out = bytearray()
        self._ready: list[_Sample] = []
        self._last_t = -math.inf
        self._end = -math.inf
        self._seq = 0
        self._sent: OrderedDict[int, float] = OrderedDict()  # seq -> send time (monotonic)
        self._ack = 0
        self._rtt = math.nan
        self._prev_ticks: int | None = None
        self._prev_read: float | None = None
        self._anchor: float | None = None
        self._opened_mono = 0.0
        self._next_retry = -math.inf
        self._down_since: float | None = None
        if c.port == "sim":
            # the device model only for this in-process mode: the host side speaks the protocol alone
            from flowtact.blocks.teleop.exo_device import ExoDevice, ExoParams

            params = ExoParams(rate_hz=c.rate_hz, user=(c.sim_user,) * N_FINGERS, drift_ppm=c.sim_drift_ppm)
            self._dev = ExoDevice(params, seed=int(self.rng.integers(2**31)))
            self._in_flight: deque[tuple[bytes, float]] = deque()  # (line, arrival)
            self._sim_arrival = -math.inf
            self._anchor = 0.0

    # -- lifecycle ------------------------------------------------------------------------------
    def open(self) -> None:
        c = self.config
        if c.port == "sim":
            return
        import serial  # noqa: F401  (the extra must be installed for a real port)

        self._opened = True
        if c.port == "emulator":
            self._path = self._start_emulator()
        else:
            self._path = c.port
        mono = time.monotonic()
        self._down_since = self._opened_mono = mono
        if not self._connect(mono):
            self._say("waiting", logging.WARNING, f"{self.node}: waiting for serial port {self._path}")

    def close(self) -> None:
        if self._ser is not None:
            self._out.clear()  # leave every servo disengaged (best effort: the device may be gone)
            self._out += Command(self._next_seq(), (0, 0, 0), (0, 0, 0)).format()
            if self._flush_out():
                self._drop_port()
        if self._proc is not None:
            self._proc.terminate()
            try:
                self._proc.wait(timeout=3.0)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait()
            self._proc = None
        if self._folder is not None:
            self._folder.close()
            self._folder = None
        self._opened = False

    def _start_emulator(self) -> str:
        c = self.config
        self._folder = make_run_folder("serial")  # private; swept after a kill
        link = os.path.join(self._folder.path, "exo")
        argv = python_command(
            "-m",
            "flowtact.blocks.teleop.exo_emulator",
            "--link",
            link,
            "--rate-hz",
            repr(c.rate_hz),
            "--exit-with-parent",
            *c.emulator_args,
        )
        self._proc = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE)
        assert self._proc.stdout is not None
        ready, _, _ = select.select([self._proc.stdout], [], [], c.startup_timeout_s)
        first = self._proc.stdout.readline().decode(errors="replace").strip() if ready else ""
        self._proc.stdout.close()
        if not first.startswith("PORT "):
            self.close()
            raise RuntimeError(
                f"{self.node} (serial_io): the exoskeleton emulator did not start within "
                f"{c.startup_timeout_s:g} s ({' '.join(argv[1:])}); it printed {first!r}"
            )
        return first[5:]

    # -- the step -----------------------------------------------------------------------------
    def step(self, now: float, cmd: ft.Chunk | None = None) -> dict[str, ft.Chunk]:
        if self.config.port == "sim":
            return self._step_sim(now, cmd)
        if not self._opened:
            raise RuntimeError(
                f"{self.node} (serial_io): port {self.config.port!r} is not open — open() runs before "
                "step() in a graph; offline, use port: sim"
            )
        mono = time.monotonic()
        self._track_clock(now, mono)
        latest = cmd.data[-1] if cmd is not None and len(cmd) else None
        if self._ser is None:
            self._retry(mono)
        if self._ser is None:
            if latest is not None:
                self.count("cmd_dropped")
            return self._emit(now)
        if latest is not None:
            self._out += self._command(latest, mono).format()
        if self._out and not self._flush_out():
            return self._emit(now)
        self._read()
        return self._emit(now)

    def _step_sim(self, now: float, cmd: ft.Chunk | None) -> dict[str, ft.Chunk]:
        c = self.config
        dev = self._dev
        while dev.next_time() < now:  # the device samples up to now (graph time = its true time)
            t_sample = dev.next_time()
            line = dev.sample(host_ns=round(t_sample * 1e9)).format()
            lat = (
                min(self.rng.exponential(c.sim_latency_s), 5.0 * c.sim_latency_s) if c.sim_latency_s else 0.0
            )
            self._sim_arrival = max(t_sample + lat, self._sim_arrival)  # the line is FIFO
            self._in_flight.append((line, self._sim_arrival))
        if cmd is not None and len(cmd):  # reaches the device now: later samples see it
            dev.receive(self._command(cmd.data[-1], now).format())
        while self._in_flight and self._in_flight[0][1] < now:
            line, arrival = self._in_flight.popleft()
            self._handle(line, arrival, None)
        return self._emit(now)

    # -- clock ----------------------------------------------------------------------------------
    def _track_clock(self, now: float, mono: float) -> None:
        """Move the anchor; refuse a run whose graph time outruns the wall clock (``--fast``).
        Graph time 0 comes after ``open`` and a real-time step never runs before its graph time,
        so graph time never exceeds the wall time since ``open``; measured from the first step
        instead, a worker that started late and catches up (merged ticks) would look ahead."""
        self._anchor = mono - now if self._anchor is None else min(self._anchor, mono - now)
        ahead = now - (mono - self._opened_mono)
        if ahead > FAST_RUN_SLACK_S:
            raise RuntimeError(
                f"{self.node} (serial_io): graph time runs {ahead:.1f} s ahead of the wall clock — a real "
                f"serial device ({self.config.port}) needs a real-time run (not --fast); use port: sim "
                "for fast or offline runs"
            )

    # -- connection -----------------------------------------------------------------------------
    def _connect(self, mono: float) -> bool:
        import serial

        problem = port_problem(self._path or "")
        if problem:  # the path became a file since the graph was checked: never write into it
            self._say("not_a_device", logging.ERROR, f"{self.node}: port {problem}; not opened")
            self._next_retry = mono + self.config.reconnect_s
            return False
        try:
            ser = serial.Serial(self._path, self.config.baudrate, timeout=0, write_timeout=0, exclusive=True)
            ser.reset_input_buffer()
        except (serial.SerialException, OSError, ValueError):
            self._next_retry = mono + self.config.reconnect_s
            return False
        self._ser = ser
        self._sync.resync()
        self._sync_resyncs = self._sync.resyncs
        self._buf.clear()
        self._out.clear()
        self._sent.clear()
        self._prev_ticks = None
        self._prev_read = None
        self.count("connects")
        if self.counters.get("disconnects"):
            self.count("resyncs")
        if self._down_since is not None and self.counters.get("disconnects"):
            log.info(
                "%s: serial port %s is back after %.2f s", self.node, self._path, mono - self._down_since
            )
        self._down_since = None
        self._logged.discard("waiting")
        self._out += Query().format()
        self._flush_out()
        return self._ser is not None

    def _retry(self, mono: float) -> None:
        c = self.config
        if self._proc is not None and self._proc.poll() is not None:
            raise RuntimeError(
                f"{self.node} (serial_io): the exoskeleton emulator exited (code {self._proc.returncode})"
            )
        if mono >= self._next_retry:
            self._connect(mono)
        down = self._down_since
        if self._ser is None and c.give_up_s is not None and down is not None and mono - down > c.give_up_s:
            raise RuntimeError(
                f"{self.node} (serial_io): serial port {self._path} unavailable for {c.give_up_s:g} s "
                "(give_up_s); is the device plugged in?"
            )

    def _drop_port(self) -> None:
        ser, self._ser = self._ser, None
        if ser is not None:
            with contextlib.suppress(OSError):  # the device is gone; closing may fail too
                ser.close()

    def _lost_port(self, err: BaseException) -> None:
        self._drop_port()
        mono = time.monotonic()
        self._down_since = mono
        self._next_retry = mono + self.config.reconnect_s
        self.count("disconnects")
        log.warning(
            "%s: serial port %s lost (%s); retrying every %g s",
            self.node,
            self._path,
            err,
            self.config.reconnect_s,
        )

    def _flush_out(self) -> bool:
        """Write what is queued without blocking; False if the port was lost."""
        if len(self._out) > MAX_OUT_BYTES:  # the device does not read: keep the newest commands
            cut = self._out.find(b"$", len(self._out) - MAX_OUT_BYTES)
            self.count("cmd_dropped", self._out[:cut].count(b"\n"))
            del self._out[:cut]
        try:
            fd = self._ser.fileno() if os.name == "posix" else None
            if fd is not None:  # pyserial's write spins on EAGAIN with write_timeout=0; write directly
                try:
                    n = os.write(fd, self._out)
                except BlockingIOError:
                    n = 0
            else:
                n = self._ser.write(bytes(self._out)) or 0
        except OSError as e:  # the device vanished (pyserial's SerialException is an OSError)
            self._lost_port(e)
            return False
        del self._out[:n]
        return True

    def _read(self) -> None:
        start = time.monotonic()
        try:
            data = self._ser.read(65536)
        except OSError as e:  # the device vanished (pyserial's SerialException is an OSError)
            self._lost_port(e)
            return
        arrival = time.monotonic()
        after = self._prev_read if self.config.poll_bracket else None
        self._prev_read = start
        if not data:
            return
        self._buf += data
        *lines, rest = self._buf.split(b"\n")
        self._buf = bytearray(rest)
        if len(self._buf) > 4096:  # no newline in sight: garbage
            self._buf.clear()
            self.count("bad_lines")
        for line in lines:
            if line.strip():
                self._handle(bytes(line), arrival, after)

    # -- packets --------------------------------------------------------------------------------
    def _handle(self, line: bytes, arrival: float, after: float | None) -> None:
        try:
            msg = parse_line(line, require_checksum=self.config.require_checksum)
        except ProtocolError as e:
            self.count("bad_lines")
            self._say("bad_line", logging.WARNING, f"{self.node}: ignoring a bad line from the device ({e})")
            return
        if isinstance(msg, DataPacket):
            self._packet(msg, arrival, after)
        elif isinstance(msg, Hello):
            self.count("hellos")
            if msg.version != PROTOCOL_VERSION:
                self._say(
                    "version",
                    logging.ERROR,
                    f"{self.node}: device speaks protocol {msg.version}, this host {PROTOCOL_VERSION}",
                )
            if not math.isclose(msg.rate_hz, self.config.rate_hz, rel_tol=0.01):
                self._say(
                    "rate",
                    logging.WARNING,
                    f"{self.node}: device sends {msg.rate_hz:g} Hz, rate_hz is {self.config.rate_hz:g}",
                )
        elif isinstance(msg, DeviceError):
            self.count("device_errors")
            self._say("deverr" + msg.code, logging.WARNING, f"{self.node}: device reports '{msg.code}'")
        else:
            self.count("bad_lines")

    def _packet(self, p: DataPacket, arrival: float, after: float | None) -> None:
        self.count("packets")
        sync = self._sync
        stamp = sync.add(p.tick_us, arrival, after)
        if stamp is None:
            self.count("out_of_order")
            return
        if sync.resyncs != self._sync_resyncs:
            self._sync_resyncs = sync.resyncs
            self._prev_ticks = None
            self.count("resyncs")  # the device reset (a reconnect re-syncs in _connect)
        ticks = sync.ticks
        if self._prev_ticks is not None:
            gap = round((ticks - self._prev_ticks) * 1e-6 * self.config.rate_hz) - 1
            if gap > 0:
                self.count("lost", gap)
        self._prev_ticks = ticks
        anchor = self._anchor or 0.0
        t = stamp - anchor - self.config.latency_s
        if self._last_t - NUDGE_MAX_S < t <= self._last_t:  # the estimate stepped back a little
            t = self._last_t + 1e-6
            self.count("stamp_nudged")
        if t <= self._end or t <= self._last_t:
            self.count("late")
            return
        self._last_t = t
        if p.ack != self._ack:
            self._ack = p.ack
            sent = self._sent.get(p.ack)
            if sent is not None:
                self._rtt = arrival - sent
        send_t = p.host_ns * 1e-9 - anchor if p.host_ns is not None else math.nan
        self._ready.append(
            _Sample(t, p.phi_mrad, p.fsr_adc, p.status, (sync.epoch_tick + ticks) * 1e-6, self._rtt, send_t)
        )

    def _next_seq(self) -> int:
        self._seq = self._seq % 65535 + 1  # 1..65535; 0 means "no command yet"
        return self._seq

    def _command(self, sample: np.ndarray, sent_at: float) -> Command:
        c = self.config
        eng, dev = [], []
        for f in range(N_FINGERS):
            e, d = float(sample[f, 0]), float(sample[f, 1])
            if not (math.isfinite(e) and math.isfinite(d)):
                self.count("cmd_nonfinite")
                eng.append(0)
                dev.append(0)
                continue
            on = e >= 0.5
            clipped = min(max(d, c.min_us), c.max_us)
            if clipped != d:
                self.count("cmd_clamped")
            eng.append(int(on))
            dev.append(round(clipped) if on else 0)
        seq = self._next_seq()
        self._sent[seq] = sent_at
        while len(self._sent) > SENT_MEMORY:
            self._sent.popitem(last=False)
        self.count("cmds_sent")
        return Command(seq, (eng[0], eng[1], eng[2]), (dev[0], dev[1], dev[2]))

    # -- output ---------------------------------------------------------------------------------
    def _emit(self, now: float) -> dict[str, ft.Chunk]:
        ready = [s for s in self._ready if s.t < now]
        self._ready = self._ready[len(ready) :]
        # held samples (t >= now) stay after the watermark: it never passes now
        self._end = max(self._end, ready[-1].t if ready else -math.inf, now - self.config.max_latency_s)
        t = np.array([s.t for s in ready], np.float64)
        n = len(ready)
        out: dict[str, ft.Chunk] = {}
        want = self.demanded
        if "angles" in want:
            phi = np.array([s.phi for s in ready], np.float64).reshape(n, N_FINGERS, 3) * 1e-3
            out["angles"] = ft.Chunk(t, phi, self._end)
        if "fsr" in want:
            out["fsr"] = ft.Chunk(
                t, np.array([s.fsr for s in ready], np.float64).reshape(n, N_FINGERS), self._end
            )
        if "engaged" in want:
            bits = np.array([s.status for s in ready], np.int64).reshape(n, 1)
            out["engaged"] = ft.Chunk(t, ((bits >> np.arange(N_FINGERS)) & 1).astype(np.float64), self._end)
        for name in ("device_t", "rtt", "send_t"):
            if name in want:
                out[name] = ft.Chunk(t, np.array([getattr(s, name) for s in ready], np.float64), self._end)
        return out

    def _say(self, key: str, level: int, message: str) -> None:
        """Log a message once per key (until the key is discarded)."""
        if key not in self._logged:
            self._logged.add(key)
            log.log(level, message)
