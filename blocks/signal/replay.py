"""Play back a recorded stream: a flowtact HDF5 recording, or a plain .npz / .csv file.

``replay`` is the "swap live for recorded" source with one output ``y``, for graph files. On the
command line, ``flowtact run graph.yaml --replay sensor=run.h5`` (or ``=log.csv``) puts a replay in
place of a live sensor on the sensor's own ports (:mod:`.replay_ports`), and everything downstream
runs unchanged. CSV logs are read by :mod:`.csv_log`; see docs/your-own-data.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

import flowtact.api as ft
from flowtact.blocks.signal.csv_log import CsvError, CsvLog, display, read_csv_log, row_place
from flowtact.blocks.signal.replay_limits import (
    MAX_CHUNK_BYTES,
    MAX_RATE_HZ,
    MAX_STREAMS,
    REPLAY_BUDGET_BYTES,
    budget_text,
    listing,
    rate_problem,
    time_problem,
)
from flowtact.errors import FileRefused
from flowtact.inputs.bounded_files import NpyHeader, NpzArchive, check_hdf5_signature, open_npz, refusal
from flowtact.inputs.safe_text import shown
from flowtact.params import did_you_mean

__all__ = ["Replay", "ReplayConfig"]

H5_SUFFIXES = (".h5", ".hdf5")
SUFFIXES = (*H5_SUFFIXES, ".npz", ".csv")
#: Relative mismatch allowed between a configured rate_hz and the median step of a file's t.
RATE_TOLERANCE = 0.01
_DENSITY_BLOCK = 1 << 20  # time stamps searched at a time by Replay._check_density


@dataclass(frozen=True)
class ReplayConfig(ft.Config):
    path: str = ft.param(
        doc="file to play back: a flowtact recording (.h5) or a .npz / .csv file (relative: to the graph file)",
        path=True,
    )
    stream: str | tuple[str, ...] | None = ft.param(
        None,
        doc=".h5: '<node>.<port>' (optional if the file holds one stream); .npz: data array (default "
        "'data'); .csv: column name or list of columns (default all but 't')",
    )
    units: str | None = ft.param(
        None, doc="units of the data for .npz/.csv (default '1'); for .h5, if given, must match the recording"
    )
    rate_hz: float | None = ft.param(
        None,
        doc="nominal sample rate; default the recorded rate (.h5) or 1 / median step of t",
        gt=0,
        le=MAX_RATE_HZ,
    )
    time_offset_s: float = ft.param(
        0.0, doc="added to every time stamp; samples landing before 0 are skipped"
    )
    loop: bool = ft.param(False, doc="start again after the end, times continuing (period = recorded length)")

    def check(self) -> None:
        suffix = Path(self.path).suffix.lower()
        if suffix not in SUFFIXES:
            raise self.error("path", f"must name a {', '.join(SUFFIXES)} file; got {self.path!r}")
        if isinstance(self.stream, tuple):
            if suffix != ".csv":
                raise self.error(
                    "stream", f"a list of columns is only for .csv files; got {list(self.stream)}"
                )
            if not self.stream:
                raise self.error("stream", "must list at least one column (or be left out for all but 't')")


@dataclass
class _Source:
    """What the file holds, as far as playback needs: spec, times, data (or an HDF5 dataset)."""

    spec: ft.StreamSpec
    t: np.ndarray | None = None  # file times, before the offset; None until loaded (h5)
    data: Any = None  # ndarray, or an h5py Dataset read slice by slice
    end_s: float | None = None  # events: the recorded end watermark
    h5_stream: str | None = None
    h5_file: Any = None
    csv: CsvLog | None = None  # a .csv's parsed log, to locate a bad time stamp at its line


class Replay(ft.Source):
    """Play back a stream from a .h5 recording, a .npz or a .csv file, in graph time.

    Config
    ------
    See the field docs (``flowtact blocks replay``).

    Notes
    -----
    Each tick emits every sample with ``t + time_offset_s < now`` not emitted yet, with the
    file's own time stamps (shifted), so record → replay gives back bit-identical chunks.
    Samples that land before 0 are skipped (counted as ``skipped_before_zero``). With ``loop``,
    playback restarts after the end with times continuing: a sample stream's period is
    ``t_last − t_first + 1/rate_hz``, an event stream's is its recorded duration (the last
    watermark). Time stamps must be non-decreasing (checked, naming the first bad sample).

    File formats. ``.h5``: a recording written by ``flowtact run --record``; dtype, shape, units,
    rate and labels come from the file; a configured ``units``/``rate_hz`` that differs is an
    error. ``.npz``: an array ``stream`` (default ``data``, shape (n, ...)) and optionally ``t``
    (n,); without ``t`` samples are stamped ``i / rate_hz``. ``.csv``: a header row naming the
    columns, one of them ``t``, separated by commas (or semicolons, tabs or spaces); the output is
    float64 of shape (k,) with the column names as labels, or () when ``stream`` names one column.
    A bad CSV (binary or not UTF-8, a ragged row, a cell that is not a number, no ``t``, a time
    that is not finite or goes back) is refused when the graph is compiled, at its line and column.
    After the file's end (without ``loop``) nothing is emitted: no held value. A relative ``path``
    in a graph file is from the graph file's folder.
    Without ``rate_hz`` the rate is 1 / the median step of ``t``; a configured rate more than 1 %
    away from it is an error.

    The output spec is read from the file header when the graph is compiled (a missing file,
    stream or column is reported then, with what the file does hold). Data is read in ``open`` or
    at the first ``reset``: .npz / .csv wholly, .h5 times wholly and the data slice by slice
    from the open file (camera recordings need not fit in memory). Latency: none beyond the tick.

    Every file is bounded before anything is allocated (:mod:`.replay_limits`): a regular file
    only; what is read wholly at most ``REPLAY_BUDGET_BYTES`` (1 GiB), as the .npz headers (which
    must match the bytes stored) or the .h5 shapes (each sample stored) declare it; time stamps
    plus ``time_offset_s`` within ±``MAX_TIME_S`` (1e6 s); a rate within [1e-6, 1e6] Hz; at most
    ``MAX_STREAMS`` streams or arrays. A file beyond a bound is refused naming it.

    Example
    -------
    >>> import os, tempfile
    >>> import numpy as np
    >>> from flowtact.blocks.signal.replay import Replay
    >>> from flowtact.testing import run_source
    >>> p = os.path.join(tempfile.mkdtemp(), "force.npz")
    >>> np.savez(p, t=np.arange(500) / 1000.0, data=np.ones((500, 3)))
    >>> out = run_source(Replay(path=p, units="N"), 0.25, tick_s=0.01)
    >>> out["y"].data.shape, float(out["y"].t[-1])
    ((250, 3), 0.249)
    """

    config_cls = ReplayConfig
    outputs = {
        "y": ft.Port(
            dtype=None,
            shape=None,
            units=None,
            doc=(
                "the recorded stream with the file's dtype, sample shape, units, rate and channel labels "
                "(.h5), or the array / columns of a .npz / .csv file. When the recorded stream is an "
                "event stream (spike times + unit index) so is y, and each chunk carries the watermark "
                "end = now"
            ),
        )
    }
    counter_docs = {
        "skipped_before_zero": "recorded samples whose time (plus time_offset_s) fell before graph time 0: "
        "not played; expected with a negative time_offset_s",
    }

    def __init__(self, *args: Any, **kw: Any) -> None:
        super().__init__(*args, **kw)
        self._src: _Source | None = None

    # -- compile time ------------------------------------------------------------------------
    def specs(self, inputs: Any) -> dict[str, ft.StreamSpec]:  # noqa: ARG002 — a source: its outputs come from its config
        """The output spec, read from the file (kept by nothing: ``open``/``reset`` read it for the run)."""
        return {"y": (self._src if self._src is not None else self._inspect()).spec}

    def _where(self) -> str:
        return f"{self.node} ({self.name})"

    def _inspect(self) -> _Source:
        c = self.config
        path = Path(c.path)
        if not path.exists() and not path.is_symlink():
            raise c.error(
                "path", f"does not exist: {path}" + ("" if path.parent.is_dir() else " (no such folder)")
            )
        suffix = path.suffix.lower()
        try:
            if suffix in H5_SUFFIXES:
                src = self._inspect_h5(path)
            else:
                src = self._inspect_npz(path) if suffix == ".npz" else self._inspect_csv(path)
                self._check_times(src.t, path, src.csv)
                src.spec = src.spec.with_(rate_hz=self._rate(src.t, path))
                self._check_density(src, src.t, path)
        except FileRefused as e:
            raise self._refused(path, e.reason) from None
        except OSError as e:  # a dangling link, a file that cannot be read
            raise self._refused(path, refusal(path, e).reason) from None
        return src

    def _refused(self, path: Path, reason: str) -> ft.SpecError:
        """A file-level refusal, located at the file (so the reason does not name it)."""
        return ft.SpecError("y", f"{self._where()}: {reason}", where=(display(path), 1, 1))

    def _inspect_h5(self, path: Path) -> _Source:
        c = self.config
        streams = h5_streams(path)
        available = listing(list(streams))
        name = c.stream
        if name is None:
            if len(streams) != 1:
                raise c.error("stream", f"is required: {path} holds {len(streams)} streams ({available})")
            name = next(iter(streams))
        if name not in streams:
            raise c.error("stream", f"must name a stream of {path} (available: {available}); got '{name}'")
        spec, _ = streams[name]
        if spec.rate_hz is not None and (why := rate_problem(spec.rate_hz)):
            raise FileRefused(path, f"stream {name} declares rate_hz {spec.rate_hz:g}; a rate {why}")
        _check_h5_stream(path, name, spec, self.config.time_offset_s)
        if c.units is not None and c.units != spec.units:
            raise ft.SpecError(
                "y", f"{self._where()}: units '{c.units}' given, but {name} in {path} is in '{spec.units}'"
            )
        if c.rate_hz is not None:
            if spec.events:
                raise ft.SpecError(
                    "y", f"{self._where()}: rate_hz given, but {name} in {path} is an event stream"
                )
            if not math.isclose(c.rate_hz, spec.rate_hz or math.nan, rel_tol=1e-9):
                raise ft.SpecError(
                    "y",
                    f"{self._where()}: rate_hz {c.rate_hz:g} given, but {name} in {path} was recorded at "
                    f"{spec.rate_hz:g} Hz",
                )
        return _Source(spec=spec, h5_stream=name)

    def _inspect_npz(self, path: Path) -> _Source:
        c = self.config
        key = c.stream if isinstance(c.stream, str) else "data"
        with open_npz(path, MAX_STREAMS) as z:
            if key not in z.names:
                raise c.error(
                    "stream", f"must name an array of {path} (arrays: {listing(z.names)}); got '{key}'"
                )
            head = _npy_header(z, key)
            has_t = "t" in z.names and key != "t"
            t_head = _npy_header(z, "t") if has_t else None
            if len(head.shape) == 0:
                raise ft.SpecError(
                    "y", f"{self._where()}: array '{key}' in {path} is a scalar; need (n, ...) samples"
                )
            n = head.shape[0]
            if t_head is not None and t_head.shape != (n,):
                raise ft.SpecError(
                    "y", f"{self._where()}: 't' in {path} has shape {t_head.shape}; '{key}' has {n} samples"
                )
            need = head.nbytes + 8 * n + (t_head.nbytes if t_head is not None else 0)
            if need > REPLAY_BUDGET_BYTES:  # the data, its time stamps as float64 (and as stored)
                raise FileRefused(
                    path,
                    f"array '{key}' {head.shape} {head.dtype} and its time stamps take "
                    f"{budget_text(need)}; record long runs to .h5 (played slice by slice)",
                )
            t = None if t_head is None else np.asarray(z.read("t", REPLAY_BUDGET_BYTES), np.float64)
        if t is None:
            if c.rate_hz is None:
                raise c.error(
                    "rate_hz", f"is required: {path} has no 't' array (samples are stamped i / rate_hz)"
                )
            t = np.arange(n) / c.rate_hz
        spec = ft.StreamSpec(dtype=head.dtype.name, shape=tuple(head.shape[1:]), units=c.units or "1")
        return _Source(spec=spec, t=t, data=(path, key))

    def _inspect_csv(self, path: Path) -> _Source:
        c = self.config
        try:
            log = read_csv_log(path)
        except CsvError as e:
            raise ft.SpecError("y", e.message, where=e.where) from None
        names = log.names
        index = {n: i for i, n in enumerate(names)}
        if c.stream is None:
            columns = list(log.data_columns)
        else:
            columns = [c.stream] if isinstance(c.stream, str) else list(c.stream)
        for col in columns:
            if col not in index:
                close = did_you_mean(col, names)
                close = close if close.startswith(" (did") else ""  # the columns are listed anyway
                raise c.error(
                    "stream", f"must name columns of {path} (columns: {listing(names)}); got '{col}'{close}"
                )
        idx = [index[col] for col in columns]
        single = isinstance(c.stream, str)
        data = np.ascontiguousarray(log.table[:, idx[0]] if single else log.table[:, idx])
        spec = ft.StreamSpec(
            dtype="float64",
            shape=() if single else (len(columns),),
            units=c.units or "1",
            labels=None if single else tuple(columns),
        )
        return _Source(spec=spec, t=np.ascontiguousarray(log.t), data=data, csv=log)

    def _check_times(self, t: np.ndarray, path: Path, log: CsvLog | None = None) -> None:
        """Finite, non-decreasing, and (shifted by ``time_offset_s``) within the span a replay may
        play: checked at the first bad sample, at its line in a .csv."""
        bad = ~np.isfinite(t)
        if bad.any():
            i = int(np.argmax(bad))
            raise ft.SpecError("y", f"{self._where()}: t[{i}] = {t[i]} in {path} is not a finite time")
        step = np.diff(t)
        if (step < 0).any():
            i = int(np.argmax(step < 0)) + 1
            raise ft.SpecError(
                "y",
                f"{self._where()}: t decreases at sample {i} in {path} ({t[i]:.9g} s after {t[i - 1]:.9g} s); "
                "time stamps must be non-decreasing",
            )
        offset = self.config.time_offset_s
        for i in (0, len(t) - 1) if len(t) else ():  # non-decreasing: the ends bound the rest
            if why := time_problem(float(t[i]) + offset):
                shifted = f" (+ time_offset_s {offset:g})" if offset else ""
                if log is not None:
                    line, col, text = row_place(log, i)
                    raise ft.SpecError(
                        "y", f"{self._where()}: time {text}{shifted} {why}", where=(display(path), line, col)
                    )
                raise self._refused(path, f"t[{i}] = {t[i]:.9g} s{shifted} {why}")

    def _check_density(self, src: _Source, t: np.ndarray, path: Path) -> None:
        """Bound what one tick may emit: the samples in the densest ``ft.MAX_TICK_S`` of the file
        (times the repeats a loop fits in a tick) must fit the budget, or a file of equal time
        stamps, or a short loop, would have one tick read everything at once (or for ever)."""
        n = len(t)
        if not n:
            return
        most = 0
        for lo in range(0, n, _DENSITY_BLOCK):  # a block at a time: no n-sized temporaries
            hi = min(n, lo + _DENSITY_BLOCK)
            ends = np.searchsorted(t, t[lo:hi] + ft.MAX_TICK_S, side="left")
            most = max(most, int(np.max(ends - np.arange(lo, hi))))
        if self.config.loop and (period := _period(src, t)) > 0:
            most = max(most, n * (math.ceil(ft.MAX_TICK_S / period) + 1))
        row = math.prod(src.spec.shape) * np.dtype(src.spec.dtype).itemsize + 8  # and its time
        if most * row > REPLAY_BUDGET_BYTES:
            looped = " (looped)" if self.config.loop else ""
            raise self._refused(
                path,
                f"up to {most} samples ({ft.format_bytes(most * row)}) fall within {ft.MAX_TICK_S:g} s{looped}, "
                f"the longest tick; a replay may emit at most {ft.format_bytes(REPLAY_BUDGET_BYTES)} in one tick",
            )

    def _rate(self, t: np.ndarray, path: Path) -> float:
        c = self.config
        steps = np.diff(t)
        inferred = None
        if len(steps) and np.median(steps) > 0:
            inferred = 1.0 / float(np.median(steps))
            if abs(inferred - round(inferred)) <= 1e-6 * inferred:
                inferred = float(round(inferred))
            if why := rate_problem(inferred):
                raise self._refused(
                    path, f"its time stamps step at {inferred:g} Hz (median); a replayed rate {why}"
                )
        if c.rate_hz is None:
            if inferred is None:
                raise c.error(
                    "rate_hz", f"is required: the time stamps of {path} give no rate (fewer than 2 distinct)"
                )
            return inferred
        if inferred is not None and abs(inferred - c.rate_hz) > RATE_TOLERANCE * c.rate_hz:
            raise ft.SpecError(
                "y",
                f"{self._where()}: rate_hz {c.rate_hz:g} given, but the time stamps of {path} step at "
                f"{inferred:g} Hz (median)",
            )
        return float(c.rate_hz)

    def ends_at(self, inputs: Any) -> float | None:  # noqa: ARG002 — a source: its end comes from its file
        """Graph time just past the last sample (one sample period after it; an event stream's
        recorded end), or None when looping or empty; read from the file when not yet opened."""
        src = self._src if self._src is not None else self._inspect()
        if self.config.loop or src is None:
            return None
        last, end = (
            (float(src.t[-1]) if len(src.t) else None, src.end_s) if src.t is not None else (None, None)
        )
        if src.t is None and src.h5_stream is not None:
            last, end = _h5_tail(Path(self.config.path), src.h5_stream)
        if last is None:
            return None
        if src.spec.events:
            stop = max(last, end if end is not None else last)
        else:
            stop = last + (1.0 / src.spec.rate_hz if src.spec.rate_hz else 0.0)
        return stop + self.config.time_offset_s

    @classmethod
    def stand_in(cls, block: str) -> str:
        """The block reference of a replay standing in for a node of ``block``, on its own output
        ports (what ``--replay NODE=FILE`` puts in the graph; see :mod:`.replay_ports`)."""
        return f"{__package__}.replay_ports:{block}"

    # -- run time ----------------------------------------------------------------------------
    def open(self) -> None:
        """Read the file (times wholly; .h5 data stays on disk, read slice by slice)."""
        self._load()

    def close(self) -> None:
        """Close the .h5 file if open."""
        src = getattr(self, "_src", None)
        if src is not None and src.h5_file is not None:
            src.h5_file.close()
            src.h5_file = None
            src.t = None
            src.data = None

    def _load(self) -> _Source:
        src = self._src if self._src is not None else self._inspect()
        self._src = src
        path = Path(self.config.path)
        if src.h5_stream is not None and src.h5_file is None:
            from flowtact.recording.hdf5 import open_stream

            try:  # the file as inspected: bounded, no declared size beyond what it stores
                check_h5_file(path)
                _check_h5_stream(path, src.h5_stream, src.spec, self.config.time_offset_s)
            except FileRefused as e:
                raise self._refused(path, e.reason) from None
            except OSError as e:
                raise self._refused(path, refusal(path, e).reason) from None
            f, h = open_stream(path, src.h5_stream)  # every checksum verified: damage refused up front
            t = np.asarray(f.read(h.t, slice(0, h.n)), np.float64)
            end = float(h.attrs.get("end_s", math.nan))
            src.h5_file, src.t, src.data, src.end_s = f, t, h.data, (end if math.isfinite(end) else None)
            self._check_times(t, path)
            self._check_density(src, t, path)
        elif isinstance(src.data, tuple):  # npz, not read yet: its header checked again, then read
            try:
                with open_npz(src.data[0], MAX_STREAMS) as z:
                    _npy_header(z, src.data[1])
                    src.data = z.read(src.data[1], REPLAY_BUDGET_BYTES)
            except FileRefused as e:
                raise self._refused(path, e.reason) from None
            except OSError as e:
                raise self._refused(path, refusal(path, e).reason) from None
        if isinstance(src.data, np.ndarray):
            src.data.flags.writeable = False
        return src

    def reset(self) -> None:
        src = self._load()
        assert src.t is not None
        t = src.t + self.config.time_offset_s
        t.flags.writeable = False
        self._t = t
        self._n = len(t)
        self._period = self._loop_period(src)
        self._k = 0
        self._i = self._first_at_or_after(0.0, 0, 0)
        self.count("skipped_before_zero", self._i)

    def _loop_period(self, src: _Source) -> float:
        if not self.config.loop or self._n == 0:
            return math.inf
        assert src.t is not None
        period = _period(src, src.t)
        if not period > 0:
            raise ft.SpecError(
                "y", f"{self._where()}: cannot loop {self.config.path}: its length is {period:g} s"
            )
        return period

    def _first_at_or_after(self, target: float, k: int, lo: int) -> int:
        """Smallest j >= lo with t[j] + k·period >= target, exact under rounding."""
        t, n = self._t, self._n
        shift = k * self._period if k else 0.0
        j = lo + int(np.searchsorted(t[lo:], target - shift, side="left"))
        while j > lo and t[j - 1] + shift >= target:
            j -= 1
        while j < n and t[j] + shift < target:
            j += 1
        return j

    def step(self, now: float) -> dict[str, ft.Chunk]:
        src = self._src
        assert src is not None
        ts: list[np.ndarray] = []
        ds: list[np.ndarray] = []
        while self._n:
            j = self._first_at_or_after(now, self._k, self._i)
            if j > self._i:
                t = self._t[self._i : j]
                ts.append(t + self._k * self._period if self._k else t)
                ds.append(np.asarray(src.data[self._i : j]))
                self._i = j
            if self._i < self._n or not self.config.loop:
                break
            self._k += 1
            self._i = self._first_at_or_after(0.0, self._k, 0)
            self.count("skipped_before_zero", self._i)
            if self._i < self._n and self._t[self._i] + self._k * self._period >= now:
                break
        spec = src.spec
        if not ts:
            empty = ft.Chunk.empty(spec)
            return {"y": ft.Chunk(empty.t, empty.data, now if spec.events else None)}
        t = ts[0] if len(ts) == 1 else np.concatenate(ts)
        d = ds[0] if len(ds) == 1 else np.concatenate(ds)
        return {"y": ft.Chunk(t, d, now if spec.events else None)}

    @classmethod
    def example(cls) -> ft.Example:
        return ft.Example(
            params={"path": str(_example_file()), "units": "N", "loop": True, "time_offset_s": -0.1},
            rate_hz=1000.0,
            duration_s=1.0,
        )


def _period(src: _Source, t: np.ndarray) -> float:
    """A loop's period: an event stream's recorded length, a sample stream's span plus a step."""
    if src.spec.events:
        return max(src.end_s or 0.0, float(t[-1]))
    return float(t[-1] - t[0]) + 1.0 / float(src.spec.rate_hz or math.inf)


