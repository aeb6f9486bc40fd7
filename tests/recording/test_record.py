"""HDF5 recordings: layout, round trip, provenance, and survival of a SIGKILLed writer."""

import json
import os
import random
import signal
import subprocess
import sys
import textwrap
import time

import h5py
import numpy as np
import pytest

from flowtact.chunk import Chunk, StreamSpec
from flowtact.recording.hdf5 import Recorder, read_recording, stream_specs

FORCE = StreamSpec("float64", (3,), "N", 1000.0, labels=("Fx", "Fy", "Fz"))
SPIKES = StreamSpec("int64", (), "1", None, events=True, n_units=24)
FRAMES = StreamSpec("uint8", (240, 320), "1", 40.0)


def _force_chunk(i: int, n: int) -> Chunk:
    t = (i + np.arange(n)) / 1000.0
    return Chunk(t, np.arange(i, i + n, dtype=np.float64)[:, None] * np.array([1.0, -2.0, 0.5]))


def _spike_chunk(i: int, n: int) -> Chunk:
    idx = np.arange(i, i + n)
    sel = idx % 7 == 0
    return Chunk(idx[sel] / 1000.0, idx[sel] % 24, end=(i + n) / 1000.0)


def _write_all(rec: Recorder, sizes: list[int]) -> tuple[int, list[Chunk], list[Chunk]]:
    i, forces, spikes = 0, [], []
    for n in sizes:
        forces.append(_force_chunk(i, n))
        spikes.append(_spike_chunk(i, n))
        rec.write("force.f", forces[-1])
        rec.write("sa1.spikes", spikes[-1])
        i += n
    return i, forces, spikes


def _sidecars(path):
    return sorted(p.name for p in path.parent.iterdir() if p.name.startswith(f".{path.name}."))


@pytest.mark.parametrize("interval", [0.0, 3600.0])
def test_round_trip_samples_events_frames(tmp_path, interval):
    path = tmp_path / "run.h5"
    streams = {"force.f": FORCE, "sa1.spikes": SPIKES, "cam.frame": FRAMES}
    prov = {"graph_yaml": "name: touch\n", "params": {"force": {"gain": 2.0}}, "seeds": '{"sa1": 11}'}
    rec = Recorder(path, streams, prov, flush_interval_s=interval)
    n, forces, spikes = _write_all(rec, [1, 7, 0, 250, 3, 64, 100])
    frames = np.random.default_rng(1).integers(0, 256, (5, 240, 320), dtype=np.uint8)
    rec.write("cam.frame", Chunk(np.arange(5) / 40.0, frames))
    rec.close({"counters": {"nlif": {"spikes": np.int64(37)}}, "wall_s": 1.5})
    assert _sidecars(path) == []

    out = read_recording(path)
    assert list(out.streams) == ["force.f", "sa1.spikes", "cam.frame"]  # creation order kept
    f = out.streams["force.f"]
    assert f.spec == FORCE
    np.testing.assert_array_equal(f.t, np.concatenate([c.t for c in forces]))
    np.testing.assert_array_equal(f.data, np.concatenate([c.data for c in forces]))
    s = out.streams["sa1.spikes"]
    assert s.spec == SPIKES and s.data.dtype == np.int64
    np.testing.assert_array_equal(s.t, np.concatenate([c.t for c in spikes]))
    np.testing.assert_array_equal(s.data, np.concatenate([c.data for c in spikes]))
    assert s.end_s == n / 1000.0 and s.chunk().end == n / 1000.0
    c = out.streams["cam.frame"]
    assert c.spec == FRAMES
    np.testing.assert_array_equal(c.data, frames)

    assert out.complete
    assert out.summary["counters"] == {"nlif": {"spikes": 37}} and out.summary["wall_s"] == 1.5
    assert out.summary["recorder"]["samples"] == {"force.f": n, "sa1.spikes": len(s.t), "cam.frame": 5}
    p = out.provenance
    assert p["graph_yaml"] == "name: touch\n"
    assert p["params"] == {"force": {"gain": 2.0}}  # a dict goes back as a dict
    assert p["seeds"] == '{"sa1": 11}' and out.json("seeds") == {"sa1": 11}  # JSON text stays text
    assert p["flowtact_version"] and p["created_utc"] and p["command"] is not None
    assert {"python", "numpy", "h5py", "hdf5"} <= set(p["versions"])


