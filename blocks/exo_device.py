"""The Remote Feelings exoskeleton as seen over its serial line: protocol, device model, emulator.

Three parts, usable separately:

* the **line protocol** (``docs/serial-protocol.md``): :func:`frame` / :func:`unframe` (``$…*XX``
  lines with an NMEA-style XOR checksum), :class:`DataPacket`, :class:`Command`, :class:`Hello`
  and :func:`parse_line`;
* :class:`ExoDevice`, a pure model of the three-finger exoskeleton worn by a simulated user, stepped
  in device time (deterministic for a seed, no I/O): servo + encoders + FSR per finger, a command
  watchdog, and the device's own clamps;
* the emulator process, ``flowtact sim exo`` (:func:`main`): serves an :class:`ExoDevice` on a
  pseudo-terminal with :mod:`flowtact.ptydevice`, so the host side runs over a real tty.

Model (per finger: thumb, index, middle)
-----------------------------------------
The hand moves along a one-dimensional grasp: closure ``c`` (0 open, 1 closed) sets the finger
pose ``θ(c) = THETA_OPEN + c·(THETA_CLOSED − THETA_OPEN)``, and the exoskeleton angles worn on that
pose are ``φ = phi_from_theta(θ)`` (:mod:`flowtact.blocks.exo`, the same kinematic constants the
host's inverse kinematics uses; tabulated on a closure grid and interpolated). So the passive
joints φ2, φ3 follow φ1 through the exoskeleton's geometry, φ1 is monotonic in ``c``, and the
host recovers θ exactly (up to the encoder noise). ``OPEN_PHI`` / ``CLOSED_PHI`` are φ at c = 0 / 1.

The user's intent is a closure ``c_user(t)``; in ``grasp`` mode it cycles every ``period_s``:
rest open 0.5 s → close over ``close_s`` → squeeze (the intent goes on past closed, by
``max_push_n / user_stiffness_n``, over ``squeeze_s``) → open over ``open_s`` to as far below 0
(the user pulls) → rest. ``idle`` holds c = 0.3. Fingers are staggered by ``stagger_s``.

* Servo **disengaged**: back-driven, it follows the finger; the finger follows the intent within
  [0, 1] and the FSR sees only the linkage friction (``friction_n``, signed with the motion). With
  ``object_stiffness_n`` set (standalone ``--object-stiffness`` mode, no host needed) a virtual
  object from ``object_closure`` on pushes back like a spring: the finger settles where the
  user's push balances it and the FSR sees that push. A host engage takes precedence.
* Servo **engaged** (host command engage = 1): it latches its angle at that moment (the contact)
  and holds ``contact + deviation`` (µs of PWM; a standard servo turns π rad per 2000 µs; positive
  deviation lets the finger close further), moving there at ``slew_rad_s`` at most, within the
  hand's range. The finger is stopped at the servo; the user's push is ``user_stiffness_n ·
  (c_user − c)`` clipped to ±``max_push_n``: positive while squeezing, negative when pulling open.

FSR: the spring preload presses the servo on the FSR with ``F_rest`` (≈ 3 N, ±5 % per finger);
``|F| = F_rest + F_push`` and the ADC reads eq. 3.10 inverted, ``R = ln(|F| / 0.6867) / 0.0023``,
plus ``fsr_noise_adc`` noise, rounded and clipped to 0..1023 (so a push of −F_rest or less reads 0
and the largest readable push is ≈ 4.2 N). Encoders report millirad with ``encoder_noise_rad``.

Safety on the device (defence in depth): deviations are clamped to ±``DEVICE_MAX_DEV_US`` and the
servo target to the hand's range; with no valid command for ``watchdog_s`` every servo disengages
(status bit 3 until the next command). Lines with a bad checksum are ignored (``$E,badsum``).

Clock: the device counts µs in a uint32 that wraps (an Arduino's ``micros()``), starting at a
random value; ``drift_ppm`` makes its oscillator run fast (positive) or slow.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import signal
import sys
import tempfile
import time
from dataclasses import dataclass
from typing import Literal, TextIO

import numpy as np

from flowtact.blocks.exo import phi_from_theta

__all__ = [
    "CLOSED_PHI",
    "DEVICE_MAX_DEV_US",
    "FSR_A",
    "FSR_B",
    "OPEN_PHI",
    "PROTOCOL_VERSION",
    "THETA_CLOSED",
    "THETA_OPEN",
    "US_PER_RAD",
    "Command",
    "DataPacket",
    "ExoDevice",
    "Hello",
    "ProtocolError",
    "checksum",
    "closure_of_phi1",
    "frame",
    "main",
    "parse_line",
    "phi_of_closure",
    "unframe",
]

PROTOCOL_VERSION = 1
DEVICE_NAME = "flowtact-exo"
N_FINGERS = 3
#: A standard hobby servo turns π rad for 2000 µs of pulse width.
US_PER_RAD = 2000.0 / math.pi
#: The device's own clamp on commanded deviations (the host clamps tighter).
DEVICE_MAX_DEV_US = 800
#: Eq. 3.10: |F_FSR| = FSR_A · exp(FSR_B · R).
FSR_A = 0.6867
FSR_B = 0.0023
ADC_MAX = 1023
TICK_WRAP = 1 << 32
SEQ_WRAP = 1 << 16

#: The simulated hand's finger poses θ (MCP, PIP, DIP; thumb: MCP, IP, 0), rad, per finger (thumb,
#: index, middle), open (relaxed, slightly flexed: a flat finger is a kinematic singularity where a
#: milliradian of encoder noise puts the pose out of the IK's reach) and closed; the hand moves
#: between them along ``θ(c) = open + c·(closed − open)`` with c the closure (0 open, 1 closed). The
#: sums of angles, (0.4, 0.7, 0.7) rad open and (1.8, 3.2, 3.2) rad closed, are the defaults of
#: the host's ``gripper_command`` calibration.
THETA_OPEN = np.array([[0.2, 0.2, 0.0], [0.2, 0.3, 0.2], [0.2, 0.3, 0.2]])
THETA_CLOSED = np.array(
    [
        [math.radians(45.0), 1.8 - math.radians(45.0), 0.0],
        [math.radians(66.0), math.radians(70.0), 3.2 - math.radians(136.0)],
        [math.radians(66.0), math.radians(70.0), 3.2 - math.radians(136.0)],
    ]
)
#: Closure grid of the pose table (a little over-travel on both sides).
_C_GRID = np.linspace(-0.1, 1.1, 241)
#: φ (241, 3, 3) along the closure grid, from the kinematics of :mod:`flowtact.blocks.exo`.
_PHI_TABLE = phi_from_theta(THETA_OPEN + _C_GRID[:, None, None] * (THETA_CLOSED - THETA_OPEN))
if not (np.diff(_PHI_TABLE[:, :, 0], axis=0) > 0).all():  # the servo angle must determine the pose
    raise ImportError(
        "exo_device: φ1 is not monotonic along the simulated grasp; check the kinematic constants"
    )
#: Exoskeleton joint angles (φ1 servo, φ2, φ3 passive; rad) worn on the open and closed poses, per
#: finger: what the device reports there (the gripper calibration uses these).
OPEN_PHI = phi_from_theta(THETA_OPEN)
CLOSED_PHI = phi_from_theta(THETA_CLOSED)


def phi_of_closure(c: np.ndarray) -> np.ndarray:
    """Exoskeleton angles (3, 3) for per-finger closures ``c`` (3,) (interpolated, exact at the grid)."""
    out = np.empty((N_FINGERS, 3))
    for f in range(N_FINGERS):
        for k in range(3):
            out[f, k] = np.interp(c[f], _C_GRID, _PHI_TABLE[:, f, k])
    return out


def closure_of_phi1(phi1: np.ndarray) -> np.ndarray:
    """The closure (3,) at which each finger's servo angle is ``phi1`` (3,)."""
    return np.array([np.interp(phi1[f], _PHI_TABLE[:, f, 0], _C_GRID) for f in range(N_FINGERS)])


