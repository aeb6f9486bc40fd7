"""``flowtact sim lsl-force``: publish an emulated force gauge on LSL (Fx, Fy, Fz in N), to try LSL graphs.

A program, not a block: it paces itself on the LSL clock (a device's own timing) and stamps each
sample with its nominal time. The force is a 120 mN baseline with a 50 mN press held for
``--press-s`` every ``--period-s`` on Fz (Fx, Fy zero), so ``graphs/lsl_touch.yaml`` makes spikes.
It publishes ``--seconds`` of samples and exits; with ``--wait`` it starts once a reader connected
and stops early when the last reader is gone (a graph that ended).
"""

from __future__ import annotations

import argparse

from flowtact.console.command import run_command
from flowtact.errors import UsageError

__all__ = ["main"]


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="flowtact sim lsl-force", description=__doc__.split("\n\n")[0])
    ap.add_argument("--name", default="flowtact_force", help="the stream's LSL name (default flowtact_force)")
    ap.add_argument("--rate-hz", type=float, default=1000.0, help="samples per second (default 1000)")
    ap.add_argument("--seconds", type=float, default=10.0, help="how long to publish (default 10)")
    ap.add_argument("--period-s", type=float, default=1.0, help="one press every this many seconds")
    ap.add_argument("--press-s", type=float, default=0.5, help="how long each press is held")
    ap.add_argument(
        "--wait",
        action="store_true",
        help="wait (up to 60 s) for a reader before publishing, and stop when the last reader is gone",
    )
    return ap


def main(argv: list[str] | None = None) -> int:
    """Publish, then exit 0; 2 for a bad flag (one line)."""
    return run_command(lambda: _publish(argv), prog="flowtact sim lsl-force")


def _publish(argv: list[str] | None) -> int:
    args = _parser().parse_args(argv)
    if not 0 < args.rate_hz <= 100_000:
        raise UsageError(f"--rate-hz: must be in (0, 100000]; got {args.rate_hz:g}")
    if not 0 < args.seconds <= 86_400:
        raise UsageError(f"--seconds: must be in (0, 86400]; got {args.seconds:g}")
    if not 0 < args.press_s < args.period_s:
        raise UsageError(f"--press-s: must be in (0, --period-s); got {args.press_s:g}")
    import time

    import pylsl

    info = pylsl.StreamInfo(args.name, "Force", 3, args.rate_hz, "double64", f"flowtact-sim/{args.name}")
    channels = info.desc().append_child("channels")
    for label in ("Fx", "Fy", "Fz"):
        ch = channels.append_child("channel")
        ch.append_child_value("label", label)
        ch.append_child_value("unit", "N")
    outlet = pylsl.StreamOutlet(info)
    if args.wait and not outlet.wait_for_consumers(60.0):
        raise UsageError(f"no reader connected to LSL stream '{args.name}' within 60 s (--wait)")
    n = round(args.seconds * args.rate_hz)
    t0 = pylsl.local_clock()
    sent = 0
    for i in range(n):
        if args.wait and i % 100 == 0 and not outlet.have_consumers():
            break
        due = t0 + i / args.rate_hz
        ahead = due - pylsl.local_clock()
        if ahead > 0:
            time.sleep(ahead)
        pressed = (i / args.rate_hz) % args.period_s < args.press_s
        outlet.push_sample([0.0, 0.0, 0.17 if pressed else 0.12], due)
        sent += 1
    print(f"published {sent} samples of '{args.name}'")
    return 0
