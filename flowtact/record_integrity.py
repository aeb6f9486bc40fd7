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

import hashlib
import json
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from flowtact.errors import FlowtactError

__all__ = [
    "MANIFEST",
    "CheckedFile",
    "Manifest",
    "NotARecording",
    "Problem",
    "RecordingCorrupted",
    "RecordingError",
    "attr_digest",
]

#: Name of the root dataset holding the manifest (UTF-8 JSON bytes).
MANIFEST = "integrity"
MANIFEST_VERSION = 1
#: Most bytes held in memory while verifying a dataset (whole chunks, several at a time).
VERIFY_BYTES = 8 << 20
_HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
_CORRUPT = "(the file is corrupted)"


class RecordingError(FlowtactError, OSError):
    """A recording that cannot be read: missing, not HDF5, truncated, or damaged."""


class RecordingCorrupted(RecordingError):
    """Part of a recording does not match its checksum or cannot be read; names file and object."""

    def __init__(self, path: str | Path, where: str, what: str = "checksum mismatch") -> None:
        self.path, self.where, self.what = str(path), where, what
        super().__init__(f"{path}: {where}: {what} {_CORRUPT}")


class NotARecording(FlowtactError, ValueError):
    """An HDF5 file that is not a flowtact recording (no ``/streams`` group)."""


@dataclass(frozen=True)
class Problem:
    """One damaged object found by :meth:`CheckedFile.problems`."""

    where: str  # "/streams/force.f/data", or "/streams/force.f" for its attributes
    what: str  # "checksum mismatch", "attribute 'units' does not match its checksum", ...

    def __str__(self) -> str:
        return f"{self.where}: {self.what}"


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


def _open_h5(path: Path) -> h5py.File:
    """Open ``path`` read-only, refusing a missing, non-HDF5 or truncated file in one line."""
    if not path.exists():
        raise FileNotFoundError(f"recording not found: {path}")
    if path.is_dir():
        raise RecordingError(f"{path}: is a directory, not a recording")
    try:
        return h5py.File(path, "r")
    except OSError as e:
        msg = str(e)
        size = path.stat().st_size
        if "truncated file" in msg:
            m = re.search(r"stored_eof = (\d+)", msg)
            expected = f" of the {int(m.group(1)):,} its header promises" if m else ""
            raise RecordingError(
                f"{path}: truncated: {size:,} bytes{expected} (cut short by a copy or a full disk?)"
            ) from None
        if "signature not found" in msg:
            head = path.read_bytes()[:8] if size else b""
            why = "it is empty" if size == 0 else "it has no HDF5 signature"
            if head == _HDF5_SIGNATURE:
                why = "its header is damaged"
            raise RecordingError(f"{path}: not a readable HDF5 file ({why})") from None
        raise RecordingError(f"{path}: cannot be opened as HDF5 ({_h5_reason(msg)})") from None


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
        self.file = _open_h5(self.path)
        self.manifest: Manifest | None = None
        self.manifest_problem: Problem | None = None
        self.datasets_checked = 0
        try:
            self._load_manifest()
        except RecordingCorrupted as e:
            if strict:
                self.file.close()
                raise
            self.manifest_problem = Problem(e.where, e.what)
        except BaseException:
            self.file.close()
            raise

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
        raw = self.read(self.group(f"/{MANIFEST}"))
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
            raise RecordingCorrupted(self.path, name, f"cannot be read ({_h5_reason(str(e))})") from None
        if isinstance(obj, h5py.Dataset):
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
            raw = _raw_attrs(obj)
        except (OSError, ValueError, KeyError, RuntimeError, UnicodeError) as e:
            return {}, [Problem(obj.name, f"attributes cannot be read ({_h5_reason(str(e))})")]
        good = {k: _text(v) for k, v in raw.items()}
        if self.manifest is None:
            return good, []
        want = self.manifest.attrs.get(obj.name)
        if want is None:
            return {}, [Problem(obj.name, "not listed in the checksum manifest")]
        problems = []
        for name in sorted(set(want) | set(raw)):
            if name not in raw:
                problems.append(Problem(obj.name, f"attribute '{name}' is missing"))
            elif name not in want or attr_digest(raw[name]) != want[name]:
                what = "is not in the manifest" if name not in want else "does not match its checksum"
                problems.append(Problem(obj.name, f"attribute '{name}' {what}"))
                good.pop(name)
        return good, problems

    # -- data ------------------------------------------------------------------------------
    def read(self, ds: h5py.Dataset, sel: Any = ()) -> np.ndarray:
        """``ds[sel]``, each chunk's checksum verified by HDF5 on the way."""
        try:
            return ds[sel]
        except OSError as e:
            raise self._read_error(ds, e) from None

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
        try:
            self.file.visit(names.append)
        except (OSError, ValueError, RuntimeError) as e:
            out.append(Problem("/", f"the group structure cannot be read ({_h5_reason(str(e))})"))
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