# -- line protocol ------------------------------------------------------------------------------


class ProtocolError(ValueError):
    """A line that is not a valid protocol message (bad framing, checksum, field count or range)."""


def checksum(body: bytes) -> int:
    """XOR of all bytes of ``body`` (what lies between ``$`` and ``*``)."""
    c = 0
    for b in body:
        c ^= b
    return c


def frame(body: str) -> bytes:
    """``$body*XX\\n`` with XX the checksum in upper-case hex."""
    raw = body.encode("ascii")
    return b"$" + raw + b"*%02X\n" % checksum(raw)


def unframe(line: bytes, *, require_checksum: bool = True) -> str:
    """The body of one line (without its ``\\n``); raises :class:`ProtocolError`.

    Anything before the last ``$`` is ignored (line noise at connect); a ``\\r`` before the end is
    tolerated. Without ``require_checksum`` a line with no ``*XX`` is accepted, but a wrong
    checksum is always an error.
    """
    line = line.rstrip(b"\r\n")
    start = line.rfind(b"$")
    if start < 0:
        raise ProtocolError("no '$' start")
    line = line[start + 1 :]
    star = line.rfind(b"*")
    if star < 0:
        if require_checksum:
            raise ProtocolError("no checksum")
        body = line
    else:
        body, tail = line[:star], line[star + 1 :]
        try:
            want = int(tail, 16)
        except ValueError:
            raise ProtocolError("checksum is not hex") from None
        if len(tail) != 2 or checksum(body) != want:
            raise ProtocolError("checksum mismatch")
    try:
        return body.decode("ascii")
    except UnicodeDecodeError:
        raise ProtocolError("non-ASCII bytes") from None


