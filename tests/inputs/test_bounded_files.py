"""The shared bounded readers: regular files only, HDF5 signature from a few bytes, NPZ members
checked (declared size, .npy header, no pickles) before anything is allocated."""

import os
import struct
import tracemalloc
import zipfile

import numpy as np
import pytest

from flowtact.errors import FileRefused
from flowtact.inputs.bounded_files import (
    check_hdf5_signature,
    open_npz,
    open_regular,
    read_npz_bounded,
    regular_file,
)


def _npz_with_header(path, shape, data=b"", descr="<f8", compress=zipfile.ZIP_DEFLATED):
    with zipfile.ZipFile(path, "w", compress) as z, z.open("x.npy", "w", force_zip64=True) as f:
        np.lib.format.write_array_header_1_0(f, {"descr": descr, "fortran_order": False, "shape": shape})
        f.write(data)
    return path


def test_arrays_round_trip_with_fortran_order_and_compression(tmp_path):
    a, b = np.arange(12.0).reshape(3, 4), np.asfortranarray(np.arange(6, dtype="i2").reshape(2, 3))
    np.savez(tmp_path / "m.npz", a=a, b=b, s=np.array("text"))
    np.savez_compressed(tmp_path / "c.npz", a=a)
    got = read_npz_bounded(tmp_path / "m.npz")
    assert np.array_equal(got["a"], a) and np.array_equal(got["b"], b) and got["s"] == "text"
    assert np.array_equal(read_npz_bounded(tmp_path / "c.npz")["a"], a)
    assert set(read_npz_bounded(tmp_path / "m.npz", names={"a"})) == {"a"}


def test_a_zip_bomb_is_refused_from_its_declared_size_before_reading(tmp_path):
    path = tmp_path / "bomb.npz"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z, z.open("x.npy", "w", force_zip64=True) as f:
        np.lib.format.write_array_header_1_0(f, {"descr": "<f8", "fortran_order": False, "shape": (1 << 25,)})
        for _ in range(256):
            f.write(bytes(1 << 20))  # 256 MiB of zeros: a file of about 250 kB
    tracemalloc.start()
    try:
        with pytest.raises(FileRefused, match=r"member x.npy declares 256.0 MiB: over the 64.0 MiB budget"):
            read_npz_bounded(path, 64 << 20)
        assert tracemalloc.get_traced_memory()[1] < 8 << 20
    finally:
        tracemalloc.stop()


def test_a_header_that_promises_more_than_the_member_holds_is_refused(tmp_path):
    path = _npz_with_header(tmp_path / "lie.npz", (1 << 40,), bytes(80))
    with pytest.raises(
        FileRefused, match=r"declares shape \(1099511627776,\) of float64 \(8.0 TiB\) but holds 80"
    ):
        read_npz_bounded(path)
    path = _npz_with_header(tmp_path / "short.npz", (100,), bytes(80))
    with pytest.raises(FileRefused, match=r"declares shape \(100,\) of float64 \(800 B\) but holds 80 bytes"):
        read_npz_bounded(path)


def test_pickles_and_foreign_members_are_refused(tmp_path):
    np.savez(tmp_path / "o.npz", o=np.array([{"a": 1}], dtype=object))
    with pytest.raises(FileRefused, match=r"member o\.npy holds Python objects"):
        read_npz_bounded(tmp_path / "o.npz")
    with zipfile.ZipFile(tmp_path / "t.npz", "w") as z:
        z.writestr("notes.txt", "hi")
    with pytest.raises(FileRefused, match=r"member notes\.txt is not an array"):
        read_npz_bounded(tmp_path / "t.npz")
    (tmp_path / "plain.npz").write_bytes(b"just text")
    with pytest.raises(FileRefused, match=r"plain\.npz: not a readable NPZ file"):
        read_npz_bounded(tmp_path / "plain.npz")


def test_too_many_members_are_refused_before_zipfile_lists_them(tmp_path):
    with zipfile.ZipFile(tmp_path / "many.npz", "w") as z:
        for i in range(40):
            z.writestr(f"{i}.npy", b"")
    with pytest.raises(FileRefused, match=r"lists 40 members .*\(at most 16\)"):
        read_npz_bounded(tmp_path / "many.npz", max_members=16)


def test_only_regular_files_and_a_fifo_does_not_block(tmp_path):
    fifo = tmp_path / "m.fifo"
    os.mkfifo(fifo)  # nobody writes: a blocking open would hang here
    for path, kind in ((fifo, "a FIFO"), (tmp_path, "a folder"), ("/dev/zero", "a character device")):
        with pytest.raises(FileRefused, match=f"not a regular file \\({kind}\\)"):
            open_regular(path) if path != tmp_path else regular_file(path)
    with pytest.raises(FileRefused, match=r"m\.fifo: not a regular file"):
        read_npz_bounded(fifo)


