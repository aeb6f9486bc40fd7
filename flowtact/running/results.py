"""What a run from Python hands back: each recorded stream as numpy arrays with its units and labels.

A :class:`Stream` is one ``node.port``: ``t`` (float64 seconds of graph time), ``data`` (samples,
frames, or the unit index of each event) and what the stream declares (units, rate, channel
labels, unit count, categories). :meth:`Stream.frame` gives a pandas DataFrame (pandas is an
extra: ``pip install "flowtact[pandas]"``). :class:`RunResult` gathers a run's streams and its
summary; :func:`read_streams` reads the same objects back from any recording.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from flowtact.chunk import StreamSpec

if TYPE_CHECKING:
    import pandas as pd

    from flowtact.recording.hdf5 import Recording
    from flowtact.runtime.inproc import RunSummary

__all__ = ["RunResult", "Stream", "read_streams"]


@dataclass(frozen=True)
class Stream:
    """One recorded stream: ``t`` (n,) seconds, ``data`` (n, *sample shape), and its declaration."""

    name: str
    """``node.port``."""
    t: np.ndarray
    data: np.ndarray
    spec: StreamSpec

    @property
    def units(self) -> str:
        """The unit of every value (``N``, ``N/s``, ``1``); an event stream's data is a unit index."""
        return self.spec.units

    @property
    def labels(self) -> tuple[str, ...] | None:
        """Channel names of the last axis, if the stream names them."""
        return self.spec.labels

    @property
    def rate_hz(self) -> float | None:
        """Nominal sample rate (None for events)."""
        return self.spec.rate_hz

    @property
    def events(self) -> bool:
        """Whether this is an event stream (spikes: ``t`` the times, ``data`` the unit index)."""
        return self.spec.events

    @property
    def n_units(self) -> int | None:
        """How many units an event stream indexes."""
        return self.spec.n_units

    @property
    def categories(self) -> tuple[str, ...] | None:
        """A categorical stream's names: sample value ``i`` means ``categories[i]``."""
        return self.spec.categories

    def __len__(self) -> int:
        return len(self.t)

    def columns(self) -> list[str]:
        """Column names for :meth:`frame`: the channel labels, else ``name`` or ``name[i]``."""
        if self.events:
            return ["t", "unit"]
        shape = self.data.shape[1:]
        if not shape:
            return [self.name]
        if len(shape) > 1:
            raise ValueError(
                f"stream '{self.name}' carries {'x'.join(map(str, shape))} samples (frames): a table has "
                "one value per column; use .t and .data"
            )
        if self.labels and len(self.labels) == shape[0]:
            return list(self.labels)
        return [f"{self.name}[{i}]" for i in range(shape[0])]

    def frame(self) -> pd.DataFrame:
        """A pandas DataFrame: for samples, indexed by ``t`` with one column per channel (labels as
        column names, units in ``df.attrs``); for events, columns ``t`` and ``unit``; categorical
        samples as pandas categories. Needs pandas (``pip install "flowtact[pandas]"``)."""
        pd = _pandas()
        attrs = {"stream": self.name, "units": self.units, "rate_hz": self.rate_hz}
        if self.events:
            df = pd.DataFrame({"t": self.t, "unit": self.data.reshape(len(self.t), -1)[:, 0]})
        else:
            cols = self.columns()
            values = self.data.reshape(len(self.t), len(cols))
            df = pd.DataFrame(values, index=pd.Index(self.t, name="t"), columns=cols)
            if self.categories:
                for c in cols:
                    df[c] = pd.Categorical.from_codes(df[c].astype(int), categories=list(self.categories))
        df.attrs.update(attrs)
        return df

    def __repr__(self) -> str:
        return f"Stream({self.name!r}: {len(self.t)} × {self.spec.describe()})"


def _pandas() -> Any:
    try:
        import pandas
    except ModuleNotFoundError:
        raise ModuleNotFoundError(
            'Stream.frame() needs pandas: pip install "flowtact[pandas]" (or use .t and .data)', name="pandas"
        ) from None
    return pandas


@dataclass(frozen=True)
class RunResult(Mapping[str, Stream]):
    """A finished run: its recorded streams by ``node.port`` (``result["force.f"]``), its summary
    (samples, spikes, wall time, counters) and the recording file when one was kept."""

    streams: dict[str, Stream]
    summary: RunSummary | None = None
    path: Path | None = None
    """The HDF5 recording when ``record=`` named one (None: the run's streams were kept in memory only)."""
    warnings: list[str] = field(default_factory=list)
    """What the run warned about, as ``flowtact run`` would print it."""

    def __getitem__(self, name: str) -> Stream:
        try:
            return self.streams[name]
        except KeyError:
            known = ", ".join(self.streams) or "none: the graph records nothing (record: [...])"
            raise KeyError(f"no recorded stream '{name}' (recorded: {known})") from None

    def __iter__(self) -> Iterator[str]:
        return iter(self.streams)

    def __len__(self) -> int:
        return len(self.streams)

    def frame(self, name: str) -> pd.DataFrame:
        """``self[name].frame()``."""
        return self[name].frame()

    def __repr__(self) -> str:
        streams = ", ".join(repr(s) for s in self.streams.values())
        return f"RunResult({streams})"


def streams_of(recording: Recording) -> dict[str, Stream]:
    """A recording's streams as :class:`Stream` objects (arrays as read, in memory)."""
    return {name: Stream(name, s.t, s.data, s.spec) for name, s in recording.streams.items()}


def read_streams(path: str | Path) -> dict[str, Stream]:
    """Every stream of a recording (``flowtact run --record FILE.h5``), checked against its checksums."""
    from flowtact.recording.hdf5 import read_recording

    return streams_of(read_recording(path))