@dataclass(frozen=True)
class DataPacket:
    """One device sample: tick (µs, uint32), 9 angles (mrad), 3 FSR readings, status, last ack."""

    tick_us: int
    phi_mrad: tuple[int, ...]  # φ1, φ2, φ3 of thumb, then index, then middle
    fsr_adc: tuple[int, int, int]
    status: int  # bits 0-2: servo engaged (thumb, index, middle); bit 3: watchdog tripped
    ack: int  # sequence number of the last command applied (0 before any)
    host_ns: int | None = None  # optional 'h=' field: true sampling time on the host clock (emulators)

    def format(self) -> bytes:
        fields = ["D", str(self.tick_us), *map(str, self.phi_mrad), *map(str, self.fsr_adc)]
        fields += [str(self.status), str(self.ack)]
        if self.host_ns is not None:
            fields.append(f"h={self.host_ns}")
        return frame(",".join(fields))


@dataclass(frozen=True)
class Command:
    """Host → device: per finger engage (0/1) and deviation (µs); ``seq`` is echoed as the ack."""

    seq: int
    engage: tuple[int, int, int]
    dev_us: tuple[int, int, int]

    def format(self) -> bytes:
        parts = ["C", str(self.seq)]
        for e, d in zip(self.engage, self.dev_us, strict=True):
            parts += [str(int(e)), str(int(d))]
        return frame(",".join(parts))


@dataclass(frozen=True)
class Hello:
    """Device → host at connect and on a ``$V`` query: name, protocol version, packet rate."""

    name: str
    version: int
    rate_hz: float

    def format(self) -> bytes:
        return frame(f"H,{self.name},{self.version},{self.rate_hz:g}")


@dataclass(frozen=True)
class Query:
    """Host → device ``$V``: please send your hello line."""

    def format(self) -> bytes:
        return frame("V")