def test_layout_is_plain_hdf5_for_matlab(tmp_path):
    path = tmp_path / "run.h5"
    with Recorder(
        path, {"force.f": FORCE, "sa1.spikes": SPIKES, "cam.frame": FRAMES}, {"graph_seed": 7}
    ) as rec:
        _write_all(rec, [500])
    with h5py.File(path, "r") as f:
        assert f.attrs["format"] == "flowtact-recording"
        for key, value in f.attrs.items():  # strings and numbers only: h5readatt reads them all
            assert isinstance(value, (str, np.integer, np.floating)), (key, type(value))
        g = f["streams/force.f"]
        assert g["t"].dtype == np.float64 and g["data"].shape == (500, 3)
        assert g["t"].maxshape == (None,) and g["data"].maxshape == (None, 3)
        assert g["data"].chunks == (2730, 3)  # ~64 kB chunks: 2.7 s at 1 kHz
        assert g["data"].compression is None
        assert f["streams/cam.frame/data"].chunks == (1, 240, 320)  # one frame per chunk
        assert g.attrs["units"] == "N" and g.attrs["rate_hz"] == 1000.0 and g.attrs["events"] == 0
        assert json.loads(g.attrs["labels"]) == ["Fx", "Fy", "Fz"]
        e = f["streams/sa1.spikes"]
        assert np.isnan(e.attrs["rate_hz"]) and e.attrs["events"] == 1 and e.attrs["n_units"] == 24
        assert f.attrs["graph_seed"] == 7


def test_gzip_option(tmp_path):
    path = tmp_path / "run.h5"
    with Recorder(path, {"force.f": FORCE}, {}, compression="gzip") as rec:
        rec.write("force.f", _force_chunk(0, 3000))
    with h5py.File(path, "r") as f:
        assert f["streams/force.f/data"].compression == "gzip"
    np.testing.assert_array_equal(read_recording(path).streams["force.f"].data, _force_chunk(0, 3000).data)


def test_readable_while_recording_and_flush_interval(tmp_path):
    path = tmp_path / "run.h5"
    rec = Recorder(path, {"force.f": FORCE, "sa1.spikes": SPIKES}, {}, flush_interval_s=3600.0)
    assert len(read_recording(path).streams["force.f"].t) == 0  # structure exists from the start
    _write_all(rec, [100, 100])
    assert len(read_recording(path).streams["force.f"].t) == 0  # not flushed yet
    rec.flush()
    mid = read_recording(path)
    assert len(mid.streams["force.f"].t) == 200 and mid.summary is None and not mid.complete
    assert _sidecars(path) == [f".{path.name}.wip"]
    rec.write("force.f", _force_chunk(200, 50))
    rec.flush()
    rec.flush()  # nothing new: no work
    assert rec.flushes == 2
    rec.flush_interval_s = 0.0
    rec.write("force.f", _force_chunk(250, 50))  # due: flushes by itself
    assert len(read_recording(path).streams["force.f"].t) == 300
    rec.close()
    rec.close()  # idempotent
    assert rec.closed and read_recording(path).summary["recorder"]["samples"]["force.f"] == 300
    with pytest.raises(ValueError, match="closed"):
        rec.write("force.f", _force_chunk(300, 1))


def test_empty_streams_and_header_only_specs(tmp_path):
    path = tmp_path / "run.h5"
    with Recorder(path, {"force.f": FORCE, "sa1.spikes": SPIKES}, {}):
        pass
    out = read_recording(path)
    assert out.streams["force.f"].data.shape == (0, 3) and out.streams["sa1.spikes"].end_s is None
    assert stream_specs(path) == {"force.f": (FORCE, 0), "sa1.spikes": (SPIKES, 0)}


