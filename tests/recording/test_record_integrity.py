"""Recordings check themselves: one flipped byte anywhere that matters is refused, naming the dataset."""

import json
import os
import shutil

import h5py
import numpy as np
import pytest

from flowtact.chunk import Chunk, StreamSpec
from flowtact.errors import FlowtactError, RecordingCorrupted, RecordingError
from flowtact.recording.hdf5 import Recorder, open_stream, open_verified, read_recording, stream_specs
from flowtact.recording.integrity import CheckedFile

FORCE = StreamSpec("float64", (3,), "N", 1000.0, labels=("Fx", "Fy", "Fz"))
SPIKES = StreamSpec("int64", (), "1", None, events=True, n_units=24)
PULSES = StreamSpec(
    "float64", (3,), "1", None, events=True, n_units=24, labels=("unit", "amplitude_ua", "width_us")
)
FRAMES = StreamSpec("uint8", (24, 32), "1", 40.0)
MARK = "name: integrity-marker-yaml\n"


def _write(path, *, big_provenance=False, **kw):
    prov = {"graph_yaml": MARK, "graph_name": "marked", "graph_seed": 7, "params": {"a": {"x": 1}}}
    if big_provenance:
        prov["graph_source"] = "# " + "y" * 70_000 + "\n"
    streams = {"force.f": FORCE, "sa1.spikes": SPIKES, "stim.y": PULSES, "cam.frame": FRAMES}
    with Recorder(path, streams, prov, **kw) as rec:
        for i in range(0, 6000, 500):
            t = (i + np.arange(500)) / 1000.0
            rec.write("force.f", Chunk(t, np.stack([t, -t, 2 * t], axis=1)))
            rec.write("sa1.spikes", Chunk(t[::7], (np.arange(len(t[::7])) % 24).astype(np.int64), end=t[-1]))
            pulses = np.stack(
                [np.arange(len(t[::50])) % 24, np.full(len(t[::50]), 50.0), np.full(len(t[::50]), 200.0)], 1
            )
            rec.write("stim.y", Chunk(t[::50], pulses.astype(np.float64), end=t[-1]))
            rec.write("cam.frame", Chunk(t[::25], np.full((len(t[::25]), 24, 32), i % 251, np.uint8)))
    return path


@pytest.fixture(scope="module")
def good(tmp_path_factory):
    return _write(tmp_path_factory.mktemp("rec") / "good.h5")


def flip(src, dst, offset):
    """Copy ``src`` to ``dst`` with the byte at ``offset`` inverted."""
    shutil.copyfile(src, dst)
    with open(dst, "r+b") as fh:
        fh.seek(offset)
        b = fh.read(1)
        fh.seek(offset)
        fh.write(bytes([b[0] ^ 0xFF]))
    return dst


def chunk_offset(path, dataset, chunk=0, into=17):
    with h5py.File(path, "r") as f:
        return f[dataset].id.get_chunk_info(chunk).byte_offset + into


def text_offset(path, needle: bytes):
    raw = path.read_bytes()
    assert raw.count(needle) == 1, needle
    return raw.index(needle) + len(needle) // 2


def test_every_dataset_checksummed_and_untouched_file_verifies(good):
    with h5py.File(good, "r") as f:
        found = []
        f.visititems(lambda _name, o: found.append(o) if isinstance(o, h5py.Dataset) else None)
        assert len(found) == 9  # 4 streams x (t, data) + /integrity
        assert all(ds.fletcher32 and ds.chunks for ds in found)
        assert f.attrs["format_version"] == 2
    with CheckedFile(good) as c:
        assert c.checksummed and c.problems() == [] and c.datasets_checked == 8
    rec = read_recording(good)
    assert rec.streams["force.f"].data.shape == (6000, 3) and rec.provenance["graph_yaml"] == MARK


@pytest.mark.parametrize(
    ("dataset", "chunk", "rows"),
    [
        ("/streams/force.f/data", 1, "2730-5459"),
        ("/streams/force.f/t", 0, "0-5999"),
        ("/streams/sa1.spikes/data", 0, "0-863"),
    ],
)
def test_flipped_byte_in_stream_data_is_refused_naming_the_dataset(good, tmp_path, dataset, chunk, rows):
    bad = flip(good, tmp_path / "bad.h5", chunk_offset(good, dataset, chunk=chunk))
    with pytest.raises(
        RecordingCorrupted, match=rf"bad\.h5: {dataset}: checksum mismatch \(the file is corrupted\)"
    ) as e:
        read_recording(bad)
    assert isinstance(e.value, FlowtactError) and e.value.where == dataset
    with pytest.raises(RecordingCorrupted, match=rf"{dataset}: checksum mismatch in samples {rows} \("):
        open_stream(bad, dataset.split("/")[2])
    other = "cam.frame"  # an intact stream of the damaged file still reads
    np.testing.assert_array_equal(
        read_recording(bad, [other]).streams[other].data, read_recording(good, [other]).streams[other].data
    )
    with CheckedFile(bad) as c:
        assert [p.where for p in c.problems()] == [dataset]