@dataclass(frozen=True)
class DeviceError:
    """Device → host ``$E,<code>``: the device rejected something (``badsum``, ``badcmd``)."""

    code: str

    def format(self) -> bytes:
        return frame(f"E,{self.code}")


Message = DataPacket | Command | Hello | Query | DeviceError


def _int(s: str, lo: int, hi: int, what: str) -> int:
    try:
        v = int(s)
    except ValueError:
        raise ProtocolError(f"{what} is not an integer: {s!r}") from None
    if not lo <= v <= hi:
        raise ProtocolError(f"{what} out of range [{lo}, {hi}]: {v}")
    return v


def parse_line(line: bytes, *, require_checksum: bool = True) -> Message:
    """Parse one line (with or without its newline) into a message; raises :class:`ProtocolError`."""
    f = unframe(line, require_checksum=require_checksum).split(",")
    kind = f[0]
    if kind == "D":
        extras = [x for x in f[1:] if "=" in x]
        fixed = [x for x in f[1:] if "=" not in x]
        if len(fixed) != 15:
            raise ProtocolError(f"data line has {len(fixed)} fields, expected 15")
        tick = _int(fixed[0], 0, TICK_WRAP - 1, "tick")
        phi = tuple(_int(x, -10_000, 10_000, "angle") for x in fixed[1:10])
        fsr = tuple(_int(x, 0, ADC_MAX, "fsr") for x in fixed[10:13])
        status = _int(fixed[13], 0, 255, "status")
        ack = _int(fixed[14], 0, SEQ_WRAP - 1, "ack")
        host_ns = None
        for x in extras:
            key, _, val = x.partition("=")
            if key == "h":
                host_ns = _int(val, 0, 1 << 63, "h")
        return DataPacket(tick, phi, fsr, status, ack, host_ns)  # type: ignore[arg-type]
    if kind == "C":
        if len(f) != 8:
            raise ProtocolError(f"command has {len(f) - 1} fields, expected 7")
        seq = _int(f[1], 0, SEQ_WRAP - 1, "seq")
        eng = tuple(_int(x, 0, 1, "engage") for x in f[2::2])
        dev = tuple(_int(x, -10_000, 10_000, "deviation") for x in f[3::2])
        return Command(seq, eng, dev)  # type: ignore[arg-type]
    if kind == "H":
        if len(f) != 4:
            raise ProtocolError("hello needs name, version, rate")
        try:
            rate = float(f[3])
        except ValueError:
            raise ProtocolError(f"hello rate is not a number: {f[3]!r}") from None
        return Hello(f[1], _int(f[2], 0, 1 << 16, "version"), rate)
    if kind == "V" and len(f) == 1:
        return Query()
    if kind == "E" and len(f) == 2:
        return DeviceError(f[1])
    raise ProtocolError(f"unknown message {kind!r}")


# -- the device model ---------------------------------------------------------------------------

UserMode = Literal["grasp", "idle"]


@dataclass(frozen=True)
class ExoParams:
    """Parameters of :class:`ExoDevice` (see the module notes). Closure c: 0 open, 1 closed."""

    rate_hz: float = 100.0
    user: tuple[UserMode, UserMode, UserMode] = ("grasp", "grasp", "grasp")
    period_s: float = 5.0
    close_s: float = 1.0
    squeeze_s: float = 1.5
    open_s: float = 1.0
    stagger_s: float = 0.05
    max_push_n: float = 3.0
    user_stiffness_n: float = 10.0  # N per unit of closure the user's intent is ahead of the finger
    friction_n: float = 0.05
    f_rest_n: float = 3.0
    slew_rad_s: float = 8.0
    watchdog_s: float = 0.5
    drift_ppm: float = 0.0
    encoder_noise_rad: float = 0.002
    fsr_noise_adc: float = 2.0
    object_stiffness_n: float | None = None  # standalone virtual object, N per unit of closure
    object_closure: float = 0.6

    def __post_init__(self) -> None:
        if self.period_s - 0.5 - self.close_s - self.squeeze_s - self.open_s < 0:
            raise ValueError("period_s must cover 0.5 s rest + close_s + squeeze_s + open_s")
        if not (self.rate_hz > 0 and self.user_stiffness_n > 0 and self.max_push_n > 0):
            raise ValueError("rate_hz, user_stiffness_n and max_push_n must be > 0")
        if len(self.user) != N_FINGERS or any(u not in ("grasp", "idle") for u in self.user):
            raise ValueError("user must list 'grasp' or 'idle' for each of the 3 fingers")