def _h5_tail(path: Path, stream: str) -> tuple[float | None, float | None]:
    """The last time stamp of a recorded stream and its recorded end watermark (None if absent)."""
    from flowtact.recording.hdf5 import open_recording, stream_header

    with open_recording(path) as f:  # checked reads: damage is refused naming the dataset
        h = stream_header(f, stream)
        last = float(f.read(h.t, h.n - 1)) if h.n else None
        end = float(h.attrs.get("end_s", math.nan))
    return last, (end if math.isfinite(end) else None)


# -- .npz: every size a member declares is checked before its data is read (bounded_files) ----


def _npy_header(z: NpzArchive, key: str) -> NpyHeader:
    """Array ``key``'s header, checked (:meth:`NpzArchive.header`), within what a replay may hold."""
    head = z.header(key)
    if head.nbytes > REPLAY_BUDGET_BYTES:
        raise FileRefused(
            z.path,
            f"array '{key}' {head.shape} {head.dtype} takes {budget_text(head.nbytes)}; record long runs "
            "to .h5 (played slice by slice)",
        )
    return head


# -- .h5: the file and the played stream checked before record.py reads them ---------------------


def check_h5_file(path: Path) -> None:
    """A regular file with the HDF5 signature (a few bytes read, never the whole file), holding at
    most :data:`MAX_STREAMS` streams (counted before any is listed)."""
    import h5py

    check_hdf5_signature(path)
    try:
        with h5py.File(path, "r") as h5:
            group = h5.get("streams")
            count = len(group) if isinstance(group, h5py.Group) else 0
    except (OSError, ValueError, RuntimeError):
        return  # record.py names the problem
    if count > MAX_STREAMS:
        raise FileRefused(path, f"{count} streams; a replayed recording may hold at most {MAX_STREAMS}")