def test_write_errors(tmp_path):
    with Recorder(tmp_path / "run.h5", {"force.f": FORCE, "sa1.spikes": SPIKES}, {}) as rec:
        with pytest.raises(
            KeyError, match=r"no recorded stream 'force\.x' \(recorded: force\.f, sa1\.spikes\)"
        ):
            rec.write("force.x", _force_chunk(0, 1))
        with pytest.raises(ValueError, match="sample shape"):
            rec.write("force.f", Chunk(np.zeros(2), np.zeros((2, 4))))
        with pytest.raises(ValueError, match="cannot be stored as int64"):
            rec.write("sa1.spikes", Chunk(np.zeros(1), np.array([0.5])))
        rec.write("force.f", Chunk(np.zeros(1), np.ones((1, 3), np.float32)))  # safe cast is fine
    with pytest.raises(ValueError, match="invalid stream name"):
        Recorder(tmp_path / "x.h5", {"a/b": FORCE}, {})
    with pytest.raises(ValueError, match="flush_interval_s"):
        Recorder(tmp_path / "x.h5", {"a.b": FORCE}, {}, flush_interval_s=-1)


def test_read_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"recording not found: .*nope\.h5"):
        read_recording(tmp_path / "nope.h5")
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f["x"] = 1
    with pytest.raises(ValueError, match="not a flowtact recording"):
        read_recording(tmp_path / "other.h5")
    (tmp_path / "junk.h5").write_bytes(b"not hdf5 at all")
    with pytest.raises(OSError, match="not a readable HDF5 file"):
        read_recording(tmp_path / "junk.h5")
    with Recorder(tmp_path / "run.h5", {"force.f": FORCE}, {}):
        pass
    with pytest.raises(KeyError, match=r"no stream 'force\.g' \(available: force\.f\)"):
        read_recording(tmp_path / "run.h5", streams=["force.g"])


def test_large_provenance_goes_to_datasets(tmp_path):
    big = "# " + "x" * 100_000 + "\n"
    params = {f"node{i}": {"w": list(range(50))} for i in range(400)}
    prov = {"graph_yaml": big, "params": params, "huge": 2**70, "seed": 2**64 - 1}
    with Recorder(tmp_path / "run.h5", {"force.f": FORCE}, prov):
        pass
    p = read_recording(tmp_path / "run.h5").provenance
    assert p["graph_yaml"] == big and p["params"] == params
    assert p["huge"] == str(2**70) and p["seed"] == 2**64 - 1


def test_exception_in_with_block_is_summarised(tmp_path):
    with pytest.raises(RuntimeError), Recorder(tmp_path / "run.h5", {"force.f": FORCE}, {}) as rec:
        rec.write("force.f", _force_chunk(0, 10))
        raise RuntimeError("boom")
    out = read_recording(tmp_path / "run.h5")
    assert out.summary["error"] == "RuntimeError: boom" and len(out.streams["force.f"].t) == 10


def test_overwrites_and_cleans_stale_sidecars(tmp_path):
    path = tmp_path / "run.h5"
    path.write_bytes(b"old junk")
    (tmp_path / ".run.h5.wip").write_bytes(b"stale")
    (tmp_path / ".run.h5.old").write_bytes(b"stale")
    with Recorder(path, {"force.f": FORCE}, {}, flush_interval_s=0) as rec:
        rec.write("force.f", _force_chunk(0, 5))
    assert _sidecars(path) == [] and len(read_recording(path).streams["force.f"].t) == 5


def test_without_hard_links(tmp_path, monkeypatch):
    def no_link(*_args, **_kwargs):
        raise OSError("hard links not supported")

    monkeypatch.setattr(os, "link", no_link)
    path = tmp_path / "run.h5"
    with Recorder(path, {"force.f": FORCE, "sa1.spikes": SPIKES}, {}, flush_interval_s=0) as rec:
        _, forces, _ = _write_all(rec, [10, 20, 30, 40])
    np.testing.assert_array_equal(
        read_recording(path).streams["force.f"].data, np.concatenate([c.data for c in forces])
    )


