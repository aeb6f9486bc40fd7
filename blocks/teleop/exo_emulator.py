"""``flowtact sim exo``: serve an :class:`~flowtact.blocks.teleop.exo_device.ExoDevice` on a
pseudo-terminal, so the host side (``serial_io``) runs over a real tty with no hardware."""

from __future__ import annotations

import argparse
import os
import signal
import time
from collections.abc import Sequence
from typing import Any, TextIO

import flowtact.api as ft
from flowtact.blocks.teleop.exo_device import ExoDevice, ExoParams
from flowtact.blocks.teleop.exo_protocol import (
    N_FINGERS,
)
from flowtact.console.command import CommandParser, run_command
from flowtact.errors import UsageError
from flowtact.inputs.limits import cli_float, cli_int
from flowtact.runtime.rundir import RunFolder, make_run_folder

# -- the emulator process -----------------------------------------------------------------------


__all__ = ["MAX_RATE_HZ", "OWN_FLAGS", "PATH_FLAGS", "graph_args_problem", "main"]

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


#: Flags that name a file: refused in a graph's ``serial_io.emulator_args`` (a graph writes no files).
PATH_FLAGS = ("--link", "--log")
#: Flags ``serial_io`` sets itself: refused in ``emulator_args`` (with the parameter to use instead).
OWN_FLAGS = {"--rate-hz": "set rate_hz", "--exit-with-parent": "always given", "--help": "", "-h": ""}


class _Parser(CommandParser):
    """Usage errors in one line (the flag, the rule, the value), exit status 2; keeps its flags."""

    def __init__(self, **kw: Any) -> None:
        self.flags: dict[str, argparse.Action] = {}
        super().__init__(**kw)

    def add_argument(self, *args: Any, **kw: Any) -> argparse.Action:
        action = super().add_argument(*args, **kw)
        self.flags.update(dict.fromkeys(action.option_strings, action))
        return action


def _parser() -> _Parser:
    ap = _Parser(
        allow_abbrev=False,  # a flag is spelled in full: emulator_args are checked flag by flag
        prog="flowtact sim exo",
        description="Emulate the Remote Feelings exoskeleton (3 fingers) on a pseudo-terminal. Prints "
        "'PORT <path>' first, then serves until SIGTERM/SIGINT; SIGUSR1 simulates an unplug/replug.",
    )
    ap.add_argument(
        "--link",
        metavar="PATH",
        help="stable symlink to the pty (default: in a private temporary folder, printed); PATH must not "
        "exist, or be a stale pty link of an earlier run: a file or folder there is never replaced",
    )
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
        "--seed",
        type=cli_int(0, ft.MAX_SEED),
        default=0,
        help="random seed (noise, preload, clock start)",
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
        help="write each applied command and watchdog trip (host monotonic s) to FILE, a new file: an "
        "existing one is never appended to or replaced",
    )
    return ap


def main(argv: list[str] | None = None) -> int:
    """``flowtact sim exo``: serve an emulated exoskeleton on a pty until SIGTERM/SIGINT; its exit
    status (:func:`flowtact.console.command.run_command`: 2 for a bad flag, one line, no traceback)."""
    return run_command(lambda: _serve(argv), prog="flowtact sim exo")


def _serve(argv: list[str] | None) -> int:
    from flowtact.blocks.devices.ptyserver import LinkError, PtyServer

    ap = _parser()
    args = ap.parse_args(argv)
    if len(args.user) not in (1, N_FINGERS):
        ap.error("argument --user: takes 1 or 3 values")
    users = tuple(args.user * N_FINGERS if len(args.user) == 1 else args.user)
    try:
        params = _params(args, users)
    except ValueError as e:  # rules across flags (a grasp cycle longer than the period)
        raise UsageError(str(e)) from None
    tick0 = None if args.offset_s is None else round(args.offset_s * 1e6)
    dev = ExoDevice(params, seed=args.seed, tick0_us=tick0)
    log = _open_log(args.log)  # before the folder: a --log refused leaves nothing behind
    try:
        link, folder = _link(args.link)
    except UsageError:
        if log is not None:  # the new, empty log this run made: nothing of anyone else's
            log.close()
            os.unlink(args.log)
        raise
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
    except LinkError as e:  # the link was swapped for something else since it was checked
        raise UsageError(f"--link {link}: {e}") from None
    finally:
        server.close()
        if log is not None:
            log.close()
        if folder is not None:
            folder.close()
    return 0