class ExoDevice:
    """The exoskeleton firmware + mechanics + a simulated user hand, stepped in device time.

    ``sample()`` advances to the next device tick and returns its :class:`DataPacket`;
    ``receive(line)`` handles one host line and returns the reply lines; ``t`` is the true
    elapsed time (s) since power-on, ``next_time()`` the true time of the next sample. State per
    finger: closure ``c``, servo angle ``servo`` (= φ1), ``engaged``, ``push`` (N). Deterministic
    for a given seed; the only randomness is noise, the per-finger preload and the initial tick.
    """

    def __init__(
        self, params: ExoParams | None = None, *, seed: int = 0, tick0_us: int | None = None
    ) -> None:
        self.p = params or ExoParams()
        self.rng = np.random.default_rng(seed)
        self.f_rest = self.p.f_rest_n * (1.0 + 0.05 * self.rng.standard_normal(N_FINGERS))
        self.power_on(tick0_us)

    # -- power cycle ----------------------------------------------------------------------
    def power_on(self, tick0_us: int | None = None) -> None:
        """(Re)start the firmware: clock from ``tick0_us`` (random if None), servos disengaged."""
        self.tick0 = int(self.rng.integers(0, TICK_WRAP)) if tick0_us is None else int(tick0_us) % TICK_WRAP
        self.n = 0  # samples taken
        self.t = 0.0
        self.c = np.clip(self.user_closure(0.0), 0.0, 1.0)
        self.servo = phi_of_closure(self.c)[:, 0]
        self.engaged = np.zeros(N_FINGERS, bool)
        self.contact = self.servo.copy()
        self.dev_us = np.zeros(N_FINGERS)
        self.push = np.zeros(N_FINGERS)
        self.last_cmd_t = -math.inf
        self.watchdog = False
        self.ack = 0
        self.bad_lines = 0
        self.commands = 0

    def hello(self) -> bytes:
        return Hello(DEVICE_NAME, PROTOCOL_VERSION, self.p.rate_hz).format()

    # -- clock --------------------------------------------------------------------------
    def next_time(self) -> float:
        """True time (s since power-on) of the next sample: the device ticks every 1/rate of its clock."""
        return self.n / (self.p.rate_hz * (1.0 + self.p.drift_ppm * 1e-6))

    def tick_at(self, t: float) -> int:
        """The device's µs counter at true time ``t``."""
        return (self.tick0 + round(t * (1.0 + self.p.drift_ppm * 1e-6) * 1e6)) % TICK_WRAP

    # -- user ----------------------------------------------------------------------------
    def user_closure(self, t: float) -> np.ndarray:
        """The simulated user's intended closure per finger at true time ``t`` (may leave [0, 1]).

        Beyond 1 the user squeezes, below 0 they pull open: against an engaged servo the
        difference becomes push force, ``user_stiffness_n`` N per unit.
        """
        p = self.p
        over = p.max_push_n / p.user_stiffness_n
        out = np.empty(N_FINGERS)
        for f in range(N_FINGERS):
            if p.user[f] == "idle":
                out[f] = 0.3
                continue
            tau = (t - f * p.stagger_s) % p.period_s
            t_close, t_squeeze = 0.5 + p.close_s, 0.5 + p.close_s + p.squeeze_s
            t_open = t_squeeze + p.open_s
            if tau < 0.5:
                c = -over
            elif tau < t_close:
                c = -over + (1.0 + over) * _smooth((tau - 0.5) / p.close_s)
            elif tau < t_squeeze:
                c = 1.0 + over * (tau - t_close) / p.squeeze_s
            elif tau < t_open:
                c = 1.0 + over - (1.0 + 2.0 * over) * _smooth((tau - t_squeeze) / p.open_s)
            else:
                c = -over
            out[f] = c
        return out

    # -- host commands --------------------------------------------------------------------
    def apply(self, cmd: Command) -> None:
        """Apply a host command now (engage latches the contact angle; clamps the deviation)."""
        for f in range(N_FINGERS):
            if cmd.engage[f]:
                if not self.engaged[f]:
                    self.contact[f] = self.servo[f]
                self.engaged[f] = True
                self.dev_us[f] = float(np.clip(cmd.dev_us[f], -DEVICE_MAX_DEV_US, DEVICE_MAX_DEV_US))
            else:
                self.engaged[f] = False
                self.dev_us[f] = 0.0
        self.ack = cmd.seq
        self.last_cmd_t = self.t
        self.watchdog = False
        self.commands += 1

    def receive(self, line: bytes) -> list[bytes]:
        """Handle one line from the host; returns the lines to send back."""
        try:
            msg = parse_line(line)
        except ProtocolError as e:
            self.bad_lines += 1
            return [DeviceError("badsum" if "checksum" in str(e) else "badcmd").format()]
        if isinstance(msg, Command):
            self.apply(msg)
            return []
        if isinstance(msg, Query):
            return [self.hello()]
        self.bad_lines += 1
        return [DeviceError("badcmd").format()]

    # -- one tick ------------------------------------------------------------------------
    def advance(self) -> None:
        """Move the mechanics to the next tick (no sensor reading)."""
        p = self.p
        t_new = self.next_time()
        dt = max(t_new - self.t, 0.0)
        self.t = t_new
        self.n += 1
        if self.engaged.any() and self.t - self.last_cmd_t > p.watchdog_s:
            self.engaged[:] = False
            self.dev_us[:] = 0.0
            self.watchdog = True
        want = self.user_closure(self.t)
        lo, hi = _PHI_TABLE[20, :, 0], _PHI_TABLE[220, :, 0]  # φ1 at closure 0 and 1
        prev = self.c.copy()
        for f in range(N_FINGERS):
            if self.engaged[f]:
                target = min(max(self.contact[f] + self.dev_us[f] / US_PER_RAD, lo[f]), hi[f])
                step = p.slew_rad_s * dt
                self.servo[f] += min(max(target - self.servo[f], -step), step)
                self.c[f] = float(np.interp(self.servo[f], _PHI_TABLE[:, f, 0], _C_GRID))
                push = p.user_stiffness_n * (want[f] - self.c[f])
                self.push[f] = min(max(push, -p.max_push_n), p.max_push_n)
                continue
            free = min(max(want[f], 0.0), 1.0)
            k_o = p.object_stiffness_n
            if k_o is not None and free > p.object_closure:
                k_u = p.user_stiffness_n
                eq = (k_u * want[f] + k_o * p.object_closure) / (k_u + k_o)
                self.c[f] = min(eq, free)
                self.push[f] = min(k_o * (self.c[f] - p.object_closure), p.max_push_n)
            else:
                self.c[f] = free
                moved = self.c[f] - prev[f]
                self.push[f] = p.friction_n * float(np.sign(moved)) if abs(moved) > 1e-9 else 0.0
            self.servo[f] = float(np.interp(self.c[f], _C_GRID, _PHI_TABLE[:, f, 0]))

    def sample(self, host_ns: int | None = None) -> DataPacket:
        """Advance to the next tick and read the sensors there (``host_ns``: optional truth field)."""
        self.advance()
        p = self.p
        phi = phi_of_closure(self.c)
        phi_noisy = phi + p.encoder_noise_rad * self.rng.standard_normal(phi.shape)
        force = np.maximum(self.f_rest + self.push, 1e-9)
        r = np.log(force / FSR_A) / FSR_B + p.fsr_noise_adc * self.rng.standard_normal(N_FINGERS)
        r = np.clip(np.round(r), 0, ADC_MAX).astype(int)
        status = int(sum(1 << f for f in range(N_FINGERS) if self.engaged[f])) | (8 if self.watchdog else 0)
        return DataPacket(
            tick_us=self.tick_at(self.t),
            phi_mrad=tuple(round(float(x) * 1000.0) for x in phi_noisy.ravel()),
            fsr_adc=(int(r[0]), int(r[1]), int(r[2])),
            status=status,
            ack=self.ack,
            host_ns=host_ns,
        )

    def angles(self) -> np.ndarray:
        """True joint angles (3, 3) rad: φ1 and the passive φ2, φ3 of the current pose."""
        return phi_of_closure(self.c)