def test_reader_holding_the_old_copy(tmp_path):
    """A reader keeping a file open across swaps: the writer rebuilds its work copy instead."""
    path = tmp_path / "run.h5"
    rec = Recorder(path, {"force.f": FORCE}, {}, flush_interval_s=3600)
    rec.write("force.f", _force_chunk(0, 10))
    rec.flush()
    reader = h5py.File(path, "r")  # holds the inode that becomes the work copy at the next swap
    try:
        rec.write("force.f", _force_chunk(10, 10))
        rec.flush()
        rec.write("force.f", _force_chunk(20, 10))
        rec.flush()  # work copy is open in the reader: copied afresh from the committed file
        assert reader["streams/force.f/t"].shape == (10,)  # the reader's view is untouched
    finally:
        reader.close()
    rec.close()
    np.testing.assert_array_equal(read_recording(path).streams["force.f"].t, np.arange(30) / 1000.0)


# -- crash safety ------------------------------------------------------------------------------

CHILD = textwrap.dedent(
    """
    import os, signal, sys, time
    import h5py
    import numpy as np
    from flowtact.chunk import Chunk, StreamSpec
    from flowtact.recording.hdf5 import Recorder

    path, interval, hook = sys.argv[1], float(sys.argv[2]), sys.argv[3]
    armed = False
    if hook != "none":  # die right before (or after) the k-th call of one step of a flush
        name, k, when = hook.split(":")
        owner, attr = {
            "setitem": (h5py.Dataset, "__setitem__"), "close": (h5py.File, "close"),
            "link": (os, "link"), "replace": (os, "replace"),
        }[name]
        orig, calls = getattr(owner, attr), [0]

        def hooked(*a, **kw):
            if armed:
                calls[0] += 1
                if calls[0] == int(k) and when == "before":
                    os.kill(os.getpid(), signal.SIGKILL)
            out = orig(*a, **kw)
            if armed and calls[0] == int(k) and when == "after":
                os.kill(os.getpid(), signal.SIGKILL)
            return out

        setattr(owner, attr, hooked)
    specs = {
        "sensor.r": StreamSpec("float64", (5,), "1", 1000.0),
        "nlif.spikes": StreamSpec("int64", (), "1", None, events=True, n_units=24),
    }
    rec = Recorder(path, specs, {"graph_yaml": "x"}, flush_interval_s=interval)
    armed = True
    start = time.monotonic()
    print(repr(start), flush=True)
    i = 0
    while True:  # 1 kHz, paced by the wall clock, written in small chunks
        n = int((time.monotonic() - start) * 1000.0) - i
        if n > 0:
            idx = np.arange(i, i + n)
            rec.write("sensor.r", Chunk(idx / 1000.0, idx[:, None] * np.arange(1.0, 6.0)))
            sel = idx % 7 == 0
            rec.write("nlif.spikes", Chunk(idx[sel] / 1000.0, idx[sel] % 24, end=(i + n) / 1000.0))
            i += n
        time.sleep(0.002)
    """
)


def _run_child(tmp_path, interval: float, hook: str = "none", kill_after: float | None = None):
    script = tmp_path / "child.py"
    script.write_text(CHILD)
    path = tmp_path / f"rec-{random.random():.9f}.h5"
    proc = subprocess.Popen(
        [sys.executable, str(script), str(path), str(interval), hook],
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONHASHSEED": "0"},
    )
    try:
        start = float(proc.stdout.readline())
        if kill_after is None:
            proc.wait(timeout=30)  # the hook kills it
        else:
            time.sleep(kill_after)
            killed_at = time.monotonic()
            proc.send_signal(signal.SIGKILL)
            proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.stdout.close()
    assert proc.returncode == -signal.SIGKILL
    return path, (killed_at - start if kill_after is not None else None)