def _params(args: argparse.Namespace, users: tuple[str, ...]) -> ExoParams:
    """The device model's parameters from the flags (``ValueError`` for a rule across flags)."""
    return ExoParams(
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


def graph_args_problem(argv: Sequence[str]) -> str | None:
    """Why ``argv`` may not be passed to the emulator from a graph (``serial_io.emulator_args``), or None.

    Only this parser's flags, spelled in full, with values its own checks accept; never a flag that
    names a file (:data:`PATH_FLAGS`) nor one ``serial_io`` sets (:data:`OWN_FLAGS`).
    """
    actions = _parser().flags
    i = 0
    while i < len(argv):
        token = str(argv[i])
        flag, eq, inline = token.partition("=")
        i += 1
        if flag in PATH_FLAGS:
            return (
                f"must not hold {flag}: a graph never names files the emulator writes (run `flowtact sim "
                f"exo {flag} PATH` yourself and set port: to its link)"
            )
        if flag in OWN_FLAGS:
            return f"must not hold {flag}: serial_io sets it" + (
                f" ({OWN_FLAGS[flag]})" if OWN_FLAGS[flag] else ""
            )
        action = actions.get(flag) if flag.startswith("--") else None
        if action is None:
            return f"must hold flags of `flowtact sim exo` only; got {token!r} (see flowtact sim exo --help)"
        if action.nargs == 0:
            if eq:
                return f"{flag} takes no value; got {token!r}"
            continue
        values = [inline] if eq else []
        while i < len(argv) and not str(argv[i]).startswith("--") and (action.nargs == "+" or not values):
            values.append(str(argv[i]))
            i += 1
        if not values:
            return f"{flag} needs a value"
        if flag == "--user" and len(values) not in (1, N_FINGERS):
            return f"--user takes 1 or {N_FINGERS} values; got {len(values)}"
        for v in values:
            problem = _value_problem(action, v)
            if problem:
                return f"{flag}: {problem}"
    return None


def _value_problem(action: argparse.Action, text: str) -> str | None:
    try:
        value = action.type(text) if callable(action.type) else text
    except (argparse.ArgumentTypeError, ValueError) as e:
        return str(e)
    if action.choices is not None and value not in action.choices:
        return f"must be one of {', '.join(map(str, action.choices))}; got {text!r}"
    return None


def _link(path: str | None) -> tuple[str, RunFolder | None]:
    """The pty link to make: ``path`` if a link may go there, else a fresh one in a private folder."""
    from flowtact.blocks.devices.ptyserver import link_problem

    if path is None:
        folder = make_run_folder("exo")
        return os.path.join(folder.path, "tty"), folder
    problem = link_problem(os.path.abspath(path))
    if problem:
        raise UsageError(f"--link {path}: {problem}")
    return path, None


def _open_log(path: str | None) -> TextIO | None:
    """``path`` created for writing, exclusively: an existing file (or a symlink) is refused."""
    if path is None:
        return None
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o644)
    except FileExistsError:
        what = "a folder" if os.path.isdir(path) else "an existing file"
        raise UsageError(f"--log {path}: is {what}; the log is only ever written to a new file") from None
    except OSError as e:
        raise UsageError(f"--log {path}: cannot create it ({e.strerror})") from None
    return os.fdopen(fd, "w", buffering=1)


if __name__ == "__main__":
    raise SystemExit(main())
