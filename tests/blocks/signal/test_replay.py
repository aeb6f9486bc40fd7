"""replay: record → replay round trips, .npz and .csv inputs, offsets, loops and clear errors."""

import numpy as np
import pytest

from flowtact.blocks.signal.replay import Replay
from flowtact.chunk import Chunk, StreamSpec, concat
from flowtact.errors import ConfigError, SpecError
from flowtact.recording.hdf5 import Recorder
from flowtact.testing import assert_same, run_source

FORCE = StreamSpec("float64", (3,), "N", 1000.0, labels=("Fx", "Fy", "Fz"))
SPIKES = StreamSpec("int32", (), "1", None, events=True, n_units=4)
FRAMES = StreamSpec("uint8", (6, 8), "1", 40.0)
TICKS = (0.001, 0.0137, [0.003, 0.25, 0.001, 0.064, 0.0])


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """0.5 s of forces (1 kHz), spikes and frames (40 Hz), written in irregular chunks."""
    path = tmp_path_factory.mktemp("rec") / "run.h5"
    rng = np.random.default_rng(5)
    chunks = {"force.f": [], "sa1.spikes": [], "cam.frame": []}
    with Recorder(
        path, {"force.f": FORCE, "sa1.spikes": SPIKES, "cam.frame": FRAMES}, {}, flush_interval_s=0
    ) as rec:
        i = 0
        for n in [1, 7, 0, 120, 33, 250, 89]:
            t = (i + np.arange(n)) / 1000.0
            f = Chunk(t, rng.normal(size=(n, 3)))
            sel = rng.random(n) < 0.1
            s = Chunk(
                np.sort(t[sel] + 0.0004), rng.integers(0, 4, int(sel.sum())).astype(np.int32), (i + n) / 1000
            )
            k = t[(t * 40.0) % 1.0 == 0]
            c = Chunk(k, rng.integers(0, 256, (len(k), 6, 8), dtype=np.uint8))
            for name, chunk in zip(chunks, (f, s, c), strict=True):
                rec.write(name, chunk)
                chunks[name].append(chunk)
            i += n
    return path, {k: concat(v) for k, v in chunks.items()}


@pytest.mark.parametrize("stream", ["force.f", "sa1.spikes", "cam.frame"])
@pytest.mark.parametrize("tick", TICKS, ids=["1ms", "13.7ms", "irregular"])
def test_record_then_replay_is_bit_identical(recording, stream, tick):
    path, written = recording
    block = Replay(path=str(path), stream=stream)
    out = run_source(block, 0.5, tick_s=tick)["y"]
    want = written[stream]
    assert block.output_specs["y"] == {"force.f": FORCE, "sa1.spikes": SPIKES, "cam.frame": FRAMES}[stream]
    assert out.t.dtype == want.t.dtype and out.data.dtype == want.data.dtype
    np.testing.assert_array_equal(out.t, want.t)
    np.testing.assert_array_equal(out.data, want.data)
    if stream == "sa1.spikes":
        assert out.end == 0.5  # watermark: nothing more before now


def test_event_chunks_carry_watermarks_even_when_empty(recording):
    path, _ = recording
    block = Replay(path=str(path), stream="sa1.spikes")
    block.bind({})
    first = block(0.0001)["y"]
    assert len(first) == 0 and first.end == 0.0001
    later = block(0.2)["y"]
    assert later.end == 0.2 and (later.t < 0.2).all() and len(later) > 0


@pytest.mark.parametrize("stream", ["force.f", "sa1.spikes"])
def test_loop_and_offset_are_chunking_invariant(recording, stream):
    path, _ = recording
    params = {"path": str(path), "stream": stream, "loop": True, "time_offset_s": -0.123}
    whole = run_source(Replay(**params), 1.7, tick_s=1.7)
    for tick in TICKS:
        assert_same(run_source(Replay(**params), 1.7, tick_s=tick), whole, f"tick={tick}")
        assert_same(run_source(Replay(**params), 1.7, tick_s=tick, empty_between=True), whole, f"tick={tick}")


