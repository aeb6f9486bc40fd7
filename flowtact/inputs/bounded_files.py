"""Reading files from others within bounds: regular files only, formats checked from their first
bytes, sizes declared in headers checked against a budget before anything is allocated.

A file given where flowtact expects a recording, a model or a replay may be hostile: a FIFO or a
device (opening it blocks, or reading never ends), a sparse file of a gigabyte, or a small archive
whose headers promise terabytes. The helpers here refuse those in one line naming the file
(:class:`FileRefused`, a ``ValueError``; ``.reason`` is the message without the file, for readers
that locate it themselves) before the reader allocates:

- :func:`regular_file` / :func:`open_regular`: the path is a regular file (``open_regular`` checks
  the file it opened, without blocking on a FIFO, so the check cannot be raced);
- :func:`has_hdf5_signature` / :func:`check_hdf5_signature`: the HDF5 signature is where HDF5
  looks for it (offset 0, 512, 1024, ...), reading 8 bytes at each place, never the file;
- :func:`open_npz`: an ``.npz`` file (numpy's ``savez``) as an :class:`NpzArchive`, its zip
  directory bounded before :mod:`zipfile` parses it; each member's ``.npy`` header (dtype, shape)
  is read alone and checked against the member's declared size (:meth:`NpzArchive.header`), and
  its data read only within a budget (:meth:`NpzArchive.read`): a reader can inspect every array
  when it validates and read the data later. Object (pickled) arrays are refused; only stored or
  deflated members are read (numpy writes nothing else);
- :func:`read_npz_bounded`: every array of an ``.npz`` within one budget, over :func:`open_npz`.

Memory stays below the budget plus a small constant. Budgets: :data:`NPZ_BUDGET_BYTES` (default
for all members' data together), :data:`MAX_NPZ_MEMBERS`, :data:`NPZ_DIRECTORY_BYTES_PER_MEMBER`,
:data:`MAX_NPY_HEADER_BYTES`; callers pass tighter budgets (a naive-Bayes model is small) or wider
counts (a replayed file lists up to 10 000 arrays).
"""

from __future__ import annotations

import io
import math
import os
import stat
import struct
import zipfile
import zlib
from dataclasses import dataclass
from types import TracebackType
from typing import BinaryIO

import numpy as np

from flowtact.errors import FileRefused
from flowtact.inputs.limits import format_bytes
from flowtact.inputs.safe_text import shown

__all__ = [
    "HDF5_SIGNATURE",
    "MAX_NPY_HEADER_BYTES",
    "MAX_NPZ_MEMBERS",
    "NPZ_BUDGET_BYTES",
    "NPZ_DIRECTORY_BYTES_PER_MEMBER",
    "NpyHeader",
    "NpzArchive",
    "check_hdf5_signature",
    "file_kind",
    "has_hdf5_signature",
    "open_npz",
    "open_regular",
    "read_npz_bounded",
    "refusal",
    "regular_file",
]

NPZ_BUDGET_BYTES = 256 << 20
"""Default most bytes of array data :func:`read_npz_bounded` reads from one file (all members)."""
MAX_NPZ_MEMBERS = 1024
"""Default most members an ``.npz`` file may list (its central directory is bounded accordingly)."""
NPZ_DIRECTORY_BYTES_PER_MEMBER = 512
"""Most bytes of zip directory allowed per member (a 46-byte record, the name, extra fields): a
directory larger than ``max_members`` times this is refused before :mod:`zipfile` parses it, since
zipfile builds an object for every record the directory holds, whatever count it declares."""
MAX_NPY_HEADER_BYTES = 10_000
"""Longest ``.npy`` header accepted (numpy's own default bound), checked before it is read."""
HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
"""The 8 bytes that start an HDF5 superblock (at offset 0, or 512 · 2^k after a user block)."""

_READ_BLOCK = 4 << 20  # bytes inflated at a time into an array
_EOCD = struct.Struct("<4s4H2LH")  # zip end of central directory record
_EOCD_SIGNATURE = b"PK\x05\x06"
_EOCD64 = struct.Struct("<4sQ2H2L4Q")  # zip64 end of central directory record
_EOCD64_LOCATOR = struct.Struct("<4sLQL")
_EOCD_MAX_COMMENT = 0xFFFF
#: What zipfile, or a damaged member, may raise while an archive is listed or a member inflated.
_ZIP_ERRORS = (zipfile.BadZipFile, zlib.error, EOFError, OSError, ValueError, NotImplementedError)


