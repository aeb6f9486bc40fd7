"""The documented bounds every graph value and command-line flag is checked against, before
anything is allocated or started: times, queue lengths, host names and the memory a block's
state may take (:data:`STATE_BUDGET_BYTES`, estimated by each config's ``state_bytes``).
"""

from __future__ import annotations

import argparse
import ipaddress
import math
import re
from typing import Any

__all__ = [
    "MAX_QUEUE",
    "MAX_TICK_S",
    "NOMINAL_FRAME_BYTES",
    "NOMINAL_RATE_HZ",
    "STATE_BUDGET_BYTES",
    "budget_problem",
    "cli_finite_seconds",
    "cli_positive_seconds",
    "cli_tick_seconds",
    "format_bytes",
    "host_problem",
    "positive_seconds",
]

STATE_BUDGET_BYTES = 1 << 30
"""Most memory (1 GiB) one block's state may need, as its config's ``state_bytes`` estimates it."""
MAX_QUEUE = 1_000_000
"""Longest edge queue, in messages."""
MAX_TICK_S = 10.0
"""Longest clock tick: a source emits a tick's worth of samples at once."""

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
    """A command-line clock tick: seconds > 0 and at most :data:`MAX_TICK_S`."""
    value = cli_positive_seconds(text)
    if value > MAX_TICK_S:
        raise argparse.ArgumentTypeError(f"must be at most {MAX_TICK_S:g} s, got {text!r}")
    return value


def cli_finite_seconds(text: str) -> float:
    """A command-line time (``plot --from``): a finite number of seconds."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of seconds, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number of seconds, got {text!r}")
    return value
