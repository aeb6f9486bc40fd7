"""The documented bounds every graph value and command-line flag is checked against, before
anything is allocated or started: times, queue lengths, host names and the memory a block's
state may take (:data:`STATE_BUDGET_BYTES`, estimated by each config's ``state_bytes``).
"""

from __future__ import annotations

import argparse
import ipaddress
import math
import re
from collections.abc import Callable
from typing import Any

__all__ = [
    "MAX_DURATION_S",
    "MAX_QUEUE",
    "MAX_RUN_TICKS",
    "MAX_SEED",
    "MAX_TICK_S",
    "MIN_TICK_S",
    "NOMINAL_FRAME_BYTES",
    "NOMINAL_RATE_HZ",
    "STATE_BUDGET_BYTES",
    "budget_problem",
    "cli_duration_seconds",
    "cli_finite_seconds",
    "cli_float",
    "cli_int",
    "cli_positive_seconds",
    "cli_tick_seconds",
    "format_bytes",
    "host_problem",
    "positive_seconds",
    "run_ticks_problem",
]

STATE_BUDGET_BYTES = 1 << 30
"""Most memory (1 GiB) one block's state may need, as its config's ``state_bytes`` estimates it."""
MAX_QUEUE = 1_000_000
"""Longest edge queue, in messages."""
MAX_TICK_S = 10.0
"""Longest clock tick: a source emits a tick's worth of samples at once."""
MIN_TICK_S = 1e-6
"""Shortest clock tick (1 µs): the fastest shipped loop ticks at 2 ms, and below a microsecond a
tick costs more than the time it stands for (real time could never keep up)."""
MAX_RUN_TICKS = 1_000_000_000
"""Most ticks one run may take (duration / tick): 24 h at the 5 ms real-time tick is 1.7e7, a
week at 1 ms 6e8. More is a typing slip (``--duration 1e308``, ``--tick 1e-12``), not a run."""
MAX_DURATION_S = MAX_RUN_TICKS * MAX_TICK_S
"""Longest run, in graph seconds (1e10 s, 317 years): at the longest tick, the most ticks."""
MAX_SEED = 2**63 - 1
"""Largest seed: fits a signed 64-bit integer (an HDF5 attribute, a numpy or torch seed)."""

NOMINAL_RATE_HZ = 10_000.0
"""Input sample rate that state estimates assume where a config cannot know it (above every
shipped sensor's)."""
NOMINAL_FRAME_BYTES = 3 * 320 * 240
"""Input frame size that state estimates assume where a config cannot know it (three TacTip frames)."""

_LABEL = re.compile(r"^(?!-)[A-Za-z0-9-]{1,63}(?<!-)$")