def h5_streams(path: Path) -> dict[str, tuple[ft.StreamSpec, int]]:
    """The streams of a recording to replay, from its header (:func:`check_h5_file`, then
    :func:`flowtact.recording.hdf5.stream_specs`); any refusal a :class:`FileRefused` naming the file once."""
    from flowtact.recording.hdf5 import stream_specs

    check_h5_file(path)
    try:
        return stream_specs(path)
    except (OSError, ValueError, KeyError) as e:
        raise FileRefused(path, str(e).removeprefix(f"{shown(path)}: ")) from None


def _check_h5_stream(path: Path, name: str, spec: ft.StreamSpec, offset: float) -> None:
    """The played stream's datasets: sizes within the budget and the file (every declared sample
    stored), its sample shape as its spec says, its first and last time stamps playable."""
    from flowtact.recording.hdf5 import open_recording, stream_header

    with open_recording(path) as f:
        h = stream_header(f, name)
        what = f"stream {name}"
        t, data = h.t, h.data
        if t.ndim != 1 or data.ndim < 1:
            raise FileRefused(path, f"{what}: datasets of shape {t.shape} (t) and {data.shape} (data)")
        if tuple(data.shape[1:]) != tuple(spec.shape):
            raise FileRefused(
                path, f"{what}: data of samples {data.shape[1:]}, but its attributes say {spec.shape}"
            )
        row = math.prod(data.shape[1:]) * data.dtype.itemsize
        if 8 * t.shape[0] > REPLAY_BUDGET_BYTES or row > REPLAY_BUDGET_BYTES:
            raise FileRefused(
                path,
                f"{what} declares {t.shape[0]} samples of {data.shape[1:]} {data.dtype}: its time stamps "
                f"alone take {budget_text(max(8 * t.shape[0], row))}",
            )
        for ds in (t, data):
            if (why := _unstored(ds)) is not None:
                raise FileRefused(path, f"{what}: {ds.name} of shape {ds.shape} {why}")
        end = float(h.attrs.get("end_s", math.nan))
        firsts = [f.read(t, i) for i in ((0, h.n - 1) if h.n else ())]
        for i, value in zip((0, h.n - 1), firsts, strict=False):
            if why := time_problem(float(value) + offset):
                raise FileRefused(path, f"{what}: t[{i}] = {float(value):.9g} s {why}")
        if math.isfinite(end) and (why := time_problem(end + offset)):
            raise FileRefused(path, f"{what}: its end_s {end:.9g} s {why}")


