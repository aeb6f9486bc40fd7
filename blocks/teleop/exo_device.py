"""A pure model of the three-finger Remote Feelings exoskeleton worn by a simulated user.

:class:`ExoDevice` is stepped in device time (deterministic for a seed, no I/O): servo + encoders
+ FSR per finger, a command watchdog and the device's own clamps; it speaks the line protocol of
:mod:`flowtact.blocks.teleop.exo_protocol`. :mod:`flowtact.blocks.teleop.exo_emulator` serves it on a
pseudo-terminal; ``serial_io`` with ``port: sim`` steps it in graph time.

Model (per finger: thumb, index, middle)
-----------------------------------------
The hand moves along a one-dimensional grasp: closure ``c`` (0 open, 1 closed) sets the finger
pose ``θ(c) = THETA_OPEN + c·(THETA_CLOSED − THETA_OPEN)``, and the exoskeleton angles worn on that
pose are ``φ = phi_from_theta(θ)`` (:mod:`flowtact.blocks.teleop.exo`, the same kinematic constants the
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

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from flowtact.blocks.teleop.exo import phi_from_theta
from flowtact.blocks.teleop.exo_protocol import (
    ADC_MAX,
    DEVICE_MAX_DEV_US,
    DEVICE_NAME,
    N_FINGERS,
    PROTOCOL_VERSION,
    TICK_WRAP,
    Command,
    DataPacket,
    DeviceError,
    Hello,
    ProtocolError,
    Query,
    parse_line,
)

__all__ = [
    "CLOSED_PHI",
    "FSR_A",
    "FSR_B",
    "OPEN_PHI",
    "THETA_CLOSED",
    "THETA_OPEN",
    "US_PER_RAD",
    "ExoDevice",
    "ExoParams",
    "closure_of_phi1",
    "phi_of_closure",
]

#: A standard hobby servo turns π rad for 2000 µs of pulse width.
US_PER_RAD = 2000.0 / math.pi
#: Eq. 3.10: |F_FSR| = FSR_A · exp(FSR_B · R).
FSR_A = 0.6867
FSR_B = 0.0023

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
#: φ (241, 3, 3) along the closure grid, from the kinematics of :mod:`flowtact.blocks.teleop.exo`.
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


def _smooth(x: float) -> float:
    x = min(max(x, 0.0), 1.0)
    return x * x * (3.0 - 2.0 * x)