def _smooth(x: float) -> float:
    x = min(max(x, 0.0), 1.0)
    return x * x * (3.0 - 2.0 * x)


# -- the emulator process -----------------------------------------------------------------------


class _ExoLine:
    """Adapter from :class:`ExoDevice` to :class:`flowtact.ptydevice.LineDevice` (host-clock times).

    With a ``log`` file it writes one line per host command the device applied and per watchdog
    trip, stamped with the host's monotonic clock: ``<t> cmd <seq> engage=<e,e,e> dev=<d,d,d>``
    and ``<t> watchdog`` (what a bench logger on the device's side would see).
    """

    def __init__(self, dev: ExoDevice, truth: bool, reset_on_replug: bool, log: TextIO | None = None) -> None:
        self.dev = dev
        self.truth = truth
        self.reset_on_replug = reset_on_replug
        self.log = log
        self.t0 = time.monotonic()

    def next_due(self) -> float:
        return self.t0 + self.dev.next_time()

    def tick(self, now: float) -> list[bytes]:
        # the sample belongs to its scheduled tick; waking late is a send delay, as on a real board
        host_ns = round((self.t0 + self.dev.next_time()) * 1e9) if self.truth else None
        tripped = self.dev.watchdog
        out = [self.dev.sample(host_ns).format()]
        if self.log is not None and self.dev.watchdog and not tripped:
            self.log.write(f"{now:.6f} watchdog\n")
        return out

    def receive(self, line: bytes, now: float) -> list[bytes]:
        applied = self.dev.commands
        out = self.dev.receive(line)
        if self.log is not None and self.dev.commands > applied:
            d = self.dev
            engage = ",".join(str(int(e)) for e in d.engaged)
            dev = ",".join(f"{x:g}" for x in d.dev_us)
            self.log.write(f"{now:.6f} cmd {d.ack} engage={engage} dev={dev}\n")
        return out

    def plugged(self, now: float, first: bool) -> list[bytes]:
        if not first and self.reset_on_replug:  # a USB unplug power-cycles the board
            self.dev.power_on()
            self.t0 = now
        while self.next_due() < now:  # a board powered on its own kept sampling; that data is lost
            self.dev.sample()
        return [self.dev.hello()]


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="flowtact sim exo",
        description="Emulate the Remote Feelings exoskeleton (3 fingers) on a pseudo-terminal. Prints "
        "'PORT <path>' first, then serves until SIGTERM/SIGINT; SIGUSR1 simulates an unplug/replug.",
    )
    ap.add_argument("--link", help="stable symlink to the pty (default: a temporary path, printed)")
    ap.add_argument("--rate-hz", type=float, default=100.0, help="packets per second (default 100)")
    ap.add_argument("--drift-ppm", type=float, default=50.0, help="device clock error in ppm (default 50)")
    ap.add_argument("--offset-s", type=float, default=None, help="initial device clock in s (default random)")
    ap.add_argument("--latency-ms", type=float, default=0.0, help="fixed delay before each write (ms)")
    ap.add_argument("--jitter-ms", type=float, default=0.0, help="extra uniform random write delay (ms)")
    ap.add_argument("--seed", type=int, default=0, help="random seed (noise, preload, clock start)")
    ap.add_argument(
        "--user", nargs="+", choices=("grasp", "idle"), default=["grasp"], help="user per finger (1 or 3)"
    )
    ap.add_argument("--period-s", type=float, default=5.0, help="grasp cycle period (default 5 s)")
    ap.add_argument("--max-push-n", type=float, default=3.0, help="the user's largest push (default 3 N)")
    ap.add_argument(
        "--object-stiffness",
        type=float,
        default=None,
        help="standalone mode: a virtual object of this stiffness (N per unit closure) stops the fingers",
    )
    ap.add_argument(
        "--object-closure", type=float, default=0.6, help="closure (0 open, 1 closed) where the object starts"
    )
    ap.add_argument("--replug-s", type=float, default=0.3, help="gap between unplug and replug (SIGUSR1)")
    ap.add_argument("--no-reset-on-replug", action="store_true", help="keep the device clock across a replug")
    ap.add_argument("--no-noise", action="store_true", help="no sensor noise")
    ap.add_argument(
        "--truth", action="store_true", help="add the true sampling time (host monotonic ns) as field h="
    )
    ap.add_argument("--exit-with-parent", action="store_true", help="stop when the parent process exits")
    ap.add_argument(
        "--log",
        metavar="FILE",
        help="append each applied command and watchdog trip (host monotonic s) to FILE",
    )
    return ap