def _check_killed_recording(path) -> float:
    """The file opens with plain h5py, reads back, and every sample it holds is right."""
    with h5py.File(path, "r") as f:
        assert "streams/sensor.r/data" in f
    out = read_recording(path)
    assert out.summary is None and not out.complete
    r, s = out.streams["sensor.r"], out.streams["nlif.spikes"]
    n = len(r.t)
    np.testing.assert_array_equal(r.t, np.arange(n) / 1000.0)
    np.testing.assert_array_equal(r.data, np.arange(n)[:, None] * np.arange(1.0, 6.0))
    idx = np.arange(0, round(s.end_s * 1000.0) if s.end_s else 0)
    idx = idx[idx % 7 == 0]
    np.testing.assert_array_equal(s.t, idx / 1000.0)
    np.testing.assert_array_equal(s.data, idx % 24)
    return n / 1000.0


@pytest.mark.slow
def test_sigkill_at_random_moments_loses_at_most_one_second(tmp_path):
    rng = random.Random(20240611)
    for _ in range(4):
        path, elapsed = _run_child(tmp_path, 1.0, kill_after=rng.uniform(1.1, 2.6))
        held = _check_killed_recording(path)
        # flushes follow each other by flush_interval_s (1 s) + one write; 0.25 s for a loaded machine
        assert held >= elapsed - 1.25, f"killed at {elapsed:.3f} s but the file holds only {held:.3f} s"
        assert held <= elapsed + 0.01


@pytest.mark.slow
def test_sigkill_while_flushing(tmp_path):
    """flush_interval_s=0: the writer is nearly always inside a flush when the kill lands."""
    rng = random.Random(7)
    for _ in range(3):
        path, elapsed = _run_child(tmp_path, 0.0, kill_after=rng.uniform(0.5, 1.2))
        held = _check_killed_recording(path)
        assert held >= elapsed - 0.25


@pytest.mark.parametrize(
    "hook",
    [
        "setitem:5:after",  # half-way through appending to the work copy
        "close:3:before",  # work copy written, HDF5 metadata not yet flushed
        "link:2:after",  # committed file hard-linked, swap not started
        "replace:3:after",  # swap done, old copy not yet renamed to the work copy
        "replace:4:before",
    ],
)
def test_sigkill_at_each_step_of_a_flush(tmp_path, hook):
    path, _ = _run_child(tmp_path, 0.0, hook=hook)
    assert _check_killed_recording(path) > 0 or hook.startswith("setitem")


def test_committed_file_is_never_opened_for_writing(tmp_path, monkeypatch):
    """The crash-safety invariant: ``path`` only ever changes by an atomic rename onto it."""
    path = tmp_path / "run.h5"
    real_file, opened = h5py.File, []

    def spy(name, mode="r", *a, **k):
        opened.append((os.path.realpath(name), mode))
        return real_file(name, mode, *a, **k)

    monkeypatch.setattr(h5py, "File", spy)
    with Recorder(path, {"force.f": FORCE, "sa1.spikes": SPIKES}, {}, flush_interval_s=0) as rec:
        _write_all(rec, [10, 20, 30])
    writes = [m for p, m in opened if p == os.path.realpath(path) and m != "r"]
    assert writes == [], writes
    assert sum(m == "r+" for _, m in opened) >= 6  # the appends went to the work copy


def test_the_recorder_refuses_a_sample_its_readers_would_refuse(tmp_path):
    from flowtact.recording.integrity import MAX_CHUNK_BYTES

    side = int((MAX_CHUNK_BYTES // 8) ** 0.5) + 1  # one float64 frame just over the chunk bound
    with pytest.raises(ValueError, match=r"one sample of .* is larger than a recording's chunks may be"):
        Recorder(tmp_path / "r.h5", {"cam.x": StreamSpec(dtype="float64", shape=(side, side))}, {})
    assert not (tmp_path / "r.h5").exists()