def positive_seconds(value: Any) -> float | None:
    """``value`` as a finite number of seconds > 0, or None (bools, strings, NaN and inf are not)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    try:
        seconds = float(value)
    except OverflowError:  # an int beyond float range
        return None
    return seconds if math.isfinite(seconds) and seconds > 0 else None


def host_problem(host: Any, *, wildcard: bool = False) -> str | None:
    """Why ``host`` is not a host name (RFC 1123) or an IPv4/IPv6 address, or None if it is one.

    ``wildcard`` also accepts ``*`` (listen on every interface).
    """
    if not isinstance(host, str) or not host:
        return f"must be a host name or an IP address; got {host!r}"
    if wildcard and host == "*":
        return None
    try:
        ipaddress.ip_address(host)
        return None
    except ValueError:
        pass
    name = host[:-1] if host.endswith(".") else host
    if len(name) <= 253 and all(_LABEL.match(label) for label in name.split(".")) and not name.isdigit():
        return None
    return f"must be a host name (letters, digits, '-', '.') or an IP address; got {host!r}"


def format_bytes(n: float) -> str:
    """``1.5 GiB``: a byte count in binary units."""
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if n < 1024 or unit == "PiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    raise AssertionError("unreachable")


def budget_problem(estimates: dict[str, float]) -> tuple[str, str] | None:
    """(field, rule) when the estimates (field -> bytes) add up to more than the budget, naming
    the field with the largest share; None within the budget."""
    total = sum(estimates.values(), 0.0)
    if total <= STATE_BUDGET_BYTES:  # NaN counts as over
        return None
    name = max(estimates, key=lambda k: estimates[k] if estimates[k] == estimates[k] else math.inf)
    return name, (
        f"small enough for the block's state to fit in {format_bytes(STATE_BUDGET_BYTES)} "
        f"(it would need about {format_bytes(total)})"
    )


# -- argparse types: a clear one-line usage error and exit status 2 --------------------------------


def cli_positive_seconds(text: str) -> float:
    """A command-line duration: a finite number of seconds > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of seconds, got {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a finite number of seconds > 0, got {text!r}")
    return value


def cli_tick_seconds(text: str) -> float:
    """A command-line clock tick: seconds in [:data:`MIN_TICK_S`, :data:`MAX_TICK_S`]."""
    value = cli_positive_seconds(text)
    if value > MAX_TICK_S:
        raise argparse.ArgumentTypeError(f"must be at most {MAX_TICK_S:g} s, got {text!r}")
    if value < MIN_TICK_S:
        raise argparse.ArgumentTypeError(f"must be at least {MIN_TICK_S:g} s, got {text!r}")
    return value


def cli_duration_seconds(text: str) -> float:
    """A command-line run duration: seconds > 0 and at most :data:`MAX_DURATION_S`."""
    value = cli_positive_seconds(text)
    if value > MAX_DURATION_S:
        raise argparse.ArgumentTypeError(f"must be at most {MAX_DURATION_S:g} s, got {text!r}")
    return value


def run_ticks_problem(duration_s: float | None, tick_s: float) -> str | None:
    """Why a run of ``duration_s`` at ``tick_s`` is refused (more than :data:`MAX_RUN_TICKS`
    ticks, or a tick outside its bounds), or None. A run without a duration ends when stopped."""
    if not MIN_TICK_S <= tick_s <= MAX_TICK_S:
        return f"the tick must be in [{MIN_TICK_S:g}, {MAX_TICK_S:g}] s; got {tick_s:g}"
    if duration_s is not None and not duration_s / tick_s <= MAX_RUN_TICKS:
        return (
            f"{duration_s:g} s at a {tick_s:g} s tick is {duration_s / tick_s:.3g} ticks; "
            f"a run takes at most {MAX_RUN_TICKS:.0e}"
        )
    return None


def cli_finite_seconds(text: str) -> float:
    """A command-line time (``plot --from``): a finite number of seconds."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of seconds, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number of seconds, got {text!r}")
    return value


# -- numbers from command-line flags (every command, plugins included) -----------------------------


def _number(text: str, integer: bool) -> float:
    """``text`` as a number; an integer may be written ``1e6`` (it must then be a whole number)."""
    try:
        return int(text) if integer else float(text)
    except ValueError:
        pass
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected {'an integer' if integer else 'a number'}, got {text!r}"
        ) from None
    if integer and not (math.isfinite(value) and value.is_integer()):
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}")
    return int(value) if integer else value


def _interval(lo: float, hi: float, lo_open: bool, unit: str) -> str:
    """``(0, 10] Hz``: a range as it is written (integers in full)."""
    a, b = (f"{lo}", f"{hi}") if isinstance(lo, int) and isinstance(hi, int) else (f"{lo:g}", f"{hi:g}")
    return f"{'(' if lo_open else '['}{a}, {b}]{' ' + unit if unit else ''}"


def cli_int(lo: int, hi: int, unit: str = "") -> Callable[[str], int]:
    """An argparse type: an integer in [lo, hi] (``1e6`` accepted when whole), else a one-line
    usage error naming the range."""

    def parse(text: str) -> int:
        value = int(_number(text, integer=True))
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(
                f"must be an integer in {_interval(lo, hi, False, unit)}, got {text!r}"
            )
        return value

    parse.__name__ = "integer"  # argparse names the type in its messages
    return parse


def cli_float(lo: float, hi: float, unit: str = "", *, lo_open: bool = False) -> Callable[[str], float]:
    """An argparse type: a finite number in [lo, hi] (``(lo, hi]`` with ``lo_open``), else a
    one-line usage error naming the range (NaN and infinities are never in it)."""

    def parse(text: str) -> float:
        value = _number(text, integer=False)
        inside = (lo < value if lo_open else lo <= value) and value <= hi  # False for NaN
        if not (math.isfinite(value) and inside):
            raise argparse.ArgumentTypeError(
                f"must be a finite number in {_interval(lo, hi, lo_open, unit)}, got {text!r}"
            )
        return value

    parse.__name__ = "number"
    return parse