def main(argv: list[str] | None = None) -> int:
    """``flowtact sim exo``: serve an emulated exoskeleton on a pty until SIGTERM/SIGINT."""
    from flowtact.ptydevice import PtyServer

    args = _parser().parse_args(argv)
    if len(args.user) not in (1, N_FINGERS):
        print("--user takes 1 or 3 values", file=sys.stderr)
        return 2
    users = tuple(args.user * N_FINGERS if len(args.user) == 1 else args.user)
    params = ExoParams(
        rate_hz=args.rate_hz,
        user=users,  # type: ignore[arg-type]
        period_s=args.period_s,
        max_push_n=args.max_push_n,
        drift_ppm=args.drift_ppm,
        object_stiffness_n=args.object_stiffness,
        object_closure=args.object_closure,
        encoder_noise_rad=0.0 if args.no_noise else ExoParams.encoder_noise_rad,
        fsr_noise_adc=0.0 if args.no_noise else ExoParams.fsr_noise_adc,
    )
    tick0 = None if args.offset_s is None else round(args.offset_s * 1e6)
    dev = ExoDevice(params, seed=args.seed, tick0_us=tick0)
    tmp = None
    link = args.link
    if link is None:
        tmp = tempfile.mkdtemp(prefix="flowtact-exo-")
        link = os.path.join(tmp, "tty")
    log = open(args.log, "a", buffering=1) if args.log else None  # noqa: SIM115 (closed below)
    server = PtyServer(
        _ExoLine(dev, args.truth, not args.no_reset_on_replug, log),
        link,
        latency_s=args.latency_ms * 1e-3,
        jitter_s=args.jitter_ms * 1e-3,
        replug_s=args.replug_s,
        seed=args.seed,
    )
    signal.signal(signal.SIGTERM, lambda *_: server.stop())
    signal.signal(signal.SIGINT, lambda *_: server.stop())
    signal.signal(signal.SIGUSR1, lambda *_: server.unplug())
    try:
        server.open()
        print(f"PORT {link}", flush=True)
        server.serve(parent_pid=os.getppid() if args.exit_with_parent else None)
    finally:
        server.close()
        if log is not None:
            log.close()
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.rmdir(tmp)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
