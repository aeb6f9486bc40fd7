"""Crash-safe HDF5 recordings of a run's streams, with the provenance needed to re-create it.

Layout of a recording (one ``.h5`` file; docs/recordings.md documents it with Python and MATLAB)::

    /                          root attributes: the provenance bundle (flowtact_version, graph_yaml,
                               params, seeds, graph_seed, versions, command, created_utc, host, ...),
                               format = "flowtact-recording", format_version = 2, and at close
                               summary (JSON: what the executor reports + samples per stream) and
                               error ("" when the run ended well)
    /streams/<node>.<port>/t      float64 (n,)   sample times, or spike times for event streams
    /streams/<node>.<port>/data   (n, *shape)    samples, frames, or the unit index of each event
        attributes: kind (samples/frames/events/pulses), units, rate_hz (NaN for events), events
        (0/1), n_units (-1: none), sample_shape (int64 array), channel_labels (string array, when
        the channels are named), labels and categories (JSON lists or "null"; categories[i] names
        sample value i), dtype, shape (JSON list), end_s (last time the stream reached)
    /provenance/<key>          only for provenance values too long for an attribute (> 60 kB)
    /integrity                 the checksum manifest (flowtact.recording.integrity)

Every dataset carries HDF5's Fletcher-32 checksum; the manifest holds the SHA-256 of every
attribute and the shape of every dataset, so the readers here refuse a damaged file naming the
dataset or attribute (:class:`flowtact.errors.RecordingCorrupted`). Recordings of
format_version 1 (no checksums) still read.

Values that were not strings (dicts, lists) are stored as JSON text and listed in the root
attribute ``json_attrs``; :func:`read_recording` decodes them. Strings are stored verbatim.

Opening from MATLAB (HDF5 is row-major, MATLAB column-major, so arrays come out transposed)::

    t  = h5read('run.h5', '/streams/force.f/t');          % n x 1
    f  = h5read('run.h5', '/streams/force.f/data').';      % n x 3 after the transpose
    u  = h5readatt('run.h5', '/streams/force.f', 'units');
    g  = h5readatt('run.h5', '/', 'graph_yaml');
    p  = jsondecode(h5readatt('run.h5', '/', 'params'));
    s  = jsondecode(h5readatt('run.h5', '/', 'summary'));  % absent if the run was killed

Crash safety. HDF5 is not crash-consistent: a process killed while the library writes metadata
can leave a file that no longer opens, or one whose datasets silently read back as zeros (the
dataspace grew but the chunk index did not). SWMR mode keeps the structure consistent, but a
killed SWMR writer leaves the superblock's "open for write" flag set, so a plain
``h5py.File(path, "r")`` refuses the file until ``h5clear`` is run. The recorder therefore never
writes the file at ``path`` in place. It keeps two complete copies: ``path`` (committed, always a
closed, consistent HDF5 file) and a hidden work copy ``.<name>.wip`` beside it. Each flush opens
the work copy, appends what it lacks, closes it, and swaps the two names (hard link + atomic
``os.replace``), so ``path`` moves from one complete file to the next in one rename. A SIGKILL at
any moment leaves ``path`` holding everything up to the previous flush: at most
``flush_interval_s`` (default 1 s) plus one write is lost, and the file opens with plain h5py.
The price: every sample is written twice (once to each copy), the disk holds two copies while
recording (the work copy is deleted at close), and each flush opens and closes an HDF5 file
(about a millisecond). Without hard links (FAT, some network shares) the swap falls back to
three renames with a moment where ``path`` is missing; the work copy is then still complete.
Process death is covered; power loss is not (no fsync). Between flushes data is held in memory.

Compression is off by default: recording is on the speed-critical path and every sample is
written twice. Checksums are always on: Fletcher-32 makes a flush re-read and re-checksum the
partly filled chunk it appends to, and the manifest is rewritten at each flush. ``compression="gzip"`` (level 1, with shuffle) is offered for frame-heavy
recordings; MATLAB reads gzip natively. ``h5repack -f GZIP=4 in.h5 out.h5`` compresses after.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import json
import math
import os
import platform
import shutil
import sys
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any, Literal

import h5py
import numpy as np

from flowtact.chunk import Chunk, StreamSpec
from flowtact.errors import NotARecording, RecordingCorrupted, RecordingRefused
from flowtact.inputs.safe_text import shown
from flowtact.recording.integrity import MAX_CHUNK_BYTES, CheckedFile, Manifest

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "RecordedStream",
    "Recorder",
    "Recording",
    "StreamHeader",
    "open_recording",
    "open_stream",
    "open_verified",
    "package_versions",
    "read_recording",
    "spec_from_attrs",
    "stream_count",
    "stream_header",
    "stream_kind",
    "stream_specs",
]

FORMAT = "flowtact-recording"
FORMAT_VERSION = 2  # 2: Fletcher-32 on every dataset and the /integrity manifest
#: Target bytes per HDF5 chunk: whole chunks are re-read and re-written when a flush appends to a
#: partly filled one, so they stay small; a 240x320 uint8 frame makes one chunk of its own.
CHUNK_BYTES = 64 * 1024
#: Longest text stored as an attribute; longer provenance values become /provenance datasets.
MAX_ATTR_BYTES = 60_000
#: Longest provenance text read back from a /provenance dataset (a resolved graph is far shorter).
MAX_PROVENANCE_BYTES = 16 << 20
_VERSIONED = ("numpy", "numba", "h5py", "pyzmq", "msgpack", "pyyaml", "scipy", "matplotlib")


def package_versions() -> dict[str, str]:
    """Python, HDF5 and dependency versions (those installed), for the provenance bundle."""
    out = {
        "python": platform.python_version(),
        "platform": platform.platform(),
        "hdf5": h5py.version.hdf5_version,
    }
    for dist in _VERSIONED:
        with contextlib.suppress(PackageNotFoundError):
            out[dist] = version(dist)
    return out


def _default_provenance() -> dict[str, Any]:
    from flowtact.version import __version__

    return {
        "flowtact_version": __version__,
        "versions": package_versions(),
        "command": " ".join(sys.argv),
        "created_utc": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "host": platform.node(),
    }


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (set, frozenset)):
        return sorted(obj, key=str)
    return str(obj)


def _dumps(obj: Any) -> str:
    return json.dumps(obj, default=_json_default, allow_nan=True)


def _chunk_rows(row_bytes: int) -> int:
    return int(max(1, min(1 << 16, CHUNK_BYTES // max(row_bytes, 1))))


def _remove(path: Path) -> None:
    with contextlib.suppress(FileNotFoundError):
        os.remove(path)


def stream_kind(spec: StreamSpec) -> str:
    """What a stream holds: "pulses" (events whose columns start with the unit), "events",
    "frames" (samples of two or more dimensions) or "samples"."""
    if spec.events:
        labels = spec.labels or ()
        return "pulses" if len(spec.shape) == 1 and labels and labels[0] == "unit" else "events"
    return "frames" if len(spec.shape) >= 2 else "samples"


def _spec_attrs(spec: StreamSpec) -> dict[str, Any]:
    extra: dict[str, Any] = {}
    if spec.labels is not None:  # plain strings, for MATLAB's h5readatt (no jsondecode)
        extra["channel_labels"] = np.array([str(x) for x in spec.labels], dtype=h5py.string_dtype())
    return {
        "kind": stream_kind(spec),
        "units": spec.units,
        "rate_hz": float(spec.rate_hz) if (spec.rate_hz is not None and not spec.events) else math.nan,
        "events": np.int8(bool(spec.events)),
        "n_units": np.int64(-1 if spec.n_units is None else spec.n_units),
        "labels": _dumps(list(spec.labels) if spec.labels is not None else None),
        "categories": _dumps(list(spec.categories) if spec.categories is not None else None),
        "dtype": np.dtype(spec.dtype).name,
        "shape": _dumps(list(spec.shape)),
        "sample_shape": np.array(spec.shape, dtype=np.int64),
        **extra,
        "end_s": math.nan,
    }


def _attr(value: Any) -> Any:
    return value.decode() if isinstance(value, bytes) else value


def spec_from_attrs(attrs: Mapping[str, Any], data: h5py.Dataset) -> StreamSpec:
    """The StreamSpec a recorded stream's attributes describe (its data set fills in dtype and shape
    when the attributes leave them out)."""
    events = bool(_attr(attrs.get("events", 0)))
    rate = float(_attr(attrs.get("rate_hz", math.nan)))
    n_units = int(_attr(attrs.get("n_units", -1)))
    labels = json.loads(_attr(attrs.get("labels", "null")))
    categories = json.loads(_attr(attrs.get("categories", "null")))
    shape = attrs.get("shape")
    return StreamSpec(
        dtype=str(_attr(attrs.get("dtype", data.dtype.name))),
        shape=tuple(json.loads(_attr(shape))) if shape is not None else tuple(data.shape[1:]),
        units=str(_attr(attrs.get("units", "1"))),
        rate_hz=None if (events or math.isnan(rate)) else rate,
        events=events,
        n_units=None if n_units < 0 else n_units,
        labels=None if labels is None else tuple(labels),
        categories=None if categories is None else tuple(categories),
    )


class _Buffer:
    """Samples of one stream not yet in both copies: index ``start`` onwards, as a list of chunks."""

    def __init__(self, spec: StreamSpec) -> None:
        self.spec = spec
        self.dtype = np.dtype(spec.dtype)
        self.shape = tuple(spec.shape)
        self.t: list[np.ndarray] = []
        self.data: list[np.ndarray] = []
        self.start = 0  # stream index of the first buffered sample
        self.n = 0  # samples written so far
        self.committed = 0  # samples in the file at ``path``
        self.end_s = -math.inf

    def take(self, first: int) -> tuple[np.ndarray, np.ndarray]:
        """Buffered samples from stream index ``first`` to ``n``, joined."""
        if len(self.t) > 1:
            self.t = [np.concatenate(self.t)]
            self.data = [np.concatenate(self.data)]
        if not self.t:
            return np.empty(0, np.float64), np.empty((0, *self.shape), self.dtype)
        k = first - self.start
        if k < 0:
            raise RuntimeError(f"recorder lost track of samples {first}..{self.start} (bug)")
        return self.t[0][k:], self.data[0][k:]

    def drop_before(self, index: int) -> None:
        """Forget samples below ``index`` (both copies hold them)."""
        k = index - self.start
        if k <= 0:
            return
        t, d = self.take(self.start)
        self.t, self.data = ([t[k:]], [d[k:]]) if k < len(t) else ([], [])
        self.start = index


class Recorder:
    """Write chunks of named streams to a crash-safe HDF5 recording (see the module docstring).

    ``streams`` maps ``"<node>.<port>"`` to the stream's spec; ``provenance`` holds the bundle
    stored at the root (missing ``flowtact_version``, ``versions``, ``command`` and
    ``created_utc`` are filled in). ``write`` appends in memory and flushes when
    ``flush_interval_s`` of wall time has passed since the last flush; ``maybe_flush`` does the
    same check without data (call it on idle ticks); ``close`` flushes and stores the summary.
    An existing file at ``path`` is replaced. Also a context manager.
    """

    def __init__(
        self,
        path: str | Path,
        streams: Mapping[str, StreamSpec],
        provenance: Mapping[str, Any],
        flush_interval_s: float = 1.0,
        *,
        compression: Literal["gzip"] | None = None,
    ) -> None:
        if not flush_interval_s >= 0:
            raise ValueError(f"flush_interval_s must be >= 0; got {flush_interval_s!r}")
        if compression not in (None, "gzip"):
            raise ValueError(f"compression must be None or 'gzip'; got {compression!r}")
        self.path = Path(path)
        if self.path.is_dir():
            raise IsADirectoryError(f"cannot record to {self.path}: it is a directory")
        for name, spec in streams.items():
            if not name or "/" in name or name in (".", ".."):
                raise ValueError(f"invalid stream name {name!r}: use '<node>.<port>' without '/'")
            row = np.dtype(spec.dtype).itemsize * math.prod(spec.shape)
            if row > MAX_CHUNK_BYTES:
                raise ValueError(
                    f"{name}: one sample of {row:,} bytes is larger than a recording's chunks may be "
                    f"({MAX_CHUNK_BYTES:,} bytes: the readers refuse larger ones)"
                )
        self.flush_interval_s = float(flush_interval_s)
        self.compression = compression
        self._bufs = {name: _Buffer(spec) for name, spec in streams.items()}
        self._wip = self.path.with_name(f".{self.path.name}.wip")
        self._old = self.path.with_name(f".{self.path.name}.old")
        self._closed = False
        self._summary: str | None = None
        self._t0 = time.monotonic()
        self.flushes = 0
        self.flush_s = 0.0
        self.path.parent.mkdir(parents=True, exist_ok=True)
        _remove(self._wip)
        _remove(self._old)
        self._create(self._wip, {**_default_provenance(), **dict(provenance)})
        shutil.copyfile(self._wip, self._old)
        os.replace(self._old, self.path)
        self._last_flush = time.monotonic()

    # -- file creation ----------------------------------------------------------------------
    def _create(self, path: Path, provenance: Mapping[str, Any]) -> None:
        with h5py.File(path, "w") as f:
            f.attrs["format"] = FORMAT
            f.attrs["format_version"] = FORMAT_VERSION
            json_keys = []
            for key, value in provenance.items():
                if value is None:
                    continue
                if isinstance(value, int) and not isinstance(value, bool) and not -(2**63) <= value < 2**64:
                    value = str(value)  # beyond HDF5's integers: kept exactly as text
                elif isinstance(value, (bool, int, float, np.generic)):
                    f.attrs[key] = value
                    continue
                if not isinstance(value, str):
                    value = _dumps(value)
                    json_keys.append(key)
                raw = value.encode()
                if len(raw) > MAX_ATTR_BYTES:  # one fixed-length UTF-8 string, so Fletcher-32 covers it
                    ds = f.require_group("provenance").create_dataset(
                        key,
                        data=np.array([raw], dtype=h5py.string_dtype("utf-8", len(raw))),
                        chunks=(1,),
                        fletcher32=True,
                    )
                    ds.attrs["json"] = np.int8(key in json_keys)
                else:
                    f.attrs[key] = value
            f.attrs["json_attrs"] = _dumps(json_keys)
            root = f.create_group("streams", track_order=True)
            for name, buf in self._bufs.items():
                g = root.create_group(name)
                for k, v in _spec_attrs(buf.spec).items():
                    g.attrs[k] = v
                row = buf.dtype.itemsize * int(np.prod(buf.shape, dtype=np.int64))
                opts: dict[str, Any] = {"fletcher32": True}
                if self.compression:
                    opts |= {"compression": "gzip", "compression_opts": 1, "shuffle": buf.dtype.itemsize > 1}
                g.create_dataset("t", (0,), np.float64, maxshape=(None,), chunks=(_chunk_rows(8),), **opts)
                g.create_dataset(
                    "data",
                    (0, *buf.shape),
                    buf.dtype,
                    maxshape=(None, *buf.shape),
                    chunks=(_chunk_rows(row), *buf.shape),
                    **opts,
                )
            self._manifest = Manifest()
            self._manifest.note_all(f)
            self._manifest.store(f)

    # -- writing ----------------------------------------------------------------------------
    def write(self, stream: str, chunk: Chunk) -> None:
        """Append a chunk of ``stream`` (copied); flush if ``flush_interval_s`` has passed."""
        if self._closed:
            raise ValueError(f"recorder for {self.path} is closed")
        buf = self._bufs.get(stream)
        if buf is None:
            raise KeyError(f"{self.path}: no recorded stream '{stream}' (recorded: {', '.join(self._bufs)})")
        n = len(chunk)
        if n:
            data = np.asarray(chunk.data)
            if data.shape[1:] != buf.shape or data.shape[0] != n:
                raise ValueError(
                    f"{stream}: chunk data shape {data.shape} does not fit t ({n},) and sample shape "
                    f"{buf.shape} of the recorded stream"
                )
            if data.dtype != buf.dtype:
                if not np.can_cast(data.dtype, buf.dtype, "same_kind"):
                    raise ValueError(f"{stream}: chunk dtype {data.dtype} cannot be stored as {buf.dtype}")
                data = data.astype(buf.dtype)
            else:
                data = data.copy()
            buf.t.append(np.array(chunk.t, np.float64))
            buf.data.append(data)
            buf.n += n
            buf.end_s = max(buf.end_s, float(chunk.t[-1]))
        if chunk.end is not None:
            buf.end_s = max(buf.end_s, float(chunk.end))
        if time.monotonic() - self._last_flush >= self.flush_interval_s:
            self.flush()

    def maybe_flush(self) -> None:
        """Flush if ``flush_interval_s`` of wall time has passed since the last flush."""
        if not self._closed and time.monotonic() - self._last_flush >= self.flush_interval_s:
            self.flush()

    def flush(self) -> None:
        """Make everything written so far durable at ``path`` (against a kill of this process)."""
        if self._closed:
            return
        self._commit(force=False)

    def _commit(self, force: bool) -> None:
        started = time.monotonic()
        if not force and all(b.n == b.committed for b in self._bufs.values()):
            self._last_flush = started
            return
        try:
            self._append(self._wip)
        except OSError:
            # the work copy is locked by a reader or damaged by an earlier failed flush:
            # start it afresh from the committed file (slow, rare).
            _remove(self._wip)
            shutil.copyfile(self.path, self._wip)
            self._append(self._wip)
        self._swap()
        for b in self._bufs.values():
            previous, b.committed = b.committed, b.n
            b.drop_before(previous)  # the work copy is now the old committed file
        self.flushes += 1
        self._last_flush = time.monotonic()
        self.flush_s += self._last_flush - started

    def _append(self, path: Path) -> None:
        with h5py.File(path, "r+") as f:
            for name, b in self._bufs.items():
                g = f["streams"][name]
                t_ds, d_ds = g["t"], g["data"]
                have = t_ds.shape[0]
                t, d = b.take(have)
                if len(t):
                    t_ds.resize((b.n,))
                    t_ds[have:] = t
                    d_ds.resize((b.n, *b.shape))
                    d_ds[have:] = d
                    self._manifest.note_dataset(t_ds)
                    self._manifest.note_dataset(d_ds)
                if math.isfinite(b.end_s) and g.attrs["end_s"] != b.end_s:
                    g.attrs["end_s"] = b.end_s
                    self._manifest.note_attr(g, "end_s")
            if self._summary is not None:
                f.attrs["summary"] = self._summary
                f.attrs["error"] = self._error
                self._manifest.note_attr(f, "summary")
                self._manifest.note_attr(f, "error")
            self._manifest.store(f)

    def _swap(self) -> None:
        """Make the freshly written work copy the file at ``path``, and the old one the work copy."""
        _remove(self._old)
        try:
            os.link(self.path, self._old)
        except OSError:  # no hard links here: three renames, with a moment where path is missing
            os.replace(self.path, self._old)
            os.replace(self._wip, self.path)
            os.replace(self._old, self._wip)
            return
        os.replace(self._wip, self.path)  # the atomic step
        os.replace(self._old, self._wip)

    # -- closing ----------------------------------------------------------------------------
    def close(self, summary: Mapping[str, Any] | None = None) -> None:
        """Flush everything, store the summary (with samples per stream), delete the work copy."""
        if self._closed:
            return
        own = {
            "samples": {name: b.n for name, b in self._bufs.items()},
            "end_s": {name: (b.end_s if math.isfinite(b.end_s) else None) for name, b in self._bufs.items()},
            "flushes": self.flushes + 1,
            "flush_s": round(self.flush_s, 6),
            "wall_s": round(time.monotonic() - self._t0, 6),
        }
        self._summary = _dumps({**dict(summary or {}), "recorder": own})
        self._error = str((summary or {}).get("error") or "")
        try:
            self._commit(force=True)
        finally:
            self._closed = True
            _remove(self._wip)
            _remove(self._old)

    @property
    def closed(self) -> bool:
        """Whether ``close`` has run."""
        return self._closed

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, exc_type: Any, exc: BaseException | None, tb: Any) -> None:
        if not self._closed:
            self.close({"error": f"{type(exc).__name__}: {exc}"} if exc is not None else None)

    def __repr__(self) -> str:
        return f"<Recorder {str(self.path)!r} streams={list(self._bufs)} closed={self._closed}>"


# -- reading --------------------------------------------------------------------------------


@dataclass(frozen=True)
class RecordedStream:
    """One recorded stream: times, data, its spec and its raw HDF5 attributes."""

    t: np.ndarray
    data: np.ndarray
    spec: StreamSpec
    attrs: dict[str, Any] = field(default_factory=dict)

    @property
    def end_s(self) -> float | None:
        """The last time the stream reached (its last watermark), if recorded."""
        end = self.attrs.get("end_s")
        return None if end is None or not math.isfinite(float(end)) else float(end)

    def chunk(self) -> Chunk:
        """The whole stream as one chunk (events carry their ``end`` watermark)."""
        return Chunk(self.t, self.data, self.end_s if self.spec.events else None)


@dataclass(frozen=True)
class Recording:
    """A recording read back: ``streams`` by name, the ``provenance`` bundle and the ``summary``.

    ``summary`` is None when the writing run was killed before it closed the recording.
    """

    path: Path
    streams: dict[str, RecordedStream]
    provenance: dict[str, Any]
    summary: dict[str, Any] | None

    @property
    def complete(self) -> bool:
        """Whether the writer closed the recording (False after a kill)."""
        return self.summary is not None

    def json(self, key: str) -> Any:
        """A provenance entry parsed as JSON, whether stored as JSON text or already decoded."""
        value = self.provenance[key]
        return json.loads(value) if isinstance(value, str) else value


def open_recording(path: str | Path) -> CheckedFile:
    """Open a recording with its checksums, refusing a non-HDF5, truncated or damaged file: the
    root attributes (the provenance) are verified here, whatever the reader goes on to read."""
    f = CheckedFile(path)
    try:
        if "streams" not in f.file:
            raise NotARecording(f"{shown(f.path)}: not a flowtact recording (no /streams group)")
        f.attrs(f.file)
    except BaseException:
        f.close()
        raise
    return f


def open_verified(path: str | Path) -> h5py.File:
    """The raw h5py file, for readers that walk it themselves (plots, training): every checksum is
    verified first, chunk by chunk (memory bounded), so a damaged file is refused naming the
    dataset or attribute before anything is read from it; the caller closes the file."""
    f = open_recording(path)
    try:
        problems = f.problems()
    except BaseException:
        f.close()
        raise
    if problems:
        f.close()
        raise RecordingCorrupted(f.path, problems[0].where, problems[0].what)
    return f.file


def _select(f: CheckedFile, streams: Iterable[str] | None) -> list[str]:
    available = list(f.group("/streams"))
    if streams is None:
        return available
    names = list(streams)
    for name in names:
        if name not in available:
            have = shown(", ".join(available) or "none", limit=500)
            raise KeyError(f"{shown(f.path)}: no stream '{shown(name)}' (available: {have})")
    return names


@dataclass(frozen=True)
class StreamHeader:
    """A stream's group, its verified attributes, datasets and sample count (no data read)."""

    attrs: dict[str, Any]
    t: h5py.Dataset
    data: h5py.Dataset
    spec: StreamSpec

    @property
    def n(self) -> int:
        return int(min(self.t.shape[0], self.data.shape[0]))