def test_loop_continues_time_and_repeats_data(recording):
    path, written = recording
    out = run_source(Replay(path=str(path), stream="force.f", loop=True), 1.2, tick_s=0.05)["y"]
    w = written["force.f"]
    n = len(w)  # 500 samples: period 0.5 s
    assert len(out) == 1200
    np.testing.assert_array_equal(out.data[n : 2 * n], w.data)
    np.testing.assert_allclose(out.t[n : 2 * n], w.t + 0.5, rtol=0, atol=1e-12)
    assert np.all(np.diff(out.t) > 0)
    ev = run_source(Replay(path=str(path), stream="sa1.spikes", loop=True), 1.0, tick_s=0.1)["y"]
    s = written["sa1.spikes"]  # period = recorded duration 0.5 s (its end watermark)
    np.testing.assert_allclose(ev.t, np.concatenate([s.t, s.t + 0.5]), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(ev.data, np.concatenate([s.data, s.data]))


def test_time_offset_shifts_and_skips_before_zero(recording):
    path, written = recording
    w = written["force.f"]
    late = run_source(Replay(path=str(path), stream="force.f", time_offset_s=0.25), 0.5)["y"]
    np.testing.assert_array_equal(late.t, w.t[:250] + 0.25)
    early = Replay(path=str(path), stream="force.f", time_offset_s=-0.1)
    out = run_source(early, 0.5)["y"]
    np.testing.assert_array_equal(out.data, w.data[100:])
    np.testing.assert_array_equal(out.t, w.t[100:] - 0.1)
    assert early.counters == {"skipped_before_zero": 100}


def test_npz_with_and_without_t(tmp_path):
    p = tmp_path / "a.npz"
    t = np.arange(300) / 500.0
    data = np.arange(600, dtype=np.int16).reshape(300, 2)
    np.savez(p, t=t, data=data, other=np.ones(300))
    b = Replay(path=str(p), units="mN")
    out = run_source(b, 0.6, tick_s=0.01)["y"]
    assert b.output_specs["y"] == StreamSpec("int16", (2,), "mN", 500.0)
    np.testing.assert_array_equal(out.t, t)
    np.testing.assert_array_equal(out.data, data)
    one = run_source(Replay(path=str(p), stream="other"), 0.6)["y"]
    assert one.data.shape == (300,)

    q = tmp_path / "b.npz"
    np.savez(q, data=np.ones((10, 3)))
    out = run_source(Replay(path=str(q), rate_hz=100.0), 0.1)["y"]
    np.testing.assert_array_equal(out.t, np.arange(10) / 100.0)
    with pytest.raises(ConfigError, match=r"'rate_hz' is required: .*b\.npz has no 't' array"):
        Replay(path=str(q)).bind({})
    with pytest.raises(
        ConfigError, match=r"'stream' must name an array of .*a\.npz \(arrays: data, other, t\); got 'x'"
    ):
        Replay(path=str(p), stream="x").bind({})


def test_npz_data_is_read_at_reset_not_at_compile(tmp_path):
    p = tmp_path / "a.npz"
    np.savez(p, t=np.arange(5) / 10.0, data=np.ones((5, 2)))
    b = Replay(path=str(p))
    spec = b.specs({})["y"]  # header only
    assert spec.shape == (2,) and spec.rate_hz == 10.0
    assert b._src is None  # noqa: SLF001 — specs() keeps nothing: when loading happens is the test
    assert isinstance(b._inspect().data, tuple)  # noqa: SLF001 — inspecting reads the npz header only
    b.bind({})
    loaded = b._src.data  # noqa: SLF001 — as above
    assert isinstance(loaded, np.ndarray) and not loaded.flags.writeable


CSV = "t,fx,fy,fz\n0.000,1,2,3\n0.002,4,5,6\n0.004,7,8,9\n0.006,10,11,12\n"


def test_csv_columns_labels_and_rate(tmp_path):
    p = tmp_path / "f.csv"
    p.write_text(CSV)
    b = Replay(path=str(p), units="N")
    out = run_source(b, 0.01)["y"]
    assert b.output_specs["y"] == StreamSpec("float64", (3,), "N", 500.0, labels=("fx", "fy", "fz"))
    np.testing.assert_array_equal(out.t, [0.0, 0.002, 0.004, 0.006])
    np.testing.assert_array_equal(out.data[:, 2], [3, 6, 9, 12])
    two = Replay(path=str(p), stream=["fz", "fx"])
    out = run_source(two, 0.01)["y"]
    assert two.output_specs["y"].labels == ("fz", "fx")
    np.testing.assert_array_equal(out.data, [[3, 1], [6, 4], [9, 7], [12, 10]])
    single = Replay(path=str(p), stream="fy")
    out = run_source(single, 0.01)["y"]
    assert single.output_specs["y"].shape == () and single.output_specs["y"].units == "1"
    np.testing.assert_array_equal(out.data, [2, 5, 8, 11])
    semi = tmp_path / "g.csv"
    semi.write_text("# t; x\n0.0; 1.5\n0.1; 2.5\n")
    out = run_source(Replay(path=str(semi)), 0.2)["y"]
    np.testing.assert_array_equal(out.data, [[1.5], [2.5]])


def test_csv_errors(tmp_path):
    p = tmp_path / "f.csv"
    p.write_text(CSV)
    with pytest.raises(
        ConfigError,
        match=r"'stream' must name columns of .*f\.csv \(columns: t, fx, fy, fz\); got 'fzz' \(did you mean 'fz'\?\)",
    ):
        Replay(path=str(p), stream=["fx", "fzz"]).bind({})
    with pytest.raises(
        SpecError, match=r"rate_hz 1000 given, but the time stamps of .*f\.csv step at 500 Hz"
    ):
        Replay(path=str(p), rate_hz=1000.0).bind({})
    Replay(path=str(p), rate_hz=502.0).bind({})  # within 1 %
    no_t = tmp_path / "no_t.csv"
    no_t.write_text("time,x\n0,1\n")
    with pytest.raises(SpecError, match=r"no 't' column .*\(columns: time, x\); if 'time' is the time") as e:
        Replay(path=str(no_t)).bind({})
    assert e.value.where == (str(no_t), 1, 1)
    back = tmp_path / "back.csv"
    back.write_text("t,x\n0.0,1\n0.1,2\n0.05,3\n0.2,4\n")
    with pytest.raises(SpecError, match=r"time goes back: t = 0\.05 s after 0\.1 s") as e:
        Replay(path=str(back)).bind({})
    assert e.value.where == (str(back), 4, 1)
    ragged = tmp_path / "ragged.csv"
    ragged.write_text("t,x\n0.0,1\n0.1,x\n")
    with pytest.raises(SpecError, match="not a number in column 'x': 'x'") as e:
        Replay(path=str(ragged)).bind({})
    assert e.value.where == (str(ragged), 3, 5)


def test_h5_errors(recording, tmp_path):
    path, _ = recording
    with pytest.raises(ConfigError, match=r"replay: 'path' does not exist: .*nope\.h5"):
        Replay(path=str(tmp_path / "nope.h5")).bind({})
    with pytest.raises(
        ConfigError,
        match=r"'stream' must name a stream of .*run\.h5 \(available: force\.f, sa1\.spikes, cam\.frame\); got 'x\.y'",
    ):
        Replay(path=str(path), stream="x.y").bind({})
    with pytest.raises(ConfigError, match=r"'stream' is required: .*run\.h5 holds 3 streams"):
        Replay(path=str(path)).bind({})
    with pytest.raises(SpecError, match=r"units 'mN' given, but force\.f in .*run\.h5 is in 'N'"):
        Replay(path=str(path), stream="force.f", units="mN").bind({})
    with pytest.raises(SpecError, match=r"rate_hz 500 given, but force\.f in .* was recorded at 1000 Hz"):
        Replay(path=str(path), stream="force.f", rate_hz=500.0).bind({})
    with pytest.raises(SpecError, match="is an event stream"):
        Replay(path=str(path), stream="sa1.spikes", rate_hz=500.0).bind({})
    Replay(path=str(path), stream="force.f", units="N", rate_hz=1000.0).bind({})  # matching is fine
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"nothing")
    with pytest.raises(SpecError, match="not a readable HDF5 file") as e:
        Replay(path=str(junk)).bind({})
    assert e.value.where == (str(junk), 1, 1)  # located at the file


