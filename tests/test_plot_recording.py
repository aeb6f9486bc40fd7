"""flowtact plot: one figure per recording, panels per stream on a shared time axis."""

import sys

import numpy as np
import pytest

from flowtact.chunk import Chunk, StreamSpec
from flowtact.plot_recording import DPI, binned_rates, plot_recording, recording_figure
from flowtact.record import Recorder

pytest.importorskip("matplotlib")


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """1 s: forces (labelled), their derivative, 2 labelled afferents, 30 units, and frames."""
    path = tmp_path_factory.mktemp("plot") / "run.h5"
    streams = {
        "force.f": StreamSpec("float64", (3,), "N", 1000.0, labels=("Fx", "Fy", "Fz")),
        "dforce.y": StreamSpec("float64", (3,), "N/s", 1000.0),
        "aff.spikes": StreamSpec("int64", (), "1", None, events=True, n_units=2, labels=("SA1", "FA1")),
        "pop.spikes": StreamSpec("int64", (), "1", None, events=True, n_units=30),
        "cam.frame": StreamSpec("uint8", (12, 16), "1", 40.0),
    }
    t = np.arange(1000) / 1000.0
    f = np.stack([np.sin(2 * np.pi * t), np.cos(2 * np.pi * t), 0.12 + (t > 0.3) * 0.2], axis=1)
    rng = np.random.default_rng(0)
    sa1 = np.arange(0.0, 1.0, 0.01)  # 100 spikes/s
    fa1 = np.array([0.301, 0.305, 0.309])
    ev_t = np.concatenate([sa1, fa1])
    order = np.argsort(ev_t, kind="stable")
    ev_u = np.concatenate([np.zeros(len(sa1), int), np.ones(3, int)])[order]
    pop_t = np.sort(rng.uniform(0, 1, 600))
    with Recorder(path, streams, {"graph_name": "touch"}) as rec:
        rec.write("force.f", Chunk(t, f))
        rec.write("dforce.y", Chunk(t, np.gradient(f, axis=0) * 1000))
        rec.write("aff.spikes", Chunk(ev_t[order], ev_u, end=1.0))
        rec.write("pop.spikes", Chunk(pop_t, rng.integers(0, 30, 600), end=1.0))
        rec.write(
            "cam.frame", Chunk(np.arange(40) / 40.0, rng.integers(0, 256, (40, 12, 16), dtype=np.uint8))
        )
    return path


def test_png_has_a_panel_per_stream_and_two_per_event_stream(recording, tmp_path):
    fig = recording_figure(recording)
    axes = fig.get_axes()
    assert len(axes) == 7  # force, dforce, aff raster + rate, pop raster + rate, frames
    titles = [ax.get_title(loc="left") for ax in axes]
    assert titles[0] == "force.f [N]" and titles[1] == "dforce.y [N/s]"
    assert titles[2].startswith("aff.spikes: spikes (103 in view, 2 units)")
    assert titles[3] == "aff.spikes: firing rate, 20 ms bins"
    assert titles[6] == "cam.frame: mean intensity per frame"
    assert [t.get_text() for t in axes[0].get_legend().get_texts()] == ["Fx", "Fy", "Fz"]
    assert [t.get_text() for t in axes[2].get_yticklabels()] == ["SA1", "FA1"]
    assert [t.get_text() for t in axes[5].get_legend().get_texts()] == ["mean of 30 units"]
    assert all(ax.get_xlim() == (0.0, 1.0) for ax in axes)  # shared time axis
    assert axes[-1].get_xlabel() == "time [s]"

    out = plot_recording(recording, tmp_path / "sub" / "fig.png")
    assert out == tmp_path / "sub" / "fig.png" and out.stat().st_size > 10_000
    import matplotlib.image

    img = matplotlib.image.imread(out)
    w, h = fig.get_size_inches()
    assert img.shape[:2] == (round(h * DPI), round(w * DPI))


def test_selected_streams_and_time_range(recording, tmp_path):
    fig = recording_figure(recording, streams=["aff.spikes"], t_range=(0.25, 0.5))
    axes = fig.get_axes()
    assert len(axes) == 2 and axes[0].get_xlim() == (0.25, 0.5)
    assert axes[0].get_title(loc="left").startswith("aff.spikes: spikes (28 in view")
    out = plot_recording(recording, tmp_path / "f.svg", streams=["force.f"], t_range=(0.1, None))
    assert out.read_text().lstrip().startswith("<?xml")
    with pytest.raises(KeyError, match=r"no stream 'nope' \(available: force\.f, dforce\.y"):
        recording_figure(recording, streams=["nope"])
    with pytest.raises(ValueError, match="empty time range"):
        recording_figure(recording, t_range=(0.5, 0.5))


def test_binned_rates():
    t = np.array([0.0, 0.001, 0.019, 0.02, 0.05, 0.999])
    u = np.array([0, 1, 0, 0, 1, 1])
    starts, r = binned_rates(t, u, 2, 0.0, 1.0)
    assert len(starts) == 50 and r.shape == (50, 2)
    np.testing.assert_allclose(starts[:3], [0.0, 0.02, 0.04])
    np.testing.assert_allclose(r[0], [100.0, 50.0])  # 2 and 1 spikes in 20 ms
    np.testing.assert_allclose(r[1], [50.0, 0.0])
    np.testing.assert_allclose(r[2], [0.0, 50.0])
    np.testing.assert_allclose(r[49], [0.0, 50.0])
    assert r.sum() * 0.02 == 6


def test_incomplete_recording_is_flagged(tmp_path):
    path = tmp_path / "killed.h5"
    rec = Recorder(path, {"x.y": StreamSpec("float64", (), "V", 100.0)}, {}, flush_interval_s=3600)
    rec.write("x.y", Chunk(np.arange(50) / 100.0, np.arange(50.0)))
    rec.flush()  # never closed, as after a kill
    fig = recording_figure(path)
    assert "incomplete" in fig.get_suptitle()
    rec.close()


def test_missing_file_and_missing_matplotlib(tmp_path, monkeypatch):
    with pytest.raises(FileNotFoundError, match=r"recording not found: .*nope\.h5"):
        plot_recording(tmp_path / "nope.h5", tmp_path / "x.png")
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    with pytest.raises(ImportError, match=r"pip install 'flowtact\[plot\]'"):
        plot_recording(tmp_path / "nope.h5", tmp_path / "x.png")
