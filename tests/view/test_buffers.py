"""The view's bounded buffers and frames: what the graph side appends is bounded (drop-oldest),
and a frame carries what a plot can show, newest kept (issue 34, Deliver 2)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from flowtact.chunk import Chunk, StreamSpec
from flowtact.view.buffers import StreamBuffer, ViewBuffers
from flowtact.view.frames import MAX_EVENTS, MAX_POINTS, MAX_RATE_BARS, MAX_SIDE, FrameMaker
from flowtact.view.kinds import view_kind

FORCE = StreamSpec(shape=(3,), units="N", rate_hz=1000.0, labels=("Fx", "Fy", "Fz"))
SPIKES = StreamSpec(dtype="int64", events=True, n_units=20)


def _chunk(t0: int, n: int, spec: StreamSpec = FORCE) -> Chunk:
    t = (np.arange(t0, t0 + n) / 1000.0).astype(np.float64)
    data = np.repeat(np.arange(t0, t0 + n, dtype=np.float64)[:, None], spec.size, axis=1).reshape(
        n, *spec.shape
    )
    return Chunk(t, data)


def test_a_buffer_keeps_the_newest_samples_and_counts_the_dropped():
    buf = StreamBuffer(FORCE, max_samples=100)
    for k in range(7):
        buf.append(_chunk(30 * k, 30))  # 210 samples, 100 fit
    p = buf.take()
    assert p is not None and len(p.t) == 100 and p.dropped == 110
    np.testing.assert_array_equal(p.data[:, 0], np.arange(110, 210))  # the newest, in order
    assert buf.take() is None  # taken: nothing pending, not even time


def test_a_chunk_larger_than_the_buffer_is_cut_to_its_newest_samples():
    buf = StreamBuffer(FORCE, max_samples=10)
    buf.append(_chunk(0, 1000))
    p = buf.take()
    assert len(p.t) == 10 and p.dropped == 990 and p.data[0, 0] == 990


def test_an_appended_chunk_is_copied():
    buf = StreamBuffer(FORCE)
    c = _chunk(0, 5)
    buf.append(c)
    c.data[:] = -1  # the graph reuses its arrays
    assert buf.take().data.min() >= 0


def test_an_image_stream_keeps_only_its_latest_frame():
    spec = StreamSpec(dtype="uint8", shape=(3, 24, 32), units="DN", rate_hz=40.0)
    buf = StreamBuffer(spec)
    frames = np.arange(5 * 3 * 24 * 32, dtype=np.int64).reshape(5, 3, 24, 32).astype(np.uint8)
    buf.append(Chunk(np.arange(5) / 40.0, frames))
    p = buf.take()
    assert len(p.t) == 1 and p.t[0] == 4 / 40.0
    np.testing.assert_array_equal(p.data[0], frames[4])


def test_an_event_watermark_without_events_still_moves_time():
    bufs = ViewBuffers({"sa1.spikes": SPIKES})
    bufs.append("sa1.spikes", Chunk(np.empty(0), np.empty(0, np.int64), end=1.5))
    bufs.append("other.y", _chunk(0, 3))  # not viewed: ignored
    p = bufs.take()["sa1.spikes"]
    assert len(p.t) == 0 and p.end == 1.5


@pytest.mark.parametrize(
    ("spec", "kind"),
    [
        (FORCE, "lines"),
        (StreamSpec(), "lines"),
        (SPIKES, "raster"),
        (
            StreamSpec(shape=(3,), events=True, n_units=20, labels=("unit", "amplitude_ua", "width_us")),
            "raster",
        ),
        (StreamSpec(dtype="uint8", shape=(3, 240, 320), units="DN"), "image"),
        (StreamSpec(shape=(3, 3), units="rad", labels=tuple(f"a{i}" for i in range(9))), "lines"),
        (StreamSpec(categories=("strawberry", "bottle")), "categorical"),
    ],
)
def test_each_stream_is_drawn_as_what_it_is(spec, kind):
    assert view_kind(spec) == kind


def test_a_frame_decimates_to_what_a_plot_shows_keeping_the_newest():
    maker = FrameMaker({"force.f": FORCE})
    bufs = ViewBuffers({"force.f": FORCE})
    bufs.append("force.f", _chunk(0, 5000))
    f = maker.frame(bufs.take())
    s = f["streams"]["force.f"]
    assert len(s["t"]) == MAX_POINTS and len(s["y"]) == 3
    assert s["t"][-1] == 4.999 and s["y"][0][-1] == 4999.0 and s["t"][0] == 0.0
    assert np.all(np.diff(s["t"]) > 0)
    assert f["now"] == 4.999


def test_non_finite_values_become_null_json_a_browser_parses():
    maker = FrameMaker({"x.y": StreamSpec(units="V", rate_hz=10.0)})
    bufs = ViewBuffers(maker.specs)
    bufs.append("x.y", Chunk(np.array([0.0, 0.1, 0.2]), np.array([1.0, np.nan, np.inf])))
    text = json.dumps(maker.frame(bufs.take()), allow_nan=False)  # raises on NaN/Infinity
    assert json.loads(text)["streams"]["x.y"]["y"] == [[1.0, None, None]]


def test_raster_rates_are_spikes_per_unit_over_the_last_second():
    rng = np.random.default_rng(3)
    maker = FrameMaker({"sa1.spikes": SPIKES})
    bufs = ViewBuffers(maker.specs)
    t_all, u_all = [], []
    for k in range(40):  # 40 frames of 50 ms: 2 s of graph time
        t = np.sort(rng.uniform(k * 0.05, (k + 1) * 0.05, 300))
        u = rng.integers(0, 20, 300)
        t_all.append(t)
        u_all.append(u)
        bufs.append("sa1.spikes", Chunk(t, u, end=(k + 1) * 0.05))
        s = maker.frame(bufs.take())["streams"]["sa1.spikes"]
    assert len(s["t"]) == 300 and s["count"] == 300
    t, u = np.concatenate(t_all), np.concatenate(u_all)
    window = t > 2.0 - 1.0  # the oracle: count the last second's spikes by hand
    expected = np.bincount(u[window], minlength=20) / 1.0
    np.testing.assert_allclose(s["rates"], expected, rtol=1e-12)


def test_many_units_are_grouped_into_bars_of_mean_rate_and_spikes_capped():
    spec = StreamSpec(dtype="int64", events=True, n_units=1000)
    maker = FrameMaker({"hand.spikes": spec})
    bufs = ViewBuffers(maker.specs)
    u = np.repeat(np.arange(1000), 5)  # 5 spikes per unit in the first 0.5 s
    bufs.append("hand.spikes", Chunk(np.linspace(0, 0.5, len(u)), u, end=0.5))
    s = maker.frame(bufs.take())["streams"]["hand.spikes"]
    assert len(s["rates"]) <= MAX_RATE_BARS and len(s["u"]) == MAX_EVENTS and s["count"] == 5000
    np.testing.assert_allclose(s["rates"], 10.0)  # 5 spikes in 0.5 s, every unit, every group
    assert s["u"][-1] == 999  # the newest kept


def test_an_image_is_downsampled_and_scaled_to_bytes():
    spec = StreamSpec(shape=(300, 200), units="kPa", rate_hz=10.0)
    maker = FrameMaker({"skin.p": spec})
    bufs = ViewBuffers(maker.specs)
    img = np.linspace(-1.0, 3.0, 300 * 200).reshape(1, 300, 200)
    bufs.append("skin.p", Chunk(np.array([0.1]), img))
    s = maker.frame(bufs.take())["streams"]["skin.p"]
    assert max(s["h"], s["w"]) <= MAX_SIDE and s["tiles"] == 1 and not s["rgb"]
    assert (s["min"], s["max"]) == (-1.0, pytest.approx(img[0, ::3, ::3].max()))
    import base64

    px = np.frombuffer(base64.b64decode(s["pixels"]), np.uint8)
    assert px.size == s["h"] * s["w"] and px.min() == 0 and px.max() == 255


def test_a_categorical_frame_names_its_current_value():
    spec = StreamSpec(rate_hz=100.0, categories=("strawberry", "bottle"))
    maker = FrameMaker({"gripper.object": spec})
    bufs = ViewBuffers(maker.specs)
    bufs.append("gripper.object", Chunk(np.array([0.0, 0.01]), np.array([0.0, 1.0])))
    assert maker.frame(bufs.take())["streams"]["gripper.object"]["current"] == "bottle"
    assert maker.meta("teleop")["streams"][0]["categories"] == ["strawberry", "bottle"]
