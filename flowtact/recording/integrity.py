"""Checksums of a recording, and a file reader that refuses damage naming the dataset or attribute.

HDF5's Fletcher-32 filter checksums every chunk of a dataset, but not attributes, nor a dataset's
shape and type. So a recording also carries a manifest, ``/integrity``: a Fletcher-32-checked
dataset of UTF-8 JSON holding the SHA-256 of every attribute of every object and the dtype and
shape of every dataset. :class:`CheckedFile` reads through it: every attribute it returns matches
its digest, every dataset its recorded shape, every chunk read its checksum, or it raises
:class:`RecordingCorrupted` naming the file and the object. Recordings written before checksums
(format_version 1: no manifest, no filters) still open; ``checksummed`` is then False.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import math
import os
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from flowtact.errors import (
    FileRefused,
    RecordingCorrupted,
    RecordingError,
    RecordingRefused,
)
from flowtact.inputs.bounded_files import check_hdf5_signature, open_regular
from flowtact.inputs.limits import format_bytes
from flowtact.inputs.safe_text import shown

__all__ = [
    "MANIFEST",
    "CheckedFile",
    "Manifest",
    "Problem",
    "attr_digest",
]

#: Name of the root dataset holding the manifest (UTF-8 JSON bytes).
MANIFEST = "integrity"
MANIFEST_VERSION = 1
#: Most bytes held in memory while verifying a dataset (whole chunks, several at a time).
VERIFY_BYTES = 8 << 20
_CORRUPT = "(the file is corrupted)"

# -- the bounds every recording is checked against before it is read (docs/recordings.md) -----------
MAX_STREAMS = 4096
"""Most streams a recording may hold (each is a group, two datasets and a dozen attributes; a graph
records a few dozen): `flowtact info` verifies and describes that many in about 5 s."""
MAX_OBJECTS = 4 * MAX_STREAMS + 64
"""Most groups and datasets a recording may hold (the streams' and a few more)."""
MAX_ATTRS = 256
"""Most attributes one object may carry (a stream carries about fifteen)."""
MAX_ATTR_BYTES = 1 << 20
"""Largest attribute value read (1 MiB; flowtact stores text over 60 kB as a dataset instead)."""
MAX_CHUNK_BYTES = 16 << 20
"""Largest HDF5 chunk (uncompressed) of a dataset: a chunk is read whole (the recorder's are 64 kB,
or one sample when a sample is larger)."""
MAX_READ_BYTES = MAX_CHUNK_BYTES + (1 << 20)
"""Largest single read from the file (a stored chunk, or a piece of HDF5 metadata such as the heap
holding a text attribute): a larger one is refused before it is done."""
MAX_MANIFEST_BYTES = 32 << 20
"""Largest checksum manifest (about 1.3 kB per stream)."""
ATTR_MEMORY_HEADROOM = 128 << 20
"""Most memory (address space) one attribute read may add, on Linux: libhdf5 allocates a text
attribute's declared length before reading it, and that length is whatever the file says."""
MAX_COMPRESSION_RATIO = 1100
"""Most uncompressed bytes a dataset may declare per stored byte when it is compressed (deflate
cannot exceed 1032:1); uncompressed, it must store every byte it declares (plus one chunk)."""


@dataclass(frozen=True)
class Problem:
    """One damaged object found by :meth:`CheckedFile.problems`."""

    where: str  # "/streams/force.f/data", or "/streams/force.f" for its attributes
    what: str  # "checksum mismatch", "attribute 'units' does not match its checksum", ...

    def __str__(self) -> str:
        return f"{shown(self.where, limit=200)}: {self.what}"


def attr_digest(value: Any) -> str:
    """SHA-256 (hex) of an attribute value as h5py reads it: type, shape and bytes."""
    h = hashlib.sha256()
    if isinstance(value, bytes):
        h.update(b"b:" + value)
    elif isinstance(value, str):
        h.update(b"s:" + value.encode("utf-8", "surrogatepass"))
    else:
        a = np.asarray(value)
        if a.dtype.hasobject:  # arrays of variable-length strings
            h.update(b"o:" + json.dumps([_text(v) for v in a.ravel().tolist()]).encode())
            h.update(repr(a.shape).encode())
        else:
            a = np.ascontiguousarray(a, a.dtype.newbyteorder("<"))
            h.update(f"a:{a.dtype.str}:{a.shape}:".encode() + a.tobytes())
    return h.hexdigest()


def _text(v: Any) -> Any:
    return v.decode("utf-8", "surrogateescape") if isinstance(v, bytes) else v


def _dataset_facts(ds: h5py.Dataset) -> dict[str, Any]:
    return {"dtype": ds.dtype.str, "shape": list(ds.shape)}


def _raw_attrs(obj: h5py.HLObject) -> dict[str, Any]:
    """Every attribute of ``obj`` as h5py reads it (raises OSError and the like when damaged)."""
    return {name: obj.attrs[name] for name in obj.attrs}


@dataclass
class Manifest:
    """SHA-256 of every attribute per object, and dtype/shape per dataset, stored at ``/integrity``."""

    attrs: dict[str, dict[str, str]] = field(default_factory=dict)
    datasets: dict[str, dict[str, Any]] = field(default_factory=dict)

    def note_attrs(self, obj: h5py.HLObject) -> None:
        """Record the digests of ``obj``'s attributes, read back from the file."""
        self.attrs[obj.name] = {k: attr_digest(v) for k, v in _raw_attrs(obj).items()}

    def note_attr(self, obj: h5py.HLObject, name: str) -> None:
        """Record the digest of one attribute of ``obj`` (after the writer changed it)."""
        self.attrs.setdefault(obj.name, {})[name] = attr_digest(obj.attrs[name])

    def note_dataset(self, ds: h5py.Dataset) -> None:
        """Record ``ds``'s dtype and shape."""
        self.datasets[ds.name] = _dataset_facts(ds)

    def note_all(self, f: h5py.File) -> None:
        """Record every object of ``f`` (but the manifest itself)."""
        self.note_attrs(f)

        def visit(name: str, obj: Any) -> None:
            if name == MANIFEST:
                return
            self.note_attrs(obj)
            if isinstance(obj, h5py.Dataset):
                self.note_dataset(obj)

        f.visititems(visit)

    def store(self, f: h5py.File) -> None:
        """Write the manifest into ``f`` (creating or resizing ``/integrity``)."""
        doc = {"version": MANIFEST_VERSION, "attributes": self.attrs, "datasets": self.datasets}
        raw = np.frombuffer(json.dumps(doc, sort_keys=True).encode(), np.uint8)
        ds = f.get(MANIFEST)
        if ds is None:
            ds = f.create_dataset(
                MANIFEST, (0,), np.uint8, maxshape=(None,), chunks=(1 << 13,), fletcher32=True
            )
        ds.resize((len(raw),))
        ds[:] = raw

    @classmethod
    def parse(cls, raw: bytes) -> Manifest:
        """The manifest from the bytes of ``/integrity`` (ValueError when they are not one)."""
        doc = json.loads(raw.decode())
        if not isinstance(doc, dict) or doc.get("version") != MANIFEST_VERSION:
            raise ValueError(
                f"unknown manifest version {doc.get('version') if isinstance(doc, dict) else doc!r}"
            )
        return cls(dict(doc["attributes"]), dict(doc["datasets"]))


class _BoundedRaw(io.RawIOBase):
    """The recording's bytes for h5py (its ``fileobj`` driver), with every read bounded: one read
    may not exceed :data:`MAX_READ_BYTES`, and inside :meth:`budget` the reads together may not
    exceed the budget. A refused read fails the HDF5 call, so a hostile chunk or heap is never read
    whole (libhdf5 may still allocate a text attribute's declared length before reading it: one
    buffer of that size, which docs/recordings.md notes)."""

    def __init__(self, fh: Any) -> None:
        super().__init__()
        self._fh = fh
        self._left: int | None = None
        self._budget = 0
        self.refused: str | None = None  # why the last read was refused (for the error message)

    def readable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def seek(self, offset: int, whence: int = 0) -> int:
        return self._fh.seek(offset, whence)

    def tell(self) -> int:
        return self._fh.tell()

    def readinto(self, b: Any) -> int:
        n = len(b)
        if self._left is not None and n > self._left:
            self.refused = f"more than {format_bytes(self._budget)}"
        elif n > MAX_READ_BYTES:
            self.refused = (
                f"a piece of {format_bytes(n)} (at most {format_bytes(MAX_READ_BYTES)} is read at once)"
            )
        if self.refused is not None:
            raise OSError(f"read refused: {self.refused}")
        if self._left is not None:
            self._left -= n
        return self._fh.readinto(b)

    @contextlib.contextmanager
    def budget(self, nbytes: int) -> Iterator[None]:
        """Bound the bytes read inside the ``with`` block to ``nbytes``."""
        self._left = self._budget = nbytes
        self.refused = None
        try:
            yield
        finally:
            self._left = None

    def close(self) -> None:
        if not self.closed:
            self._fh.close()
        super().close()


def _address_space() -> int | None:
    """Bytes of address space this process maps now (Linux), or None where that is unknown."""
    try:
        with open("/proc/self/statm", "rb") as fh:
            return int(fh.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return None


@contextlib.contextmanager
def _memory_headroom(nbytes: int) -> Iterator[None]:
    """Within the block, allocations beyond ``nbytes`` more address space fail (``RLIMIT_AS``,
    Linux): a libhdf5 allocation sized by a hostile length field becomes an error instead of
    gigabytes. The limit is process-wide but held only for one attribute read, with ``nbytes`` of
    room for other threads' small allocations; restored after. A no-op where the limit cannot be
    read or set."""
    try:
        import resource

        soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    except (ImportError, OSError, ValueError):
        soft = hard = None
    used = _address_space()
    limit = None if used is None else used + nbytes
    if soft is None or limit is None or (soft != resource.RLIM_INFINITY and soft <= limit):
        yield
        return
    if hard != resource.RLIM_INFINITY:
        limit = min(limit, hard)
    resource.setrlimit(resource.RLIMIT_AS, (limit, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


def _open_h5(path: Path) -> tuple[h5py.File, _BoundedRaw]:
    """Open ``path`` read-only through a bounded reader, refusing a missing, non-regular, non-HDF5
    or truncated file in one line; the HDF5 signature is checked from a few bytes first."""
    if not path.exists():
        raise FileNotFoundError(f"recording not found: {shown(path)}")
    try:
        size = check_hdf5_signature(path).st_size
        raw = _BoundedRaw(open_regular(path))
    except FileRefused as e:
        raise RecordingRefused(str(e)) from None
    try:
        return h5py.File(raw, "r"), raw
    except OSError as e:
        raw.close()
        msg = str(e)
        if "truncated file" in msg:
            m = re.search(r"stored_eof = (\d+)", msg)
            expected = f" of the {int(m.group(1)):,} its header promises" if m else ""
            raise RecordingError(
                f"{shown(path)}: truncated: {size:,} bytes{expected} (cut short by a copy or a full disk?)"
            ) from None
        if "signature not found" in msg:
            raise RecordingError(f"{shown(path)}: not a readable HDF5 file (its header is damaged)") from None
        raise RecordingError(
            f"{shown(path)}: cannot be opened as HDF5 ({shown(_h5_reason(msg), limit=200)})"
        ) from None


def _storage_allows(ds: h5py.Dataset) -> int:
    """Most bytes ``ds`` may declare given what it stores (see :data:`MAX_COMPRESSION_RATIO`)."""
    plist = ds.id.get_create_plist()
    passive = {h5py.h5z.FILTER_FLETCHER32, h5py.h5z.FILTER_SHUFFLE}
    compressed = any(plist.get_filter(i)[0] not in passive for i in range(plist.get_nfilters()))
    chunk = math.prod(ds.chunks) * ds.dtype.itemsize if ds.chunks else 0
    return ds.id.get_storage_size() * (MAX_COMPRESSION_RATIO if compressed else 1) + chunk


def _dataset_bound_problem(ds: h5py.Dataset) -> str | None:
    """Why ``ds`` cannot be read within bounds (a huge chunk, or more samples declared than the
    file can hold), or None."""
    itemsize = ds.dtype.itemsize
    if ds.chunks:
        chunk = math.prod(ds.chunks) * itemsize
        if chunk > MAX_CHUNK_BYTES:
            return f"stored in chunks of {format_bytes(chunk)} (at most {format_bytes(MAX_CHUNK_BYTES)})"
    declared = math.prod(ds.shape or ()) * itemsize
    if declared > _storage_allows(ds):
        return (
            f"declares {math.prod(ds.shape or ()):,} values ({format_bytes(declared)}) but stores "
            f"{format_bytes(ds.id.get_storage_size())}"
        )
    return None


def _h5_reason(msg: str) -> str:
    """The useful part of an h5py error message ('Unable to ... (reason)' -> 'reason')."""
    m = re.search(r"\(([^()]*)\)\s*$", msg)
    return m.group(1) if m else msg


class CheckedFile:
    """A recording opened read-only whose reads are checked against its checksums.

    ``checksummed`` says whether the file carries them (False for recordings written before
    format_version 2). Every method raises :class:`RecordingCorrupted` naming the object at fault;
    :meth:`problems` instead lists every damaged object (for ``flowtact info``). With
    ``strict=False`` a damaged manifest is not raised but listed first by :meth:`problems`.
    """

    def __init__(self, path: str | Path, *, strict: bool = True) -> None:
        self.path = Path(path)
        self.file, self._raw = _open_h5(self.path)
        self.manifest: Manifest | None = None
        self.manifest_problem: Problem | None = None
        self.datasets_checked = 0
        try:
            self._check_streams()
            self._load_manifest()
        except RecordingCorrupted as e:
            if strict:
                self.close()
                raise
            self.manifest_problem = Problem(e.where, e.what)
        except BaseException:
            self.close()
            raise

    def _refused(self, what: str) -> RecordingRefused:
        return RecordingRefused(f"{shown(self.path)}: {what}")

    def _refusal(self, where: str) -> RecordingRefused | None:
        """The refusal of a read the bounded reader stopped (a hostile size), if that is what failed."""
        if self._raw.refused is None:
            return None
        return self._refused(f"{shown(where, limit=200)}: {self._raw.refused} (refused)")

    def _check_streams(self) -> None:
        """Refuse a file with more streams than :data:`MAX_STREAMS` before anything walks them."""
        try:
            g = self.file.get("streams")
            n = len(g) if isinstance(g, h5py.Group) else 0
        except (OSError, ValueError, RuntimeError) as e:
            raise self._refusal("/streams") or RecordingCorrupted(
                self.path, "/streams", f"cannot be read ({_h5_reason(str(e))})"
            ) from None
        if n > MAX_STREAMS:
            raise self._refused(f"holds {n:,} streams (at most {MAX_STREAMS:,})")

    def _load_manifest(self) -> None:
        f = self.file
        try:
            has = MANIFEST in f
            version = f.attrs.get("format_version", 1) if not has else None
        except (OSError, KeyError, ValueError, RuntimeError) as e:
            raise RecordingCorrupted(self.path, "/", f"cannot be read ({_h5_reason(str(e))})") from None
        if not has:
            if np.ndim(version) == 0 and isinstance(version, (int, np.integer)) and int(version) >= 2:
                raise RecordingCorrupted(
                    self.path, f"/{MANIFEST}", "missing, though format_version says checksummed"
                )
            return
        ds = self.group(f"/{MANIFEST}")
        if ds.ndim != 1 or ds.dtype.itemsize * ds.shape[0] > MAX_MANIFEST_BYTES:
            raise self._refused(
                f"/{MANIFEST}: a checksum manifest of shape {ds.shape} (at most {format_bytes(MAX_MANIFEST_BYTES)})"
            )
        raw = self.read(ds)
        try:
            self.manifest = Manifest.parse(raw.tobytes())
        except (ValueError, KeyError, TypeError, UnicodeDecodeError) as e:
            raise RecordingCorrupted(self.path, f"/{MANIFEST}", f"not a valid manifest ({e})") from None

    @property
    def checksummed(self) -> bool:
        """Whether the file carries checksums (a manifest and Fletcher-32 datasets)."""
        return self.manifest is not None or self.manifest_problem is not None

    def close(self) -> None:
        """Close the file."""
        self.file.close()
        self._raw.close()

    def __enter__(self) -> CheckedFile:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- objects and attributes ------------------------------------------------------------
    def group(self, name: str) -> Any:
        """The group or dataset at ``name``; a dataset's dtype and shape are checked."""
        try:
            obj = self.file[name]
        except KeyError:
            if self.manifest is not None and (name in self.manifest.datasets or name in self.manifest.attrs):
                raise RecordingCorrupted(self.path, name, "missing") from None
            raise
        except (OSError, ValueError, RuntimeError) as e:
            raise self._refusal(name) or RecordingCorrupted(
                self.path, name, f"cannot be read ({_h5_reason(str(e))})"
            ) from None
        if isinstance(obj, h5py.Dataset):
            problem = _dataset_bound_problem(obj)
            if problem is not None:
                raise self._refused(f"{shown(name, limit=200)}: {problem}")
            self._check_facts(obj)
        return obj

    def _check_facts(self, ds: h5py.Dataset) -> None:
        if self.manifest is None or ds.name == f"/{MANIFEST}":
            return
        want = self.manifest.datasets.get(ds.name)
        if want is None:
            raise RecordingCorrupted(self.path, ds.name, "not listed in the checksum manifest")
        have = _dataset_facts(ds)
        if have != want:
            raise RecordingCorrupted(
                self.path,
                ds.name,
                f"dtype/shape {have['dtype']} {have['shape']} differ from the "
                f"checksummed {want['dtype']} {want['shape']}",
            )

    def attrs(self, obj: h5py.HLObject) -> dict[str, Any]:
        """``obj``'s attributes (bytes decoded to str), each verified against its SHA-256."""
        values, problems = self.checked_attrs(obj)
        if problems:
            raise RecordingCorrupted(self.path, problems[0].where, problems[0].what)
        return values

    def checked_attrs(self, obj: h5py.HLObject) -> tuple[dict[str, Any], list[Problem]]:
        """``obj``'s attributes that match their SHA-256, and a problem for each one that does not."""
        try:
            raw = self._read_attrs(obj)
        except (OSError, ValueError, KeyError, RuntimeError, UnicodeError) as e:
            if isinstance(e, RecordingRefused):
                raise
            refusal = self._refusal(obj.name)
            if refusal is not None:
                raise refusal from None
            return {}, [
                Problem(obj.name, f"attributes cannot be read ({shown(_h5_reason(str(e)), limit=200)})")
            ]
        good = {k: _text(v) for k, v in raw.items()}
        if self.manifest is None:
            return good, []
        want = self.manifest.attrs.get(obj.name)
        if want is None:
            return {}, [Problem(obj.name, "not listed in the checksum manifest")]
        problems = []
        for name in sorted(set(want) | set(raw)):
            if name not in raw:
                problems.append(Problem(obj.name, f"attribute '{shown(name, limit=200)}' is missing"))
            elif name not in want or attr_digest(raw[name]) != want[name]:
                what = "is not in the manifest" if name not in want else "does not match its checksum"
                problems.append(Problem(obj.name, f"attribute '{shown(name, limit=200)}' {what}"))
                good.pop(name)
        return good, problems

    def _read_attrs(self, obj: h5py.HLObject) -> dict[str, Any]:
        """Every attribute of ``obj``, each size checked before it is read (:data:`MAX_ATTRS`,
        :data:`MAX_ATTR_BYTES`); a text attribute's heap is read under a byte budget."""
        n = h5py.h5o.get_info(obj.id).num_attrs
        if n > MAX_ATTRS:
            raise self._refused(
                f"{shown(obj.name, limit=200)}: carries {n:,} attributes (at most {MAX_ATTRS})"
            )
        out = {}
        for name in obj.attrs:
            stored = _attr_storage(obj, name)
            if stored > MAX_ATTR_BYTES:
                raise self._attr_refused(obj, name, stored)
            try:
                with self._raw.budget(MAX_ATTR_BYTES), _memory_headroom(ATTR_MEMORY_HEADROOM):
                    value = obj.attrs[name]
            except MemoryError:
                raise self._attr_too_long(obj, name) from None
            except OSError as e:  # a read refused by the budget, or an allocation libhdf5 could not make
                if self._raw.refused is None and "alloc" not in str(e):
                    raise
                raise self._attr_too_long(obj, name) from None
            size = _value_bytes(value)
            if size > MAX_ATTR_BYTES:
                raise self._attr_refused(obj, name, size)
            out[name] = value
        return out

    def _attr_too_long(self, obj: h5py.HLObject, name: str) -> RecordingRefused:
        return self._refused(
            f"{shown(obj.name, limit=200)}: attribute '{shown(name, limit=200)}' is larger than "
            f"{format_bytes(MAX_ATTR_BYTES)} (refused before it was read)"
        )

    def _attr_refused(self, obj: h5py.HLObject, name: str, size: int) -> RecordingRefused:
        return self._refused(
            f"{shown(obj.name, limit=200)}: attribute '{shown(name, limit=200)}' holds {format_bytes(size)} "
            f"(at most {format_bytes(MAX_ATTR_BYTES)})"
        )

    # -- data ------------------------------------------------------------------------------
    def read(self, ds: h5py.Dataset, sel: Any = ()) -> np.ndarray:
        """``ds[sel]``, each chunk's checksum verified by HDF5 on the way."""
        try:
            if ds.dtype.kind == "O":  # variable-length text: its heap is read under a budget
                with self._raw.budget(MAX_READ_BYTES), _memory_headroom(ATTR_MEMORY_HEADROOM):
                    return ds[sel]
            if ds.chunks is None and isinstance(sel, slice) and sel.step in (None, 1) and ds.ndim:
                return _read_rows(ds, *sel.indices(ds.shape[0])[:2])
            return ds[sel]
        except MemoryError:
            raise self._refused(
                f"{shown(ds.name, limit=200)}: declares text larger than memory allows (refused)"
            ) from None
        except OSError as e:
            raise self._refusal(ds.name) or self._read_error(ds, e) from None

    def _read_error(self, ds: h5py.Dataset, e: Exception, rows: str = "") -> RecordingCorrupted:
        msg = str(e)
        if ds.fletcher32 and ("filter" in msg or "Fletcher" in msg or "checksum" in msg):
            return RecordingCorrupted(self.path, ds.name, f"checksum mismatch{rows}")
        return RecordingCorrupted(self.path, ds.name, f"cannot be read{rows} ({_h5_reason(msg)})")

    def verify(self, ds: h5py.Dataset, max_bytes: int = VERIFY_BYTES) -> None:
        """Read all of ``ds`` a few chunks at a time (memory bounded), checking every checksum;
        a failure names the dataset and the samples of the first damaged chunk."""
        if ds.ndim == 0:
            self.read(ds)
            return
        step = _chunk_rows(ds)
        for start, stop in _row_blocks(ds, max_bytes):
            try:
                ds[start:stop]
            except OSError as e:
                refusal = self._refusal(ds.name)
                if refusal is not None:
                    raise refusal from None
                for first in range(start, stop, step):  # find the chunk at fault
                    last = min(stop, first + step)
                    try:
                        ds[first:last]
                    except OSError:
                        raise self._read_error(ds, e, f" in samples {first}-{last - 1}") from None
                raise self._read_error(ds, e) from None

    def problems(self, max_bytes: int = VERIFY_BYTES) -> list[Problem]:
        """Every damaged object: attributes, dataset shapes and every chunk of every dataset
        (read a few chunks at a time, so memory stays bounded whatever the file's size)."""
        out = [self.manifest_problem] if self.manifest_problem is not None else []
        names: list[str] = []

        def note(name: str) -> bool | None:
            names.append(name)
            return True if len(names) > MAX_OBJECTS else None  # True stops the walk

        try:
            self.file.visit(note)
        except (OSError, ValueError, RuntimeError) as e:
            refusal = self._refusal("/")
            if refusal is not None:
                raise refusal from None
            out.append(
                Problem("/", f"the group structure cannot be read ({shown(_h5_reason(str(e)), limit=200)})")
            )
        if len(names) > MAX_OBJECTS:
            raise self._refused(f"holds more than {MAX_OBJECTS:,} groups and datasets")
        seen = {"/"}
        self.datasets_checked = 0
        for name in ["/", *(f"/{n}" for n in names if n != MANIFEST)]:
            seen.add(name)
            out += self._object_problems(name, max_bytes)
        if self.manifest is not None:
            for name in sorted((set(self.manifest.attrs) | set(self.manifest.datasets)) - seen):
                out.append(Problem(name, "missing"))
        return out

    def _object_problems(self, name: str, max_bytes: int) -> list[Problem]:
        try:
            obj = self.group(name)
        except RecordingCorrupted as e:
            return [Problem(e.where, e.what)]
        _, out = self.checked_attrs(obj)
        if isinstance(obj, h5py.Dataset):
            self.datasets_checked += 1
            try:
                self.verify(obj, max_bytes)
            except RecordingCorrupted as e:
                out.append(Problem(e.where, e.what))
        return out


def _attr_storage(obj: h5py.HLObject, name: str) -> int:
    """Bytes an attribute stores in the file (0 for an empty one: h5py raises for those)."""
    try:
        return int(obj.attrs.get_id(name).get_storage_size())
    except (RuntimeError, OSError, ValueError):
        return 0


def _value_bytes(value: Any) -> int:
    """Bytes an attribute value holds (text and arrays of text counted by their characters)."""
    if isinstance(value, (str, bytes)):
        return len(value)
    a = np.asarray(value)
    if a.dtype.hasobject:
        return sum(len(v) if isinstance(v, (str, bytes)) else 8 for v in a.ravel().tolist())
    return int(a.nbytes)


def _read_rows(ds: h5py.Dataset, start: int, stop: int) -> np.ndarray:
    """Rows ``[start, stop)`` of an unchunked dataset, read a few MB at a time (HDF5 would read a
    contiguous selection in one piece, which the bounded reader refuses beyond MAX_READ_BYTES)."""
    out = np.empty((max(0, stop - start), *ds.shape[1:]), ds.dtype)
    for a, b in _row_blocks(ds, VERIFY_BYTES):
        lo, hi = max(a, start), min(b, stop)
        if lo < hi:
            ds.read_direct(out, np.s_[lo:hi], np.s_[lo - start : hi - start])
    return out


def _chunk_rows(ds: h5py.Dataset) -> int:
    """Rows per HDF5 chunk (or per 64 kB for an unchunked dataset)."""
    row_bytes = ds.dtype.itemsize * int(np.prod(ds.shape[1:], dtype=np.int64))
    return ds.chunks[0] if ds.chunks else max(1, (1 << 16) // max(row_bytes, 1))


def _row_blocks(ds: h5py.Dataset, max_bytes: int) -> Iterator[tuple[int, int]]:
    """Row ranges of ``ds`` covering whole chunks, each at most ``max_bytes`` (or one chunk)."""
    row_bytes = ds.dtype.itemsize * int(np.prod(ds.shape[1:], dtype=np.int64))
    rows = _chunk_rows(ds)
    per = max(1, max_bytes // max(row_bytes * rows, 1)) * rows
    for start in range(0, ds.shape[0], per):
        yield start, min(ds.shape[0], start + per)