def stream_header(f: CheckedFile, name: str) -> StreamHeader:
    where = f"/streams/{name}"
    g = f.group(where)
    attrs = f.attrs(g)
    t, data = f.group(f"{where}/t"), f.group(f"{where}/data")
    try:
        spec = spec_from_attrs(attrs, data)
    except (ValueError, TypeError, KeyError, RecursionError) as e:  # only unchecksummed (old) files get here
        raise RecordingCorrupted(
            f.path, where, f"attributes do not describe a stream ({shown(e, limit=200)})"
        ) from None
    return StreamHeader(attrs, t, data, spec)


def stream_count(path: str | Path) -> int:
    """How many streams a recording holds, from its header (root attributes verified, no data)."""
    with open_recording(path) as f:
        return len(f.group("/streams"))


def stream_specs(path: str | Path) -> dict[str, tuple[StreamSpec, int]]:
    """Each stream's spec and sample count, read from the file header only (no data).

    Attributes and dataset shapes are checked against the file's checksums; the data is not read.
    """
    with open_recording(path) as f:
        out = {}
        for name in _select(f, None):
            h = stream_header(f, name)
            out[name] = (h.spec, h.n)
        return out


def open_stream(path: str | Path, name: str) -> tuple[CheckedFile, StreamHeader]:
    """Open one stream for reading slice by slice, after verifying every checksum of its datasets
    chunk by chunk (memory bounded): a damaged file is refused before anything is played."""
    f = open_recording(path)
    try:
        h = stream_header(f, _select(f, [name])[0])
        f.verify(h.t)
        f.verify(h.data)
    except BaseException:
        f.close()
        raise
    return f, h


