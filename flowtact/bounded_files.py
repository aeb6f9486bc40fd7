"""Reading files from others within bounds: regular files only, formats checked from their first
bytes, sizes declared in headers checked against a budget before anything is allocated.

A file given where flowtact expects a recording, a model or a replay may be hostile: a FIFO or a
device (opening it blocks, or reading never ends), a sparse file of a gigabyte, or a small archive
whose headers promise terabytes. The helpers here refuse those in one line naming the file
(:class:`FileRefused`, a ``ValueError``) before the reader allocates:

- :func:`regular_file` / :func:`open_regular`: the path is a regular file (``open_regular`` checks
  the file it opened, without blocking on a FIFO, so the check cannot be raced);
- :func:`check_hdf5_signature`: the HDF5 signature is where HDF5 looks for it (offset 0, 512,
  1024, ...), reading 8 bytes at each place, never the file;
- :func:`read_npz_bounded`: the arrays of an ``.npz`` file (numpy's ``savez``), each member's
  declared size (``ZipInfo.file_size``) and ``.npy`` header (dtype, shape) checked against the
  budget before it is read, object (pickled) arrays refused, the zip's central directory bounded
  before ``zipfile`` parses it. Memory stays below the budget plus a small constant.

Budgets: :data:`NPZ_BUDGET_BYTES` (default for all members' data together),
:data:`MAX_NPZ_MEMBERS`, :data:`MAX_NPY_HEADER_BYTES`; callers pass tighter budgets (a naive-Bayes
model is small).
"""

from __future__ import annotations

import math
import os
import stat
import struct
import zipfile
from typing import BinaryIO

import numpy as np

from flowtact.errors import FlowtactError
from flowtact.limits import format_bytes
from flowtact.safe_text import shown

__all__ = [
    "MAX_NPY_HEADER_BYTES",
    "MAX_NPZ_MEMBERS",
    "NPZ_BUDGET_BYTES",
    "FileRefused",
    "check_hdf5_signature",
    "has_hdf5_signature",
    "open_regular",
    "read_npz_bounded",
    "regular_file",
]

NPZ_BUDGET_BYTES = 256 << 20
"""Default most bytes of array data :func:`read_npz_bounded` reads from one file (all members)."""
MAX_NPZ_MEMBERS = 1024
"""Most members an ``.npz`` file may list (its central directory is bounded accordingly)."""
MAX_NPY_HEADER_BYTES = 10_000
"""Longest ``.npy`` header accepted (numpy's own default bound)."""
HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
"""The 8 bytes that start an HDF5 superblock (at offset 0, or 512 · 2^k after a user block)."""

_READ_BLOCK = 4 << 20
_EOCD = struct.Struct("<4s4H2LH")  # zip end of central directory record
_EOCD_MAX_COMMENT = 0xFFFF


class FileRefused(FlowtactError, ValueError):
    """A file flowtact will not read: not a regular file, not the expected format, or over a budget.

    ``str(e)`` is one line, ``PATH: reason``, with the path shown as data (control characters escaped).
    """

    def __init__(self, path: str | os.PathLike[str], reason: str) -> None:
        self.path, self.reason = str(path), reason
        super().__init__(f"{shown(self.path)}: {reason}")


def regular_file(path: str | os.PathLike[str]) -> os.stat_result:
    """``os.stat(path)`` after checking it is a regular file (a FIFO, device, socket or folder is
    refused with :class:`FileRefused`); a missing file raises ``FileNotFoundError`` as usual."""
    st = os.stat(path)
    if not stat.S_ISREG(st.st_mode):
        raise FileRefused(path, f"not a regular file ({_kind(st.st_mode)})")
    return st