def test_h5_single_stream_needs_no_name_and_decreasing_t_is_caught(tmp_path):
    path = tmp_path / "one.h5"
    with Recorder(path, {"s.y": StreamSpec("float64", (), "V", 10.0)}, {}) as rec:
        rec.write("s.y", Chunk(np.array([0.0, 0.1, 0.2]), np.array([1.0, 2.0, 3.0])))
        rec.write("s.y", Chunk(np.array([0.15]), np.array([4.0])))
    with pytest.raises(SpecError, match=r"t decreases at sample 3"):
        Replay(path=str(path)).bind({})


def test_config_rules_and_cheap_construction():
    Replay(path="/no/such/file.h5")  # the file is only read when the graph is compiled
    with pytest.raises(ConfigError, match=r"'path' must name a \.h5, \.hdf5, \.npz, \.csv file"):
        Replay(path="data.txt")
    with pytest.raises(ConfigError, match=r"a list of columns is only for \.csv"):
        Replay(path="a.npz", stream=["x", "y"])
    with pytest.raises(ConfigError, match="at least one column"):
        Replay(path="a.csv", stream=[])
    with pytest.raises(ConfigError, match="'rate_hz' must be > 0"):
        Replay(path="a.csv", rate_hz=0.0)


def test_single_sample_needs_a_rate_and_loops_by_it(tmp_path):
    p = tmp_path / "e.npz"
    np.savez(p, t=np.array([0.0]), data=np.ones((1, 2)))
    with pytest.raises(ConfigError, match=r"'rate_hz' is required: the time stamps of .* give no rate"):
        Replay(path=str(p)).bind({})
    out = run_source(Replay(path=str(p), rate_hz=10.0, loop=True), 0.5)["y"]
    np.testing.assert_allclose(out.t, [0.0, 0.1, 0.2, 0.3, 0.4], rtol=0, atol=1e-12)


def test_cannot_loop_a_recording_of_no_length(tmp_path):
    path = tmp_path / "ev.h5"
    with Recorder(path, {"n.spikes": SPIKES}, {}) as rec:
        rec.write("n.spikes", Chunk(np.array([0.0]), np.array([1], np.int32), end=0.0))
    assert len(run_source(Replay(path=str(path)), 0.1)["y"]) == 1
    with pytest.raises(SpecError, match=r"cannot loop .*ev\.h5: its length is 0 s"):
        Replay(path=str(path), loop=True).bind({})


def test_close_releases_the_h5_file_and_open_reloads(recording):
    path, written = recording
    b = Replay(path=str(path), stream="force.f")
    b.bind({})
    b.close()
    assert b._src.h5_file is None  # noqa: SLF001 — whether the file handle is released is the test
    b.open()
    b.restart()
    np.testing.assert_array_equal(b(0.01)["y"].data, written["force.f"].data[:10])
    b.close()
