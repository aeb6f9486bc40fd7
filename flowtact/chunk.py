"""Chunks and stream specs: the only things that flow between blocks."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

__all__ = ["Chunk", "StreamSpec", "concat"]


@dataclass(frozen=True, slots=True)
class Chunk:
    """``n`` time-stamped samples: ``t`` (float64 seconds, shape (n,)) and ``data`` (n, *shape).

    Event streams (spikes) use the same type: ``t`` holds event times and ``data`` the unit index
    (or, for events that carry more, rows whose first column is the unit, e.g. stimulation pulses).
    ``end`` is a watermark: the stream holds nothing more before this time. Event producers set it
    so that consumers (rates, pulse trains) know time moved on even when no event came.
    """

    t: np.ndarray
    data: np.ndarray
    end: float | None = None

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @staticmethod
    def empty(
        spec: StreamSpec | None = None,
        *,
        shape: tuple[int, ...] = (),
        dtype: str = "float64",
        end: float | None = None,
    ) -> Chunk:
        """A zero-sample chunk: of the stream ``spec`` describes, or of samples ``shape``/``dtype``.

        ``end`` marks the end of the stream (a flush's last chunk).
        """
        if spec is not None:
            shape, dtype = tuple(spec.shape), spec.dtype
        return Chunk(np.empty(0, np.float64), np.empty((0, *shape), dtype), end)

    def readonly(self) -> Chunk:
        """This chunk with arrays that cannot be written (what blocks receive): itself when both
        already are, else a chunk of read-only views (the arrays given stay writable)."""
        if not (self.t.flags.writeable or self.data.flags.writeable):
            return self
        t, d = self.t.view(), self.data.view()
        t.setflags(write=False)
        d.setflags(write=False)
        return Chunk(t, d, self.end)


def concat(chunks: list[Chunk], spec: StreamSpec | None = None) -> Chunk:
    """Join chunks in time order; an empty list needs ``spec`` to know the sample shape."""
    if not chunks:
        if spec is None:
            raise ValueError("concat of no chunks needs a spec")
        return Chunk.empty(spec)
    if len(chunks) == 1:
        return chunks[0]
    ends = [c.end for c in chunks if c.end is not None]
    return Chunk(
        np.concatenate([c.t for c in chunks]),
        np.concatenate([c.data for c in chunks]),
        max(ends) if ends else None,
    )


@dataclass(frozen=True, slots=True)
class StreamSpec:
    """What one stream carries, resolved when a graph is compiled.

    ``rate_hz`` is the nominal sample rate (None for event streams); ``units`` a unit string such
    as ``"N"``, ``"N/s"`` or ``"1"`` (dimensionless); ``n_units`` the number of units an event
    stream indexes; ``labels`` optional channel names for the last axis, or one per value of a
    multi-axis sample (C order); ``categories`` marks a categorical stream: sample value ``i`` means
    ``categories[i]`` (an object, a state), which plots draw as steps named on the axis.
    """

    dtype: str = "float64"
    shape: tuple[int, ...] = ()
    units: str = "1"
    rate_hz: float | None = None
    events: bool = False
    n_units: int | None = None
    labels: tuple[str, ...] | None = None
    categories: tuple[str, ...] | None = None

    @property
    def size(self) -> int:
        """Values per sample: 1 for a scalar, C for a vector of C channels, H·W for a frame."""
        return int(np.prod(self.shape)) if self.shape else 1

    def with_(self, **changes: object) -> StreamSpec:
        """A copy with some fields changed."""
        return replace(self, **changes)  # type: ignore[arg-type]

    def describe(self) -> str:
        """Short human form used in error messages: ``float64[3] N @ 1000 Hz``."""
        shape = "[" + ",".join(map(str, self.shape)) + "]" if self.shape else ""
        if self.events:
            return f"events of {self.n_units} units"
        rate = f" @ {self.rate_hz:g} Hz" if self.rate_hz else ""
        return f"{self.dtype}{shape} {self.units}{rate}"