def _unstored(ds: Any) -> str | None:
    """Why a dataset cannot be read as declared (a chunk index with too few chunks, contiguous
    storage smaller than the shape, chunks too large to inflate), or None: a recording stores
    what it declares, in small chunks."""
    shape = ds.shape
    if not shape or 0 in shape:
        return None
    if ds.chunks is None:
        stored = ds.id.get_storage_size()
        need = math.prod(shape) * ds.dtype.itemsize
        return None if stored >= need or ds.compression else f"stores only {stored} of its {need} bytes"
    chunk = math.prod(ds.chunks) * ds.dtype.itemsize
    if chunk > MAX_CHUNK_BYTES and ds.chunks[0] > 1:  # HDF5 inflates a whole chunk to read a value
        return f"is stored in chunks of {ft.format_bytes(chunk)}; a replay reads chunks of at most {ft.format_bytes(MAX_CHUNK_BYTES)}"
    need = math.prod(-(-n // c) for n, c in zip(shape, ds.chunks, strict=True))
    stored = ds.id.get_num_chunks()
    return None if stored >= need else f"stores only {stored} of its {need} chunks (not written, or cut)"


def _example_file() -> Path:
    """A small .npz (0.4 s of three force channels at 1 kHz) in this process's private example
    folder (:func:`flowtact.block.example_folder`), written once."""
    path = ft.example_folder() / "replay-example.npz"
    if not path.exists():
        i = np.arange(400)
        t = i / 1000.0
        data = np.stack(
            [0.1 * np.sin(2 * np.pi * 5 * t), 0.05 * np.cos(2 * np.pi * 3 * t), 0.12 + 0.0 * t], axis=1
        )
        np.savez(path, t=t, data=data)
    return path
