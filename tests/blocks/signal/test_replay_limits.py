"""Replay readers are bounded before they allocate: every size, count and number a replayed file
declares is checked against blocks/signal/replay_limits.py, and a refusal names the file (and the
line of a .csv). The files too large to keep are in bench/hostile_cases.py (``replay_*``), measured
in a child by tests/inputs/test_hostile_input.py; these are the small, exact cases."""

from __future__ import annotations

import io
import os
import tracemalloc
import zipfile

import h5py
import numpy as np
import pytest

import flowtact.blocks.signal.csv_log as csv_log
import flowtact.blocks.signal.replay as replay
from flowtact.blocks.signal.csv_log import CsvError, read_csv_log
from flowtact.blocks.signal.replay import Replay
from flowtact.blocks.signal.replay_limits import MAX_COLUMNS, listing
from flowtact.blocks.signal.replay_ports import stand_in_class
from flowtact.chunk import Chunk, StreamSpec
from flowtact.errors import ConfigError, FileRefused, SpecError
from flowtact.inputs.bounded_files import HDF5_SIGNATURE, has_hdf5_signature, open_regular
from flowtact.recording.hdf5 import Recorder


def _npy(array: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array(buf, array, allow_pickle=True)
    return buf.getvalue()


def _npz(path, members: dict[str, bytes], compression: int = zipfile.ZIP_DEFLATED) -> str:
    with zipfile.ZipFile(path, "w", compression) as z:
        for name, data in members.items():
            z.writestr(f"{name}.npy", data)
    return str(path)


def _refusal(block: Replay) -> SpecError:
    with pytest.raises(SpecError) as e:
        block.bind({})
    return e.value


# -- .npz ---------------------------------------------------------------------------------------


def test_a_header_declaring_more_than_the_member_holds_is_refused_before_allocating(tmp_path):
    buf = io.BytesIO()  # a header promising 2**40 samples, then 2 samples of data
    np.lib.format.write_array_header_1_0(buf, {"descr": "<f8", "fortran_order": False, "shape": (1 << 40,)})
    lie = buf.getvalue() + bytes(16)
    path = _npz(tmp_path / "lie.npz", {"data": _npy(np.zeros(2)), "t": lie})
    tracemalloc.start()
    try:
        e = _refusal(Replay(path=path))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert "member t.npy declares shape (1099511627776,) of float64 (8.0 TiB) but holds 16 bytes" in str(e)
    assert e.where == (path, 1, 1)
    assert peak < 20 << 20


def test_arrays_over_the_budget_are_refused_from_their_headers(tmp_path, monkeypatch):
    path = _npz(tmp_path / "big.npz", {"data": _npy(np.zeros((100, 2))), "t": _npy(np.arange(100.0))})
    Replay(path=path).bind({})  # within the budget: played
    monkeypatch.setattr(replay, "REPLAY_BUDGET_BYTES", 2000)  # data 1600 + t 800 (+ t as float64)
    e = _refusal(Replay(path=path))
    assert "take" in str(e) and "over the" in str(e) and "record long runs to .h5" in str(e)
    # no 't': the time stamps made from rate_hz count too (a (n, 0) array holds no bytes)
    empty = _npz(tmp_path / "empty.npz", {"data": _npy(np.zeros((1000, 0)))})
    assert "over the" in str(_refusal(Replay(path=empty, rate_hz=10.0)))


@pytest.mark.parametrize(
    "array,why",
    [
        (np.array([{"a": 1}, None], dtype=object), "member data.npy holds Python objects (a pickle)"),
        (np.zeros(2, dtype=[("a", "f8"), ("b", "i4")]), "only plain numbers or text are read"),
    ],
    ids=["objects", "structured"],
)
def test_only_plain_numbers_are_read(tmp_path, array, why):
    path = _npz(tmp_path / "odd.npz", {"data": _npy(array), "t": _npy(np.arange(2.0))})
    assert why in str(_refusal(Replay(path=path)))


def test_members_compressed_unlike_numpy_are_refused(tmp_path):
    # bzip2 and lzma inflate a whole read at once: zipfile's size cap would come too late
    path = _npz(tmp_path / "bz.npz", {"data": _npy(np.zeros(4))}, zipfile.ZIP_BZIP2)
    assert "compressed other than numpy writes" in str(_refusal(Replay(path=path, rate_hz=10.0)))


def test_a_zip_directory_of_too_many_members_is_refused_before_listing(tmp_path, monkeypatch):
    path = _npz(tmp_path / "many.npz", {f"a{i}": _npy(np.zeros(1)) for i in range(5)})
    monkeypatch.setattr(replay, "MAX_STREAMS", 4)
    assert "lists 5 members" in str(_refusal(Replay(path=path, stream="a0", rate_hz=1.0)))


def test_a_damaged_member_is_one_located_refusal(tmp_path):
    path = tmp_path / "crc.npz"
    np.savez(path, data=np.arange(1000.0), t=np.arange(1000.0) / 100)
    raw = bytearray(path.read_bytes())
    at = raw.find(np.arange(1000.0)[500:].tobytes()[:64])
    raw[at] ^= 0xFF  # a data byte: the sizes agree, the CRC does not
    path.write_bytes(bytes(raw))
    Replay(path=str(path)).specs({})  # the header is fine: compiled
    e = _refusal(Replay(path=str(path)))  # the data is read when the block starts
    assert "member data.npy cannot be read (Bad CRC-32 for file 'data.npy')" in str(e)
    assert e.where == (str(path), 1, 1)


def test_fortran_and_big_endian_arrays_read_as_numpy_does(tmp_path):
    data = np.asfortranarray(np.arange(12.0).reshape(4, 3)).astype(">f8")
    path = tmp_path / "f.npz"
    np.savez(path, data=data, t=np.arange(4) / 10)
    block = Replay(path=str(path))
    block.bind({})
    block.open()
    np.testing.assert_array_equal(block._src.data, data)  # noqa: SLF001 - what was read


# -- .csv ---------------------------------------------------------------------------------------


def test_a_csv_over_the_size_cap_is_refused_from_its_size(tmp_path, monkeypatch):
    path = tmp_path / "log.csv"
    path.write_text("t,a\n" + "0,1\n" * 100)
    monkeypatch.setattr(csv_log, "MAX_TEXT_BYTES", 100)
    with pytest.raises(CsvError, match=r"larger than the 100 B a \.csv log may be") as e:
        read_csv_log(path)
    assert e.value.where == (str(path), 1, 1)


def test_a_long_line_is_refused_at_its_line_whatever_the_blocks(tmp_path, monkeypatch):
    monkeypatch.setattr(csv_log, "MAX_LINE_BYTES", 20)
    monkeypatch.setattr(csv_log, "_BLOCK", 7)  # lines and characters cut across blocks
    path = tmp_path / "log.csv"
    path.write_text("t,a\n0,1\n\n1,2\n2," + "3" * 25 + "\n")
    with pytest.raises(CsvError, match="a line longer than 20 B") as e:
        read_csv_log(path)
    assert e.value.where == (str(path), 5, 1)
    path.write_text("t,a\n0,1\n\n1,2\n2," + "3" * 17 + "\n")  # 20 bytes: fine
    assert read_csv_log(path).table.shape == (3, 2)


def test_text_checks_hold_across_block_boundaries(tmp_path, monkeypatch):
    monkeypatch.setattr(csv_log, "_BLOCK", 3)
    path = tmp_path / "u.csv"
    path.write_bytes("t,ünï\n0,1\n".encode())
    assert read_csv_log(path).names == ("t", "ünï")
    path.write_bytes(b"t,a\n0,1\n0.5,\xc3\n")  # a bad byte on line 3
    with pytest.raises(CsvError, match="byte 0xc3 is not UTF-8") as e:
        read_csv_log(path)
    assert e.value.where == (str(path), 3, 5)
    path.write_bytes("t,a\n0,1\n0.5,1 # é".encode()[:-1])  # ends inside a character
    with pytest.raises(CsvError, match="ends inside a UTF-8 character") as e:
        read_csv_log(path)
    assert e.value.where == (str(path), 3, 9)


def test_columns_are_capped_and_checked_by_name(tmp_path):
    names = ["t", *(f"c{i}" for i in range(1, MAX_COLUMNS))]
    path = tmp_path / "wide.csv"
    path.write_text(",".join(names) + "\n" + ",".join(["0"] * MAX_COLUMNS) + "\n")
    assert len(read_csv_log(path).names) == MAX_COLUMNS
    path.write_text(",".join([*names, "c1"]) + "\n")
    with pytest.raises(
        CsvError, match=f"{MAX_COLUMNS + 1} columns in the header row; a .csv log may have at most"
    ):
        read_csv_log(path)
    path.write_text(",".join([*names[:-1], "c1"]) + "\n")  # the last name repeats the second
    with pytest.raises(CsvError, match="column 'c1' is named twice") as e:
        read_csv_log(path)
    assert e.value.where[1:] == (1, len(",".join(names[:-1])) + 2)


# -- time stamps and rates ------------------------------------------------------------------------


def test_a_time_beyond_the_playable_span_is_refused_at_its_line(tmp_path):
    path = tmp_path / "far.csv"
    path.write_text("t,a\n0,1\n# gap\n2e6,2\n")
    e = _refusal(Replay(path=str(path), stream="a"))
    assert e.where == (str(path), 4, 1)
    assert "time 2e6 is beyond the 1e+06 s a replay may span" in str(e)


def test_unix_times_play_once_shifted_into_the_span(tmp_path):
    path = tmp_path / "unix.npz"
    np.savez(path, data=np.ones(10), t=1.7e9 + np.arange(10) / 10)
    e = _refusal(Replay(path=str(path)))
    assert "t[0] = 1.7e+09 s is beyond" in str(e) and e.where == (str(path), 1, 1)
    Replay(path=str(path), time_offset_s=-1.7e9).bind({})  # shifted: plays from 0
    assert "(+ time_offset_s 1e+300)" in str(_refusal(Replay(path=str(path), time_offset_s=1e300)))


def test_rates_from_files_and_configs_are_range_checked(tmp_path):
    path = tmp_path / "ghz.npz"
    np.savez(path, data=np.ones(10), t=np.arange(10) * 1e-9)
    assert "step at 1e+09 Hz (median); a replayed rate must be between" in str(
        _refusal(Replay(path=str(path)))
    )
    slow = tmp_path / "slow.npz"
    np.savez(slow, data=np.ones(3), t=np.arange(3) * 1e5)  # 1e-5 Hz: fine
    Replay(path=str(slow)).bind({})
    with pytest.raises(ConfigError, match="rate_hz"):
        Replay(path=str(path), rate_hz=1e7)


# -- .h5 ----------------------------------------------------------------------------------------


def _recording(path, rate: float = 100.0):
    with Recorder(path, {"s.y": StreamSpec("float64", (2,), "V", rate)}, {}) as rec:
        rec.write("s.y", Chunk(np.arange(5) / rate, np.ones((5, 2))))
    return str(path)


def _forged(path, samples: int, *, stored: int = 0, rate: float = 100.0, end_s: float = float("nan")):
    """An unchecksummed (old-format) recording of one stream declaring ``samples`` samples, of
    which the first ``stored`` are written."""
    with h5py.File(path, "w") as f:
        g = f.create_group("streams").create_group("s.y")
        g.attrs.update({"rate_hz": rate, "dtype": "float64", "shape": "[2]", "end_s": end_s})
        t = g.create_dataset("t", (samples,), "f8", maxshape=(None,), chunks=(64,))
        d = g.create_dataset("data", (samples, 2), "f8", maxshape=(None, 2), chunks=(64, 2))
        t[:stored] = np.arange(stored) / rate
        d[:stored] = 1.0
    return str(path)


def test_a_stream_declaring_more_samples_than_it_stores_is_refused(tmp_path):
    # the recording reader (flowtact/recording/hdf5.py) refuses these first: located at the file, named once
    Replay(path=_forged(tmp_path / "ok.h5", 200, stored=200)).bind({})
    hollow = _forged(tmp_path / "hollow.h5", 1 << 20, stored=200)
    e = _refusal(Replay(path=hollow))
    assert e.where == (hollow, 1, 1) and "hollow.h5" not in str(e)
    assert "/streams/s.y/t: declares 1,048,576 values (8.0 MiB) but stores 2.0 KiB" in str(e)
    e = _refusal(Replay(path=_forged(tmp_path / "huge.h5", 1 << 40)))
    assert "declares 1,099,511,627,776 values (8.0 TiB) but stores 0 B" in str(e)


def test_chunks_too_large_to_inflate_are_refused(tmp_path, monkeypatch):
    path = _forged(tmp_path / "chunky.h5", 200, stored=200)  # chunks of 64 samples: 512 B of t
    Replay(path=path).bind({})
    monkeypatch.setattr(replay, "MAX_CHUNK_BYTES", 511)
    e = _refusal(Replay(path=path))
    assert (
        "/streams/s.y/t of shape (200,) is stored in chunks of 512 B; a replay reads chunks of at most"
        in str(e)
    )


def test_numbers_a_recording_declares_are_range_checked(tmp_path):
    e = _refusal(Replay(path=_forged(tmp_path / "rate.h5", 10, stored=10, rate=1e300)))
    assert "declares rate_hz 1e+300; a rate must be between" in str(e)
    e = _refusal(Replay(path=_forged(tmp_path / "end.h5", 10, stored=10, end_s=1e300)))
    assert "its end_s 1e+300 s is beyond" in str(e)


def test_too_many_streams_are_refused_before_they_are_listed(tmp_path, monkeypatch):
    path = _recording(tmp_path / "rec.h5")
    monkeypatch.setattr(replay, "MAX_STREAMS", 0)
    e = _refusal(Replay(path=path))
    assert "1 streams; a replayed recording may hold at most 0" in str(e) and e.where == (path, 1, 1)


def test_hdf5_is_told_by_its_signature_not_by_reading_the_file(tmp_path):
    sparse = tmp_path / "sparse.h5"
    with open(sparse, "wb") as f:
        f.truncate(1 << 40)  # 1 TiB of holes: a whole read would never end
    e = _refusal(Replay(path=str(sparse)))
    assert "not a readable HDF5 file (it has no HDF5 signature)" in str(e)
    with open_regular(sparse) as f:
        assert not has_hdf5_signature(f)
    blocked = tmp_path / "userblock.h5"
    with h5py.File(blocked, "w", userblock_size=1024) as f:
        f["x"] = 1
    with open_regular(blocked) as f:
        assert has_hdf5_signature(f)
        f.seek(1024)
        assert f.read(8) == HDF5_SIGNATURE


# -- regular files only -----------------------------------------------------------------------------


@pytest.mark.parametrize("suffix", [".csv", ".npz", ".h5"])
def test_fifos_and_folders_are_refused_without_blocking(tmp_path, suffix):
    fifo = tmp_path / f"log{suffix}"
    os.mkfifo(fifo)  # nobody writes: a blocking open or read would hang here
    e = _refusal(Replay(path=str(fifo), rate_hz=1.0))
    assert str(e).endswith("not a regular file (a FIFO)")
    assert e.where == (str(fifo), 1, 1)
    folder = tmp_path / f"dir{suffix}"
    folder.mkdir()
    assert "not a regular file (a folder)" in str(_refusal(Replay(path=str(folder), rate_hz=1.0)))
    cls = stand_in_class("aunp_sensor")
    with pytest.raises(SpecError, match=r"not a regular file \(a FIFO\)"):
        cls(path=str(fifo)).bind({})


def test_open_regular_refuses_devices():
    with pytest.raises(FileRefused, match=r"/dev/zero: not a regular file \(a character device\)"):
        open_regular("/dev/zero")


def test_long_name_lists_are_cut():
    assert listing(["a", "b"]) == "a, b" and listing([]) == "none"
    assert listing([f"c{i}" for i in range(100)], most=3) == "c0, c1, c2, ... (100 in all)"


def test_what_one_tick_may_emit_is_bounded(tmp_path, monkeypatch):
    short = tmp_path / "short.npz"  # 2 samples looped every 2 us: 5 million repeats a tick
    np.savez(short, data=np.ones((2, 100)), t=np.array([0.0, 1e-6]))
    Replay(path=str(short)).bind({})
    e = _refusal(Replay(path=str(short), loop=True))
    assert "up to 10000002 samples (7.5 GiB) fall within 10 s (looped), the longest tick" in str(e)
    rec = _forged(tmp_path / "same.h5", 64, stored=64)
    with h5py.File(rec, "r+") as f:
        f["streams/s.y/t"][:] = 0.0  # every sample at once
    Replay(path=rec).bind({})
    monkeypatch.setattr(replay, "REPLAY_BUDGET_BYTES", 64 * 24 - 1)  # 64 samples of 16 bytes + t
    e = _refusal(Replay(path=rec))  # .h5 times are read when the block starts
    assert "up to 64 samples (1.5 KiB) fall within 10 s, the longest tick" in str(e)
    assert e.where == (rec, 1, 1)