def read_recording(path: str | Path, streams: Iterable[str] | None = None) -> Recording:
    """Read a recording (all streams, or the named ones); copes with a killed run (no summary).

    Every attribute and chunk read is checked against the file's checksums: a damaged recording
    raises :class:`flowtact.errors.RecordingCorrupted` naming the dataset.
    """
    with open_recording(path) as f:
        out = {}
        for name in _select(f, streams):
            h = stream_header(f, name)
            out[name] = RecordedStream(
                f.read(h.t, slice(0, h.n)), f.read(h.data, slice(0, h.n)), h.spec, h.attrs
            )
        root = f.attrs(f.file)
        json_keys = set(_json(f, "/ json_attrs", root.pop("json_attrs", "[]")))
        summary = root.pop("summary", None)
        root.pop("error", None)  # the summary's error, repeated as plain text for MATLAB
        provenance: dict[str, Any] = {}
        for key, value in root.items():
            if isinstance(value, np.generic):
                value = value.item()
            provenance[key] = _json(f, f"/ {key}", value) if key in json_keys else value
        if "provenance" in f.file:
            for key in f.group("/provenance"):
                ds = f.group(f"/provenance/{key}")
                if ds.size * ds.dtype.itemsize > MAX_PROVENANCE_BYTES:
                    raise RecordingRefused(
                        f"{shown(f.path)}: /provenance/{shown(key, limit=200)}: {ds.size * ds.dtype.itemsize:,} "
                        f"bytes of text (at most {MAX_PROVENANCE_BYTES:,})"
                    )
                text = _provenance_text(f.read(ds))
                provenance[key] = (
                    _json(f, f"/provenance/{key}", text) if int(f.attrs(ds).get("json", 0)) else text
                )
        summary = _json(f, "/ summary", summary) if summary is not None else None
    return Recording(Path(path), out, provenance, summary)


def _json(f: CheckedFile, where: str, text: Any) -> Any:
    """``text`` (JSON from the file at ``where``) parsed; text that does not parse is damage, named."""
    try:
        return json.loads(text)
    except (ValueError, TypeError, RecursionError) as e:
        raise RecordingCorrupted(f.path, where, f"not valid JSON ({shown(e, limit=200)})") from None


def _provenance_text(value: Any) -> str:
    """A /provenance dataset's text: one fixed-length UTF-8 string (v2) or a scalar string (v1)."""
    if isinstance(value, np.ndarray):
        value = value.reshape(-1)[0]
    return value.decode() if isinstance(value, bytes) else str(value)