def refusal(path: str | os.PathLike[str], error: OSError) -> FileRefused:
    """``error``, met opening ``path``, as a :class:`FileRefused` (``no such file``, ``cannot be
    read (Permission denied)``): for readers that report every problem with a file alike."""
    if isinstance(error, FileNotFoundError):
        return FileRefused(path, "no such file")
    return FileRefused(path, f"cannot be read ({shown(error.strerror or error, limit=200)})")


def regular_file(path: str | os.PathLike[str]) -> os.stat_result:
    """``os.stat(path)`` after checking it is a regular file (a FIFO, device, socket or folder is
    refused with :class:`FileRefused`); a missing file raises ``FileNotFoundError`` as usual."""
    st = os.stat(path)
    if not stat.S_ISREG(st.st_mode):
        raise FileRefused(path, f"not a regular file ({file_kind(st.st_mode)})")
    return st


def file_kind(mode: int) -> str:
    """What an ``st_mode`` is, in words for a message ("a regular file", "a FIFO", ...)."""
    for test, name in (
        (stat.S_ISREG, "a regular file"),
        (stat.S_ISDIR, "a folder"),
        (stat.S_ISFIFO, "a FIFO"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
    ):
        if test(mode):
            return name
    return "not a file"


def open_regular(path: str | os.PathLike[str]) -> BinaryIO:
    """``open(path, "rb")`` of a regular file, refusing anything else without blocking: the file
    is opened non-blocking (a FIFO with no writer does not hang) and checked with ``fstat``, so a
    file swapped in between cannot slip through. A missing file raises ``FileNotFoundError``."""
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise FileRefused(path, f"not a regular file ({file_kind(mode)})")
        os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def has_hdf5_signature(fh: BinaryIO) -> bool:
    """Whether the open file ``fh`` holds the HDF5 signature where HDF5 looks (offset 0, 512,
    1024, 2048, ...): at most log2(size) reads of 8 bytes, never the whole file."""
    size = os.fstat(fh.fileno()).st_size
    offset = 0
    while offset + len(HDF5_SIGNATURE) <= size:
        fh.seek(offset)
        if fh.read(len(HDF5_SIGNATURE)) == HDF5_SIGNATURE:
            return True
        offset = 512 if offset == 0 else 2 * offset
    return False


def check_hdf5_signature(path: str | os.PathLike[str]) -> os.stat_result:
    """Refuse (:class:`FileRefused`) a path that is not a regular file, is empty, or has no HDF5
    signature, reading a few bytes only; returns its ``stat``."""
    with open_regular(path) as fh:
        st = os.fstat(fh.fileno())
        if st.st_size == 0:
            raise FileRefused(path, "not a readable HDF5 file (it is empty)")
        if not has_hdf5_signature(fh):
            raise FileRefused(path, "not a readable HDF5 file (it has no HDF5 signature)")
    return st


# -- NPZ ------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class NpyHeader:
    """One array of an ``.npz`` as its ``.npy`` header declares it, checked against the member's
    declared size: ``offset`` bytes of magic and header, then exactly ``nbytes`` of data."""

    name: str
    shape: tuple[int, ...]
    dtype: np.dtype
    fortran: bool
    offset: int
    info: zipfile.ZipInfo

    @property
    def nbytes(self) -> int:
        return math.prod(self.shape) * self.dtype.itemsize


class NpzArchive:
    """An open ``.npz`` (from :func:`open_npz`): its arrays listed, each header checked on its own
    (:meth:`header`) and its data read within a budget (:meth:`read`), member by member."""

    def __init__(self, path: str | os.PathLike[str], fh: BinaryIO, zf: zipfile.ZipFile) -> None:
        self.path = str(path)
        self._fh, self._zf = fh, zf
        infos = zf.infolist()
        self._arrays = {i.filename[:-4]: i for i in infos if i.filename.endswith(".npy")}
        self.names: tuple[str, ...] = tuple(sorted(self._arrays))
        """The arrays (member ``x.npy`` -> ``"x"``), sorted."""
        self.others: tuple[str, ...] = tuple(i.filename for i in infos if not i.filename.endswith(".npy"))
        """Members that are not arrays (numpy writes none)."""
        self._headers: dict[str, NpyHeader] = {}

    def header(self, name: str) -> NpyHeader:
        """Array ``name``'s header, read alone (at most :data:`MAX_NPY_HEADER_BYTES`) and checked:
        stored or deflated, numbers or text (no Python objects), exactly as many bytes of data as
        the header declares (a zip never inflates past its declared size, so that bounds a read)."""
        if name not in self._headers:
            self._headers[name] = self._read_header(name)
        return self._headers[name]

    def read(self, name: str, budget_bytes: int) -> np.ndarray:
        """Array ``name``, refused unless its declared size fits ``budget_bytes``; inflated a block
        at a time into one array of that size (the CRC checked at the end)."""
        info = self._info(name)
        where = _member(info)
        if info.file_size > budget_bytes + MAX_NPY_HEADER_BYTES + 128:  # before parsing anything
            raise self._refused(f"{where} declares {format_bytes(info.file_size)}: {_over(budget_bytes)}")
        head = self.header(name)
        if head.nbytes > budget_bytes:
            raise self._refused(
                f"{where} declares shape {head.shape} of {head.dtype} ({format_bytes(head.nbytes)}): "
                + _over(budget_bytes)
            )
        out = np.empty(head.nbytes, np.uint8)
        done = 0
        try:
            with self._zf.open(info) as fp:
                fp.read(head.offset)
                while done < head.nbytes and (got := fp.readinto(memoryview(out)[done : done + _READ_BLOCK])):
                    done += got
                fp.read(1)  # at the end: zipfile checks the CRC
        except _ZIP_ERRORS as e:
            raise self._refused(f"{where} cannot be read ({shown(e, limit=200)})") from None
        if done != head.nbytes:
            raise self._refused(f"{where} ends after {done} of its {head.nbytes} bytes of data")
        data = out.view(head.dtype)
        return data.reshape(head.shape[::-1]).T if head.fortran else data.reshape(head.shape)

    def close(self) -> None:
        self._zf.close()
        self._fh.close()

    def __enter__(self) -> NpzArchive:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def _info(self, name: str) -> zipfile.ZipInfo:
        info = self._arrays.get(name)
        if info is None:
            raise self._refused(f"has no array {shown(name, limit=80)!r}")
        return info

    def _refused(self, reason: str) -> FileRefused:
        return FileRefused(self.path, reason)

    def _read_header(self, name: str) -> NpyHeader:
        info = self._info(name)
        where = _member(info)
        if info.flag_bits & 0x1 or info.compress_type not in (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED):
            raise self._refused(
                f"{where} is encrypted or compressed other than numpy writes (stored or deflated)"
            )
        try:
            with self._zf.open(info) as fp:
                prefix = fp.read(12)
                major = prefix[6] if len(prefix) >= 10 and prefix[:6] == b"\x93NUMPY" else None
                if major not in (1, 2):
                    raise self._refused(f"{where} is not a .npy array of a readable version (1.0 or 2.0)")
                size_len = 2 if major == 1 else 4
                header_len = int.from_bytes(prefix[8 : 8 + size_len], "little")
                if header_len > MAX_NPY_HEADER_BYTES:
                    raise self._refused(
                        f"{where} has a {header_len}-byte header; a .npy header is at most {MAX_NPY_HEADER_BYTES}"
                    )
                prefix, header = prefix[: 8 + size_len], prefix[8 + size_len :]
                header += fp.read(header_len - len(header))
        except _ZIP_ERRORS as e:
            if isinstance(e, FileRefused):
                raise
            raise self._refused(f"{where} cannot be read ({shown(e, limit=200)})") from None
        shape, fortran, dtype = self._parse(where, prefix + header, major)
        head = NpyHeader(name, shape, dtype, fortran, len(prefix) + len(header), info)
        held = info.file_size - head.offset
        if head.nbytes != held:
            raise self._refused(
                f"{where} declares shape {shape} of {dtype} ({format_bytes(head.nbytes)}) "
                f"but holds {held} bytes of data"
            )
        return head

    def _parse(self, where: str, raw: bytes, major: int) -> tuple[tuple[int, ...], bool, np.dtype]:
        """numpy's own header parser, over the bounded bytes read; the dtype and shape checked."""
        fmt = np.lib.format
        buf = io.BytesIO(raw)
        try:
            fmt.read_magic(buf)
            read = fmt.read_array_header_1_0 if major == 1 else fmt.read_array_header_2_0
            shape, fortran, dtype = read(buf, max_header_size=MAX_NPY_HEADER_BYTES)
        except (ValueError, SyntaxError, TypeError, RecursionError, MemoryError) as e:
            raise self._refused(f"{where} has a damaged header ({shown(e, limit=200)})") from None
        dtype = np.dtype(dtype)
        if dtype.hasobject:
            raise self._refused(f"{where} holds Python objects (a pickle): refused")
        if dtype.itemsize == 0 or dtype.subdtype is not None or dtype.names is not None:
            raise self._refused(
                f"{where} is of dtype {shown(dtype, limit=80)}; only plain numbers or text are read"
            )
        if len(shape) > 32 or any(not isinstance(n, int) or n < 0 for n in shape):
            raise self._refused(f"{where} has an invalid shape {shown(shape, limit=80)}")
        return tuple(int(n) for n in shape), bool(fortran), dtype


def _member(info: zipfile.ZipInfo) -> str:
    return f"member {shown(info.filename, limit=80)}"


def _over(budget: int) -> str:
    return f"over the {format_bytes(budget)} budget for this file's arrays"


def open_npz(path: str | os.PathLike[str], max_members: int = MAX_NPZ_MEMBERS) -> NpzArchive:
    """``path`` as an :class:`NpzArchive` (use it in a ``with``), or :class:`FileRefused`: a
    regular file whose zip directory lists at most ``max_members`` members, each once, in at most
    ``max_members`` × :data:`NPZ_DIRECTORY_BYTES_PER_MEMBER` bytes (checked from the end records
    zipfile itself reads, before it lists the members). A missing file raises ``FileNotFoundError``."""
    fh = open_regular(path)
    try:
        _check_directory(fh, path, max_members)
        try:
            zf = zipfile.ZipFile(fh)
        except _ZIP_ERRORS as e:
            raise FileRefused(path, f"not a readable NPZ file ({shown(e, limit=200)})") from None
        seen = [i.filename for i in zf.infolist()]
        if len(seen) > max_members:
            raise FileRefused(path, f"NPZ file has {len(seen)} members (at most {max_members})")
        if len(set(seen)) != len(seen):
            raise FileRefused(path, "NPZ file lists a member twice")
        return NpzArchive(path, fh, zf)
    except BaseException:
        fh.close()
        raise


def _check_directory(fh: BinaryIO, path: str | os.PathLike[str], max_members: int) -> None:
    """Refuse a zip whose end records (the zip64 one too, where zipfile looks for it) declare more
    members, or a larger directory, than allowed: zipfile would parse every record in it."""
    size = os.fstat(fh.fileno()).st_size
    tail_len = min(size, _EOCD.size + _EOCD_MAX_COMMENT)
    fh.seek(size - tail_len)
    tail = fh.read(tail_len)
    if tail[-_EOCD.size : -_EOCD.size + 4] == _EOCD_SIGNATURE and tail[-2:] == b"\0\0":
        at = len(tail) - _EOCD.size  # no comment: where zipfile looks first
    else:
        at = tail.rfind(_EOCD_SIGNATURE)
    if at < 0 or len(tail) - at < _EOCD.size:
        raise FileRefused(path, "not a readable NPZ file (no zip directory at its end)")
    _, _, _, _, entries, cd_size, _, _ = _EOCD.unpack(tail[at : at + _EOCD.size])
    end = size - tail_len + at  # the end record's offset in the file
    locator_at = end - _EOCD64_LOCATOR.size
    if locator_at >= _EOCD64.size:  # zipfile takes the zip64 record just before the locator
        fh.seek(locator_at - _EOCD64.size)
        raw = fh.read(_EOCD64.size + _EOCD64_LOCATOR.size)
        if raw[_EOCD64.size : _EOCD64.size + 4] == b"PK\x06\x07" and raw[:4] == b"PK\x06\x06":
            record = _EOCD64.unpack(raw[: _EOCD64.size])
            entries, cd_size = max(entries, record[6], record[7]), max(cd_size, record[8])
    if entries > max_members or cd_size > max_members * NPZ_DIRECTORY_BYTES_PER_MEMBER:
        raise FileRefused(
            path, f"NPZ file lists {entries} members in a {cd_size}-byte directory (at most {max_members})"
        )


def read_npz_bounded(
    path: str | os.PathLike[str],
    budget_bytes: int = NPZ_BUDGET_BYTES,
    *,
    names: set[str] | frozenset[str] | None = None,
    max_members: int = MAX_NPZ_MEMBERS,
) -> dict[str, np.ndarray]:
    """The arrays of an ``.npz`` file by name (``x.npy`` -> ``"x"``), or :class:`FileRefused`.

    The data of the arrays read must fit ``budget_bytes`` together, each checked from its declared
    size and header before it is read (:meth:`NpzArchive.read`). ``names``: read only these arrays
    (others are listed but not read; missing ones are simply absent from the result). A member that
    is not an array is refused when it would be read.
    """
    with open_npz(path, max_members) as npz:
        foreign = [m for m in npz.others if names is None or m in names]
        if foreign:
            raise FileRefused(path, f"member {shown(foreign[0], limit=80)} is not an array (.npy)")
        out: dict[str, np.ndarray] = {}
        left = budget_bytes
        for name in npz.names:
            if names is None or name in names:
                out[name] = npz.read(name, left)
                left -= out[name].nbytes
        return out