def test_the_hdf5_signature_is_checked_from_a_few_bytes(tmp_path):
    sparse = tmp_path / "big.h5"
    with open(sparse, "wb") as f:
        f.truncate(1 << 40)  # a terabyte of nothing (sparse): only a few bytes may be read
    with pytest.raises(FileRefused, match="it has no HDF5 signature"):
        check_hdf5_signature(sparse)
    (tmp_path / "e.h5").write_bytes(b"")
    with pytest.raises(FileRefused, match="it is empty"):
        check_hdf5_signature(tmp_path / "e.h5")
    (tmp_path / "ub.h5").write_bytes(b"\0" * 512 + b"\x89HDF\r\n\x1a\n" + b"\0" * 100)
    assert check_hdf5_signature(tmp_path / "ub.h5").st_size == 620  # after a 512-byte user block


def test_an_archive_is_inspected_header_by_header_then_read_within_a_budget(tmp_path):
    big = np.arange(1 << 20, dtype="<f8")  # 8 MiB
    np.savez(tmp_path / "two.npz", t=np.arange(3.0), data=big.reshape(-1, 4))
    tracemalloc.start()
    try:
        with open_npz(tmp_path / "two.npz") as npz:
            assert npz.names == ("data", "t") and npz.others == ()
            head = npz.header("data")  # the header alone: no data read
            assert (head.shape, head.dtype, head.nbytes) == ((1 << 18, 4), np.dtype("<f8"), 8 << 20)
            assert tracemalloc.get_traced_memory()[1] < 1 << 20
            with pytest.raises(
                FileRefused, match=r"member data.npy declares 8.0 MiB: over the 4.0 MiB budget"
            ):
                npz.read("data", 4 << 20)
            assert np.array_equal(npz.read("data", 8 << 20), big.reshape(-1, 4))
    finally:
        tracemalloc.stop()


def _forge_zip64_end(path, entries: int) -> None:
    """Make the zip's classic end record claim one member while a zip64 end record, which zipfile
    reads instead, tells the truth: a check of the classic record alone lets zipfile list them all."""
    raw = path.read_bytes()
    end = raw[-22:]
    _, _, _, _, _, cd_size, cd_offset, _ = struct.unpack("<4s4H2LH", end)
    at = len(raw) - 22
    record = struct.pack("<4sQ2H2L4Q", b"PK\x06\x06", 44, 45, 45, 0, 0, entries, entries, cd_size, cd_offset)
    locator = struct.pack("<4sLQL", b"PK\x06\x07", 0, at, 1)
    classic = struct.pack("<4s4H2LH", b"PK\x05\x06", 0, 0, 1, 1, 50, cd_offset, 0)
    path.write_bytes(raw[:at] + record + locator + classic)


def test_the_zip64_end_record_zipfile_reads_is_checked_too(tmp_path):
    path = tmp_path / "z64.npz"
    with zipfile.ZipFile(path, "w") as z:
        for i in range(400):
            z.writestr(f"{i}.npy", b"")
    _forge_zip64_end(path, 400)
    with pytest.raises(FileRefused, match=r"lists 400 members in a \d+-byte directory \(at most 16\)"):
        read_npz_bounded(path, max_members=16)


def test_a_npy_header_length_is_checked_before_the_header_is_read(tmp_path):
    path = tmp_path / "longhead.npz"
    declared = 48 << 20  # a version 2.0 header may declare up to 4 GiB; numpy reads it all first
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z, z.open("x.npy", "w") as f:
        f.write(b"\x93NUMPY\x02\x00" + struct.pack("<I", declared))
        for _ in range(48):
            f.write(b" " * (1 << 20))
    tracemalloc.start()
    try:
        with pytest.raises(
            FileRefused, match=f"member x.npy has a {declared}-byte header; a .npy header is at most"
        ):
            read_npz_bounded(path)
        assert tracemalloc.get_traced_memory()[1] < 4 << 20
    finally:
        tracemalloc.stop()


def test_a_damaged_deflate_stream_is_a_refusal_not_a_traceback(tmp_path):
    path = tmp_path / "bad.npz"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as z:
        z.writestr("x.npy", b"\xff" * 200)  # as deflate: a block of the reserved type 3
    raw = bytearray(path.read_bytes())
    for sig, at in ((b"PK\x03\x04", 8), (b"PK\x01\x02", 10)):  # mark it deflated in both headers
        pos = raw.find(sig) + at
        raw[pos : pos + 2] = struct.pack("<H", zipfile.ZIP_DEFLATED)
    path.write_bytes(bytes(raw))
    with pytest.raises(FileRefused, match=r"member x.npy cannot be read \(Error -3 while decompressing"):
        read_npz_bounded(path)
