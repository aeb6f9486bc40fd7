"""The documented bounds of every replay reader (the ``replay`` block and ``--replay NODE=FILE``):
a replayed file is data from someone else, so every size, count and number it declares is checked
against these bounds before anything is allocated or played. The file checks themselves (regular
files only, the HDF5 signature, .npz members' headers and sizes) are :mod:`flowtact.inputs.bounded_files`,
whose :class:`~flowtact.errors.FileRefused` every replay reader raises.

The bounds are generous for real logs and recordings and small enough that a refusal, and a run
over a file within them, fits in memory: each player holds at most :data:`REPLAY_BUDGET_BYTES`
of a file's arrays (a .npz's arrays, a .csv's table, a .h5 stream's time stamps; .h5 data is read
slice by slice).
"""

from __future__ import annotations

import math

import flowtact.api as ft

__all__ = [
    "MAX_CHUNK_BYTES",
    "MAX_COLUMNS",
    "MAX_LINE_BYTES",
    "MAX_RATE_HZ",
    "MAX_STREAMS",
    "MAX_TEXT_BYTES",
    "MAX_TIME_S",
    "REPLAY_BUDGET_BYTES",
    "budget_text",
    "listing",
    "rate_problem",
    "time_problem",
]

REPLAY_BUDGET_BYTES = ft.STATE_BUDGET_BYTES
"""Most memory (1 GiB) the arrays one player reads whole may take: a .npz's data and ``t`` arrays
(as their headers declare them), a .csv's float64 table, a .h5 stream's time stamps. A replay's
data is its state, so it gets a block's state budget; a larger recording plays from .h5, whose
data is read slice by slice."""

MAX_TEXT_BYTES = 256 << 20
"""Largest .csv file (256 MiB). A cell takes at least two bytes of text (``0,``) and eight in the
float64 table, so a file this size yields a table within :data:`REPLAY_BUDGET_BYTES`."""

MAX_LINE_BYTES = 1 << 20
"""Longest line of a .csv (1 MiB, header included): :data:`MAX_COLUMNS` numbers of 25 characters
fit four times over; a longer line is refused before it is read."""

MAX_COLUMNS = 10_000
"""Most columns a .csv header may name (name lookups are linear; error messages list them)."""

MAX_STREAMS = 10_000
"""Most streams (or .npz arrays) a replayed file may hold: every one is listed and looked up."""

MAX_CHUNK_BYTES = 64 << 20
"""Largest HDF5 chunk of a replayed stream (64 MiB; flowtact writes 64 kB, or one sample when a
sample is larger): HDF5 inflates a whole chunk to read one value from it."""

MAX_TIME_S = 1e6
"""Largest time stamp (in magnitude, ``time_offset_s`` included) a replayed file may carry:
1e6 s, 11.6 days of graph time. Graph time starts at 0 and a run over a file lasts until its end,
so a file stamped in Unix seconds (about 1.7e9), or with a stamp 1e300 s away, would run for ever;
such a file is refused with the hint to shift it (``t - t[0]``, or ``time_offset_s``)."""

MAX_RATE_HZ = 1e6
"""Highest sample rate (1 MHz) a replayed file may give (1 / its median time step) or declare
(a recording's ``rate_hz``): above every tactile sensor's, and blocks downstream size their
buffers by their input's rate."""


def budget_text(nbytes: int) -> str:
    """``2.0 GiB, over the 1.0 GiB a replay may read``: for refusals."""
    return f"{ft.format_bytes(nbytes)}, over the {ft.format_bytes(REPLAY_BUDGET_BYTES)} a replay may hold in memory"


def time_problem(t: float) -> str | None:
    """Why ``t`` (a file's time stamp plus any offset) cannot be played: not finite, or beyond
    :data:`MAX_TIME_S` (a run over the file would last for ever); None if it can."""
    if not math.isfinite(t):
        return "is not a finite time"
    if abs(t) > MAX_TIME_S:
        return (
            f"is beyond the {MAX_TIME_S:g} s a replay may span (graph time starts at 0); "
            "shift the file's times to start near 0 (t - t[0])"
        )
    return None


def rate_problem(rate_hz: float) -> str | None:
    """Why ``rate_hz`` (given by a file) cannot be a replayed stream's rate, or None: it must be
    finite and within [1 / :data:`MAX_TIME_S`, :data:`MAX_RATE_HZ`]."""
    if not (math.isfinite(rate_hz) and 1.0 / MAX_TIME_S <= rate_hz <= MAX_RATE_HZ):
        return f"must be between {1.0 / MAX_TIME_S:g} and {MAX_RATE_HZ:g} Hz"
    return None


def listing(names: list[str] | tuple[str, ...], most: int = 20) -> str:
    """``a, b, c`` — at most ``most`` names, then ``... (N in all)``: a file may hold thousands."""
    if len(names) <= most:
        return ", ".join(names) or "none"
    return f"{', '.join(names[:most])}, ... ({len(names)} in all)"