def test_flipped_byte_in_provenance_attribute(good, tmp_path):
    bad = flip(good, tmp_path / "bad.h5", text_offset(good, MARK.encode()))
    with pytest.raises(
        RecordingCorrupted, match=r"bad\.h5: /: attribute 'graph_yaml' does not match its checksum"
    ):
        read_recording(bad, streams=())
    with pytest.raises(RecordingCorrupted, match="graph_yaml"):
        stream_specs(bad)  # every reader checks the provenance, whatever it goes on to read


def test_flipped_byte_in_stream_attribute(good, tmp_path):
    bad = flip(good, tmp_path / "bad.h5", text_offset(good, b'"amplitude_ua"'))
    with pytest.raises(RecordingCorrupted, match=r"/streams/stim\.y: attribute 'labels' does not match"):
        stream_specs(bad)


def test_flipped_byte_in_large_provenance_dataset(tmp_path):
    path = _write(tmp_path / "big.h5", big_provenance=True)
    assert read_recording(path, streams=()).provenance["graph_source"].startswith("# yyy")
    bad = flip(path, tmp_path / "bad.h5", chunk_offset(path, "/provenance/graph_source", into=30_000))
    with pytest.raises(RecordingCorrupted, match=r"/provenance/graph_source: checksum mismatch"):
        read_recording(bad, streams=())


def test_flipped_byte_in_the_manifest(good, tmp_path):
    bad = flip(good, tmp_path / "bad.h5", chunk_offset(good, "/integrity", into=40))
    with pytest.raises(RecordingCorrupted, match=r"bad\.h5: /integrity: checksum mismatch"):
        read_recording(bad)
    with CheckedFile(bad, strict=False) as c:
        assert [p.where for p in c.problems()] == ["/integrity"]


def test_changed_shape_is_refused(good, tmp_path):
    """Metadata HDF5 does not checksum (a dataset's extent) is held by the manifest."""
    bad = tmp_path / "bad.h5"
    shutil.copyfile(good, bad)
    with h5py.File(bad, "r+") as f:
        f["streams/force.f/t"].resize((5000,))
    with pytest.raises(RecordingCorrupted, match=r"/streams/force\.f/t: dtype/shape <f8 \[5000\] differ"):
        read_recording(bad)