def _kind(mode: int) -> str:
    for test, name in (
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
    is opened non-blocking (a FIFO with no writer does not hang) and checked with ``fstat``."""
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise FileRefused(path, f"not a regular file ({_kind(mode)})")
        os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def has_hdf5_signature(fh: BinaryIO, size: int) -> bool:
    """Whether the open file ``fh`` of ``size`` bytes holds the HDF5 signature where HDF5 looks
    (offset 0, 512, 1024, 2048, ...): at most log2(size) reads of 8 bytes."""
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
        if not has_hdf5_signature(fh, st.st_size):
            raise FileRefused(path, "not a readable HDF5 file (it has no HDF5 signature)")
    return st


# -- NPZ ------------------------------------------------------------------------------------------


def read_npz_bounded(
    path: str | os.PathLike[str],
    budget_bytes: int = NPZ_BUDGET_BYTES,
    *,
    names: set[str] | frozenset[str] | None = None,
    max_members: int = MAX_NPZ_MEMBERS,
) -> dict[str, np.ndarray]:
    """The arrays of an ``.npz`` file by name (``x.npy`` -> ``"x"``), or :class:`FileRefused`.

    Before reading a member its declared size and ``.npy`` header (dtype, shape) are checked: the
    data of the members read must fit ``budget_bytes`` together, the header must describe exactly
    the member's bytes, and object dtypes (pickles) are refused. ``names``: read only these members
    (others are listed but not read; missing ones are simply absent from the result). Regular files
    only; at most ``max_members`` members; only stored or deflated members (numpy writes nothing else).
    """
    with open_regular(path) as fh:
        size = os.fstat(fh.fileno()).st_size
        _check_central_directory(fh, size, path, max_members)
        try:
            with zipfile.ZipFile(fh) as zf:
                return _read_members(zf, path, budget_bytes, names, max_members)
        except zipfile.BadZipFile as e:
            raise FileRefused(path, f"not a readable NPZ file ({shown(e, limit=200)})") from None
        except (EOFError, OSError, ValueError, NotImplementedError) as e:
            if isinstance(e, FileRefused):
                raise
            raise FileRefused(path, f"not a readable NPZ file ({shown(e, limit=200)})") from None


def _check_central_directory(fh: BinaryIO, size: int, path: str | os.PathLike[str], max_members: int) -> None:
    """Refuse a zip whose end record promises more members, or a larger directory, than allowed,
    before :mod:`zipfile` reads the directory (it builds an object per member)."""
    tail_len = min(size, _EOCD.size + _EOCD_MAX_COMMENT)
    fh.seek(size - tail_len)
    tail = fh.read(tail_len)
    at = tail.rfind(b"PK\x05\x06")
    if at < 0 or len(tail) - at < _EOCD.size:
        raise FileRefused(path, "not a readable NPZ file (no zip directory at its end)")
    _, _, _, _, entries, cd_size, _, _ = _EOCD.unpack(tail[at : at + _EOCD.size])
    if entries > max_members or cd_size > max_members * (46 + 2 * 1024):  # 0xFFFF: zip64, far more
        raise FileRefused(
            path, f"NPZ file lists {entries} members in a {cd_size}-byte directory (at most {max_members})"
        )


def _read_members(
    zf: zipfile.ZipFile,
    path: str | os.PathLike[str],
    budget: int,
    names: set[str] | frozenset[str] | None,
    max_members: int,
) -> dict[str, np.ndarray]:
    infos = zf.infolist()
    if len(infos) > max_members:
        raise FileRefused(path, f"NPZ file has {len(infos)} members (at most {max_members})")
    seen = [i.filename for i in infos]
    if len(set(seen)) != len(seen):
        raise FileRefused(path, "NPZ file lists a member twice")
    out: dict[str, np.ndarray] = {}
    left = budget
    for info in infos:
        key = info.filename[:-4] if info.filename.endswith(".npy") else info.filename
        if names is not None and key not in names:
            continue
        where = f"member {shown(info.filename, limit=80)!s}"
        if not info.filename.endswith(".npy"):
            raise FileRefused(path, f"{where} is not an array (.npy)")
        if info.flag_bits & 0x1 or info.compress_type not in (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED):
            raise FileRefused(path, f"{where} is encrypted or compressed with an unsupported method")
        if info.file_size > left + MAX_NPY_HEADER_BYTES + 128:
            raise FileRefused(path, f"{where} declares {format_bytes(info.file_size)}: {_over(budget)}")
        arr = _read_npy(zf, info, path, where, left)
        left -= arr.nbytes
        out[key] = arr
    return out


def _over(budget: int) -> str:
    return f"over the {format_bytes(budget)} budget for this file's arrays"


def _read_npy(
    zf: zipfile.ZipFile, info: zipfile.ZipInfo, path: str | os.PathLike[str], where: str, left: int
) -> np.ndarray:
    """One member's array, its header checked against ``left`` bytes of budget before reading."""
    fmt = np.lib.format
    with zf.open(info) as fp:
        version = fmt.read_magic(fp)
        if version == (1, 0):
            shape, fortran, dtype = fmt.read_array_header_1_0(fp, max_header_size=MAX_NPY_HEADER_BYTES)
        elif version == (2, 0):
            shape, fortran, dtype = fmt.read_array_header_2_0(fp, max_header_size=MAX_NPY_HEADER_BYTES)
        else:
            raise FileRefused(path, f"{where}: .npy format version {version} is not supported")
        if dtype.hasobject:
            raise FileRefused(path, f"{where} holds Python objects (a pickle): refused")
        if len(shape) > 32 or any(not isinstance(n, int) or n < 0 for n in shape):
            raise FileRefused(path, f"{where} has an invalid shape {shape}")
        count = math.prod(shape)
        nbytes = count * dtype.itemsize
        if nbytes > left or count > left:
            raise FileRefused(
                path, f"{where} declares shape {shape} of {dtype} ({format_bytes(nbytes)}): {_over(left)}"
            )
        if nbytes != info.file_size - fp.tell():
            raise FileRefused(
                path,
                f"{where} declares shape {shape} of {dtype} but holds {info.file_size - fp.tell()} bytes of data",
            )
        arr = np.empty(count, dtype)
        if nbytes:
            raw = memoryview(arr.reshape(-1).view(np.uint8))
            done = 0
            while done < nbytes:
                got = fp.readinto(raw[done : done + _READ_BLOCK])
                if not got:
                    raise FileRefused(path, f"{where} is cut short")
                done += got
            fp.read(1)  # at the end: zipfile checks the CRC
    return arr.reshape(shape[::-1]).T if fortran else arr.reshape(shape)
