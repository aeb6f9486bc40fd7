"""``flowtact sim exo``: serve an :class:`~flowtact.blocks.teleop.exo_device.ExoDevice` on a
pseudo-terminal, so the host side (``serial_io``) runs over a real tty with no hardware."""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import tempfile
import time
from typing import TextIO

from flowtact.blocks.teleop.exo_device import ExoDevice, ExoParams
from flowtact.blocks.teleop.exo_protocol import (
    N_FINGERS,
)
from flowtact.command import CommandParser, run_command
from flowtact.limits import MAX_SEED, cli_float, cli_int

# -- the emulator process -----------------------------------------------------------------------


__all__ = ["main"]

# -- the documented ranges of the flags (a value outside is a one-line usage error, exit 2) ---------

MAX_RATE_HZ = 10_000.0
"""Fastest packet rate: the board sends at 100 Hz; a pty and a Python loop keep up to about 10 kHz."""
MAX_DRIFT_PPM = 10_000.0
"""Largest clock error either way (1 %: a crystal is within 100 ppm, an RC oscillator within 1 %)."""
MAX_OFFSET_S = float(1 << 32) * 1e-6
"""Largest initial device clock: the 32-bit microsecond counter wraps there (about 71.6 min)."""
MAX_DELAY_MS = 10_000.0
"""Longest write delay, fixed or random (10 s: the host's watchdog has long tripped by then)."""
_P = ExoParams()
MIN_PERIOD_S = 0.5 + _P.close_s + _P.squeeze_s + _P.open_s
"""Shortest grasp cycle: rest, close, squeeze and open must fit in it (4 s)."""
MAX_PERIOD_S = 3600.0
"""Longest grasp cycle (an hour)."""
MAX_PUSH_N = 100.0
"""Strongest push of the emulated user (a human finger pushes well under 100 N)."""
MAX_STIFFNESS = 1e6
"""Stiffest virtual object, N per unit of closure (stiffer is a wall at the time step used)."""
MAX_REPLUG_S = 60.0
"""Longest gap between an unplug and the replug (SIGUSR1)."""


class _ExoLine:
    """Adapter from :class:`ExoDevice` to :class:`flowtact.blocks.devices.ptyserver.LineDevice` (host-clock times).

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
    ap = CommandParser(
        prog="flowtact sim exo",
        description="Emulate the Remote Feelings exoskeleton (3 fingers) on a pseudo-terminal. Prints "
        "'PORT <path>' first, then serves until SIGTERM/SIGINT; SIGUSR1 simulates an unplug/replug.",
    )
    ap.add_argument("--link", help="stable symlink to the pty (default: a temporary path, printed)")
    ap.add_argument(
        "--rate-hz",
        type=cli_float(0, MAX_RATE_HZ, "Hz", lo_open=True),
        default=100.0,
        help="packets per second (default 100)",
    )
    ap.add_argument(
        "--drift-ppm",
        type=cli_float(-MAX_DRIFT_PPM, MAX_DRIFT_PPM, "ppm"),
        default=50.0,
        help="device clock error in ppm (default 50)",
    )
    ap.add_argument(
        "--offset-s",
        type=cli_float(0, MAX_OFFSET_S, "s"),
        default=None,
        help="initial device clock in s (default random)",
    )
    ap.add_argument(
        "--latency-ms",
        type=cli_float(0, MAX_DELAY_MS, "ms"),
        default=0.0,
        help="fixed delay before each write (ms)",
    )
    ap.add_argument(
        "--jitter-ms",
        type=cli_float(0, MAX_DELAY_MS, "ms"),
        default=0.0,
        help="extra uniform random write delay (ms)",
    )
    ap.add_argument(
        "--seed", type=cli_int(0, MAX_SEED), default=0, help="random seed (noise, preload, clock start)"
    )
    ap.add_argument(
        "--user", nargs="+", choices=("grasp", "idle"), default=["grasp"], help="user per finger (1 or 3)"
    )
    ap.add_argument(
        "--period-s",
        type=cli_float(MIN_PERIOD_S, MAX_PERIOD_S, "s"),
        default=5.0,
        help="grasp cycle period (default 5 s)",
    )
    ap.add_argument(
        "--max-push-n",
        type=cli_float(0, MAX_PUSH_N, "N", lo_open=True),
        default=3.0,
        help="the user's largest push (default 3 N)",
    )
    ap.add_argument(
        "--object-stiffness",
        type=cli_float(0, MAX_STIFFNESS, "N", lo_open=True),
        default=None,
        help="standalone mode: a virtual object of this stiffness (N per unit closure) stops the fingers",
    )
    ap.add_argument(
        "--object-closure",
        type=cli_float(0, 1),
        default=0.6,
        help="closure (0 open, 1 closed) where the object starts",
    )
    ap.add_argument(
        "--replug-s",
        type=cli_float(0, MAX_REPLUG_S, "s"),
        default=0.3,
        help="gap between unplug and replug (SIGUSR1)",
    )
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
    """``flowtact sim exo``: serve an emulated exoskeleton on a pty until SIGTERM/SIGINT; its exit
    status (:func:`flowtact.command.run_command`: 2 for a bad flag, one line, no traceback)."""
    return run_command(lambda: _serve(argv), prog="flowtact sim exo")


def _serve(argv: list[str] | None) -> int:
    from flowtact.blocks.devices.ptyserver import PtyServer

    ap = _parser()
    args = ap.parse_args(argv)
    if len(args.user) not in (1, N_FINGERS):
        ap.error("argument --user: takes 1 or 3 values")
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
    # before the temporary folder: a --log that cannot be opened leaves nothing behind
    log = open(args.log, "a", buffering=1) if args.log else None  # noqa: SIM115 (closed below)
    tmp = None
    link = args.link
    if link is None:
        tmp = tempfile.mkdtemp(prefix="flowtact-exo-")
        link = os.path.join(tmp, "tty")
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
