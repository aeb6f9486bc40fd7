"""The shared bounded readers: regular files only, HDF5 signature from a few bytes, NPZ members
checked (declared size, .npy header, no pickles) before anything is allocated."""

import os
import tracemalloc
import zipfile

import numpy as np
import pytest

from flowtact.bounded_files import (
    FileRefused,
    check_hdf5_signature,
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