def test_truncated_and_foreign_files_refused_in_one_line(good, tmp_path):
    cut = tmp_path / "cut.h5"
    shutil.copyfile(good, cut)
    os.truncate(cut, os.path.getsize(good) // 2)
    with pytest.raises(
        RecordingError, match=r"cut\.h5: truncated: [\d,]+ bytes of the [\d,]+ its header promises"
    ) as e:
        read_recording(cut)
    assert "\n" not in str(e.value)
    (tmp_path / "junk.h5").write_bytes(b"\0" * 5000)
    with pytest.raises(
        RecordingError, match=r"junk\.h5: not a readable HDF5 file \(it has no HDF5 signature\)"
    ):
        stream_specs(tmp_path / "junk.h5")
    (tmp_path / "empty.h5").write_bytes(b"")
    with pytest.raises(RecordingError, match=r"empty\.h5: not a readable HDF5 file \(it is empty\)"):
        read_recording(tmp_path / "empty.h5")


def write_format1(path):
    """A recording as flowtact wrote them before checksums: no filters, no manifest."""
    with h5py.File(path, "w") as f:
        f.attrs.update(
            {"format": "flowtact-recording", "format_version": 1, "graph_name": "old", "json_attrs": "[]"}
        )
        f.attrs["graph_yaml"] = "name: old\n"
        g = f.create_group("streams").create_group("force.f")
        g.attrs.update(
            {"units": "N", "rate_hz": 1000.0, "events": np.int8(0), "n_units": -1, "dtype": "float64"}
        )
        g.attrs.update({"labels": '["Fx", "Fy", "Fz"]', "shape": "[3]", "end_s": 0.099})
        g.create_dataset("t", data=np.arange(100) / 1000.0, maxshape=(None,), chunks=(64,))
        g.create_dataset("data", data=np.ones((100, 3)), maxshape=(None, 3), chunks=(64, 3))
    return path


def test_old_recording_without_checksums_still_reads(tmp_path):
    path = write_format1(tmp_path / "old.h5")
    rec = read_recording(path)
    assert rec.streams["force.f"].spec == FORCE and rec.streams["force.f"].data.shape == (100, 3)
    with CheckedFile(path) as c:
        assert not c.checksummed and c.problems() == []
    f, h = open_stream(path, "force.f")
    f.close()
    assert h.n == 100


def test_manifest_removed_from_a_checksummed_file_is_refused(good, tmp_path):
    bad = tmp_path / "bad.h5"
    shutil.copyfile(good, bad)
    with h5py.File(bad, "r+") as f:
        del f["integrity"]
    with pytest.raises(
        RecordingCorrupted, match=r"/integrity: missing, though format_version says checksummed"
    ):
        read_recording(bad)


def test_every_copy_of_the_crash_safe_writer_is_checksummed(tmp_path):
    """Mid-recording, the committed file and the work copy each verify; so after close."""
    path = tmp_path / "run.h5"
    rec = Recorder(
        path, {"force.f": FORCE, "sa1.spikes": SPIKES}, {"graph_yaml": MARK}, flush_interval_s=3600
    )
    for k in range(4):
        t = (k * 1000 + np.arange(1000)) / 1000.0
        rec.write("force.f", Chunk(t, np.ones((1000, 3)) * k))
        rec.write("sa1.spikes", Chunk(t[::9], np.zeros(len(t[::9]), np.int64), end=t[-1]))
        rec.flush()
        for copy in (path, tmp_path / ".run.h5.wip"):
            with CheckedFile(copy) as c:
                assert c.checksummed and c.problems() == [], copy
                assert all(
                    c.file[f"streams/{s}/{d}"].fletcher32
                    for s in ("force.f", "sa1.spikes")
                    for d in ("t", "data")
                )
    holder = h5py.File(path, "r")  # a reader on the committed file: the next flush rebuilds the work copy
    try:
        rec.write("force.f", Chunk(np.array([4.0]), np.ones((1, 3))))
        rec.flush()
        rec.write("force.f", Chunk(np.array([4.001]), np.ones((1, 3))))
        rec.flush()
    finally:
        holder.close()
    rec.close({"error": "boom"})
    with CheckedFile(path) as c:
        assert c.problems() == []
        assert (
            c.attrs(c.file)["error"] == "boom" and json.loads(c.attrs(c.file)["summary"])["error"] == "boom"
        )


def test_checksums_without_hard_links_and_with_gzip(tmp_path, monkeypatch):
    def no_link(*_args, **_kwargs):
        raise OSError("hard links not supported")

    monkeypatch.setattr(os, "link", no_link)
    path = _write(tmp_path / "z.h5", compression="gzip", flush_interval_s=0)
    with h5py.File(path, "r") as f:
        assert f["streams/force.f/data"].compression == "gzip" and f["streams/force.f/data"].fletcher32
    with CheckedFile(path) as c:
        assert c.problems() == []
    bad = flip(path, tmp_path / "bad.h5", chunk_offset(path, "/streams/cam.frame/data", chunk=2, into=5))
    with CheckedFile(bad) as c:
        assert [p.where for p in c.problems()] == ["/streams/cam.frame/data"]


def test_verify_reads_a_few_chunks_at_a_time(good, monkeypatch):
    """Memory stays bounded: no read during verification is larger than max_bytes (or one chunk)."""
    sizes = []
    real = h5py.Dataset.__getitem__

    def spy(self, sel):
        out = real(self, sel)
        sizes.append(np.asarray(out).nbytes)
        return out

    monkeypatch.setattr(h5py.Dataset, "__getitem__", spy)
    with CheckedFile(good) as c:
        ds = c.group("/streams/force.f/data")
        sizes.clear()
        c.verify(ds, max_bytes=100_000)
    chunk_bytes = 2730 * 3 * 8
    assert len(sizes) == 3 and max(sizes) <= chunk_bytes  # 6000 rows = 3 chunks, one per read


def test_raw_file_for_readers_that_walk_it_is_verified_first(good, tmp_path):
    """open_verified (the plots read the raw h5py file) refuses damage before handing the file out."""
    f = open_verified(good)
    try:
        assert isinstance(f, h5py.File) and f["streams/force.f/data"].shape == (6000, 3)
    finally:
        f.close()
    bad = flip(good, tmp_path / "bad.h5", chunk_offset(good, "/streams/cam.frame/data", chunk=1))
    with pytest.raises(
        RecordingCorrupted, match=r"bad\.h5: /streams/cam\.frame/data: checksum mismatch in samples"
    ):
        open_verified(bad)


def test_a_large_unchunked_dataset_is_read_in_bounded_pieces(tmp_path):
    from flowtact.recording.hdf5 import read_recording
    from flowtact.recording.integrity import MAX_READ_BYTES

    n = MAX_READ_BYTES // 16 + 1000  # (n, 2) float64: more than one read may fetch
    with h5py.File(tmp_path / "c.h5", "w") as f:  # written by another tool: contiguous, no checksums
        g = f.create_group("streams/s.y")
        g.create_dataset("t", data=np.arange(n) / 1000.0)
        g.create_dataset("data", data=np.ones((n, 2)))
    s = read_recording(tmp_path / "c.h5").streams["s.y"]
    assert s.data.shape == (n, 2) and s.data.sum() == 2 * n and s.t[-1] == (n - 1) / 1000.0


@pytest.mark.parametrize(
    "attr,value,where",
    [
        ("json_attrs", "[", "/ json_attrs"),
        ("summary", "{bad", "/ summary"),
        ("summary", "[" * 100_000, "/ summary"),
    ],
)
def test_provenance_that_is_not_json_is_named_damage(tmp_path, attr, value, where):
    path = write_format1(tmp_path / "old.h5")  # no checksums: a forged file's text reaches the parser
    with h5py.File(path, "r+") as f:
        f.attrs[attr] = value
    with pytest.raises(RecordingCorrupted, match=rf"old\.h5: {where}: not valid JSON") as e:
        read_recording(path)
    assert "\n" not in str(e.value)
