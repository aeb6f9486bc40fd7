"""flowtact plot: each stream drawn as what it is, checked on the figure's own axes; bounded memory."""

import re
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from flowtact.chunk import Chunk, StreamSpec
from flowtact.cli import main
from flowtact.pictures.recording_figure import DPI, binned_rates, plot_recording, recording_figure
from flowtact.recording.hdf5 import Recorder

pytest.importorskip("matplotlib")

ROOT = __import__("pathlib").Path(__file__).resolve().parents[2]


def _axes(fig, name):
    """The time-axis panels of a stream (titles start with ``name —``)."""
    return [ax for ax in fig.get_axes() if ax.get_title(loc="left").startswith(f"{name} — ")]


def _one(fig, name, contains=""):
    found = [ax for ax in _axes(fig, name) if contains in ax.get_title(loc="left")]
    assert len(found) == 1, [ax.get_title(loc="left") for ax in fig.get_axes()]
    return found[0]


def _legend(ax):
    return [t.get_text() for t in ax.get_legend().get_texts()]


def _all_text(fig):
    texts = [fig.get_suptitle()]
    for sub in fig.subfigs:
        texts.append(sub.get_suptitle())
    for ax in fig.get_axes():
        texts += [ax.get_title(loc="left"), ax.get_title(), ax.get_xlabel(), ax.get_ylabel()]
        texts += [t.get_text() for t in ax.get_yticklabels()]
        if ax.get_legend():
            texts += _legend(ax)
    return texts


# -- a teleop recording made by the command line -----------------------------------------------


@pytest.fixture(scope="module")
def teleop(tmp_path_factory):
    """2 s of graphs/teleop.yaml on the in-process exoskeleton emulator, objects swapped each second."""
    path = tmp_path_factory.mktemp("teleop") / "teleop.h5"
    argv = [
        "run",
        str(ROOT / "graphs" / "teleop.yaml"),
        "--set",
        "exo.port=sim",
        "--set",
        "gripper.period_s=1",
    ]
    assert main([*argv, "--fast", "--inproc", "--duration", "2", "--record", str(path)]) == 0
    return path


def test_teleop_angles_are_nine_labelled_lines_in_rad(teleop):
    fig = recording_figure(teleop)
    ax = _one(fig, "exo.angles")
    assert len(ax.get_lines()) == 9
    fingers, joints = ("thumb", "index", "middle"), ("φ1", "φ2", "φ3")
    assert _legend(ax) == [f"{f} {j}" for f in fingers for j in joints]
    assert ax.get_ylabel() == "rad"
    assert "9 channels as lines, rad, 100 Hz" in ax.get_title(loc="left")
    y = np.array([line.get_ydata() for line in ax.get_lines()])
    assert y.shape[1] == 200 and np.ptp(y, axis=1).max() > 0.1  # the recorded angles, not a mean
    assert fig.get_axes()[0].get_xlim() == (0.0, 2.0) and "time [s]" in [
        a.get_xlabel() for a in fig.get_axes()
    ]


def test_teleop_categorical_object_is_steps_named_on_the_axis(teleop):
    ax = _one(teleop_fig := recording_figure(teleop), "gripper.object")
    assert [t.get_text() for t in ax.get_yticklabels()] == ["strawberry", "bottle"]
    (line,) = ax.get_lines()
    assert line.get_drawstyle() == "steps-post"
    assert set(np.unique(line.get_ydata())) == {0.0, 1.0}  # values, not a ramp
    assert line.get_xdata()[1] == pytest.approx(1.0, abs=0.011)  # the swap at 1 s
    assert "categorical (strawberry / bottle): steps, 1 change" in ax.get_title(loc="left")
    assert teleop_fig.get_suptitle() == "teleop.h5 — graph teleop"


def test_teleop_command_columns_get_their_own_units_and_us_is_written_micro(teleop):
    fig = recording_figure(teleop)
    engage = _one(fig, "control.cmd", "engage")
    deviation = _one(fig, "control.cmd", "deviation")
    assert deviation.get_ylabel() == "µs" and engage.get_ylabel() == "dimensionless"
    assert _legend(deviation) == ["thumb deviation", "index deviation", "middle deviation"]
    bare_us = [t for t in _all_text(fig) if re.search(r"\bus\b|_us\b", t)]
    assert not bare_us, bare_us


# -- a synthetic recording with every kind of stream ---------------------------------------------


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """1 s: forces, 2 labelled afferents, 30 units, pulses, a categorical state, 20 channels, frames."""
    path = tmp_path_factory.mktemp("plot") / "run.h5"
    streams = {
        "force.f": StreamSpec("float64", (3,), "N", 1000.0, labels=("Fx", "Fy", "Fz")),
        "aff.spikes": StreamSpec("int64", (), "1", None, events=True, n_units=2, labels=("SA1", "FA1")),
        "pop.spikes": StreamSpec("int64", (), "1", None, events=True, n_units=30),
        "stim.y": StreamSpec(
            "float64", (3,), "1", None, events=True, n_units=2, labels=("unit", "amplitude_ua", "width_us")
        ),
        "state.y": StreamSpec("float64", (), "1", 100.0, categories=("rest", "grasp", "hold")),
        "array.x": StreamSpec("float64", (20,), "mV", 100.0),
        "cam.frame": StreamSpec("uint8", (2, 12, 16), "DN", 40.0),
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
    t100 = np.arange(100) / 100.0
    with Recorder(path, streams, {"graph_name": "touch"}) as rec:
        rec.write("force.f", Chunk(t, f))
        rec.write("aff.spikes", Chunk(ev_t[order], ev_u, end=1.0))
        rec.write("pop.spikes", Chunk(pop_t, rng.integers(0, 30, 600), end=1.0))
        pulses = np.array([[0, 60.0, 200.0], [1, 40.0, 200.0], [0, 60.0, 200.0]])
        rec.write("stim.y", Chunk(np.array([0.2, 0.25, 0.5]), pulses, end=1.0))
        rec.write("state.y", Chunk(t100, np.select([t100 < 0.3, t100 < 0.6], [0.0, 1.0], 2.0)))
        rec.write("array.x", Chunk(t100, rng.normal(size=(100, 20))))
        frames = np.zeros((40, 2, 12, 16), np.uint8)
        frames[:, 1] = np.arange(40, dtype=np.uint8)[:, None, None] * 6  # camera 1 brightens
        rec.write("cam.frame", Chunk(np.arange(40) / 40.0, frames))
    return path


def test_every_kind_of_stream_is_drawn_as_what_it_is(recording, tmp_path):
    fig = recording_figure(recording)
    force = _one(fig, "force.f")
    assert _legend(force) == ["Fx", "Fy", "Fz"] and force.get_ylabel() == "N"

    raster = _one(fig, "aff.spikes", "raster")
    assert raster.get_title(loc="left") == "aff.spikes — spike raster: 103 spikes on 2 units"
    (ticks,) = raster.get_lines()
    assert ticks.get_marker() == "|" and sorted(set(ticks.get_ydata())) == [0, 1]
    assert [t.get_text() for t in raster.get_yticklabels()] == ["SA1", "FA1"]
    rate = _one(fig, "aff.spikes", "rate")
    assert rate.get_ylabel() == "1/s" and _legend(rate) == ["SA1", "FA1"]
    assert "population firing rate (mean over 30 units), 20 ms bins" in _one(
        fig, "pop.spikes", "rate"
    ).get_title(loc="left")

    pulses = _one(fig, "stim.y", "stimulation pulses")
    assert pulses.get_ylabel() == "µA"
    heights = sorted(seg[1][1] for c in pulses.collections for seg in c.get_segments())
    assert heights == [40.0, 60.0, 60.0]  # one stem per pulse, at its amplitude
    assert "3 pulses on 2 channels; widths 200 µs" in pulses.get_title(loc="left")
    assert _one(fig, "stim.y", "pulse raster").get_ylabel() == "channel"

    state = _one(fig, "state.y")
    assert [t.get_text() for t in state.get_yticklabels()] == ["rest", "grasp", "hold"]
    assert state.get_lines()[0].get_drawstyle() == "steps-post"

    heat = _one(fig, "array.x")
    assert "heat map of 20 channels" in heat.get_title(loc="left") and len(heat.get_images()) == 1

    strip = [sub for sub in fig.subfigs if sub.get_suptitle().startswith("cam.frame — ")]
    assert (
        len(strip) == 1
        and "8 of 40 frames (2×12×16) at evenly spaced times, 2 cameras" in strip[0].get_suptitle()
    )
    thumbs = [ax for ax in strip[0].get_axes() if ax.get_images()]
    assert len(thumbs) == 16  # 8 times × 2 cameras, each an image
    times = [float(ax.get_title()[4:-2]) for ax in thumbs if ax.get_title()]
    assert times == sorted(times) and times[0] == 0.0 and times[-1] == pytest.approx(0.975)
    brightest = thumbs[-1].get_images()[0].get_array()
    assert int(brightest.max()) == 39 * 6  # the last frame of camera 1, as recorded

    time_axes = [ax for ax in fig.get_axes() if ax not in strip[0].get_axes()]
    assert all(ax.get_xlim() == (0.0, 1.0) for ax in time_axes)  # one shared time axis

    out = plot_recording(recording, tmp_path / "sub" / "fig.png")
    import matplotlib.image

    img = matplotlib.image.imread(out)
    w, h = fig.get_size_inches()
    assert img.shape[:2] == (round(h * DPI), round(w * DPI))


def test_selected_streams_and_time_range(recording, tmp_path):
    fig = recording_figure(recording, streams=["aff.spikes"], t_range=(0.25, 0.5))
    axes = fig.get_axes()
    assert len(axes) == 2 and axes[0].get_xlim() == (0.25, 0.5)
    assert axes[0].get_title(loc="left") == "aff.spikes — spike raster: 28 spikes on 2 units"
    out = plot_recording(recording, tmp_path / "f.svg", streams=["force.f"], t_range=(0.1, None))
    assert out.read_text().lstrip().startswith("<?xml")
    with pytest.raises(KeyError, match=r"no stream 'nope' \(available: force\.f, aff\.spikes"):
        recording_figure(recording, streams=["nope"])
    with pytest.raises(ValueError, match="empty time range"):
        recording_figure(recording, t_range=(0.5, 0.5))


def test_cli_plot_and_its_usage_errors(recording, tmp_path, capsys):
    assert main(["plot", str(recording), "-o", str(tmp_path / "a.png")]) == 0
    assert (tmp_path / "a.png").stat().st_size > 10_000
    assert main(["plot", str(recording), "-o", str(tmp_path / "b.png"), "--streams", "nope"]) == 2
    assert "no stream 'nope'" in capsys.readouterr().err
    assert main(["plot", str(tmp_path / "missing.h5"), "-o", str(tmp_path / "c.png")]) == 2  # bad input


# -- the paper figure ------------------------------------------------------------------------------


def test_paper_figure_stacks_force_derivative_rasters_and_rates(tmp_path):
    path = tmp_path / "touch.h5"
    streams = {
        "force.f": StreamSpec("float64", (3,), "N", 1000.0, labels=("Fx", "Fy", "Fz")),
        "dforce.y": StreamSpec("float64", (3,), "N/s", 1000.0, labels=("Fx", "Fy", "Fz")),
        "sa1.spikes": StreamSpec("int64", (), "1", None, events=True, n_units=4),
        "fa1.spikes": StreamSpec("int64", (), "1", None, events=True, n_units=4),
        "sa1_stim.y": StreamSpec(
            "float64", (3,), "1", None, events=True, n_units=4, labels=("unit", "amplitude_ua", "width_us")
        ),
    }
    t = np.arange(1000) / 1000.0
    f = np.stack([0 * t, 0 * t, 0.12 + 0.2 * (t > 0.3)], axis=1)
    with Recorder(path, streams, {"graph_name": "touch"}) as rec:
        rec.write("force.f", Chunk(t, f))
        rec.write("dforce.y", Chunk(t, np.gradient(f, axis=0) * 1000))
        rec.write("sa1.spikes", Chunk(np.arange(0.3, 1.0, 0.01), np.arange(70) % 4, end=1.0))  # 25/s per unit
        rec.write("fa1.spikes", Chunk(np.array([0.3, 0.301]), np.array([0, 1]), end=1.0))
        rec.write("sa1_stim.y", Chunk(np.array([0.3]), np.array([[0, 60.0, 200.0]]), end=1.0))
    fig = recording_figure(path, figure="paper")
    axes = fig.get_axes()
    assert [ax.get_ylabel() for ax in axes] == [
        "force\n[N]",
        "dF/dt\n[N/s]",
        "SA1\nunit",
        "FA1\nunit",
        "rate [1/s]\n20 ms bins",
    ]
    assert len(axes[0].get_lines()) == 3 and _legend(axes[0]) == ["Fx", "Fy", "Fz"]
    assert len(axes[2].get_lines()[0].get_xdata()) == 70  # every SA1 spike, not the pulses
    sa1_rate = axes[4].patches[0].get_data()[0]
    assert sa1_rate[20:45].mean() == pytest.approx(25.0)  # mean over 4 units of 100 spikes/s
    assert _legend(axes[4]) == ["SA1 (mean of 4)", "FA1 (mean of 4)"]
    assert all(ax.get_xlim() == (0.0, 1.0) for ax in axes) and axes[-1].get_xlabel() == "time [s]"
    assert main(["plot", str(path), "--paper", "-o", str(tmp_path / "p.png")]) == 0


def test_paper_figure_refuses_a_recording_without_force_or_spikes(recording, tmp_path, capsys):
    with pytest.raises(
        ValueError, match=r"paper figure needs a spike event stream|paper figure needs a force"
    ):
        recording_figure(recording, streams=["force.f"], figure="paper")
    assert (
        main(["plot", str(recording), "--streams", "state.y", "--paper", "-o", str(tmp_path / "x.png")]) == 1
    )
    assert "the paper figure needs a force stream in N" in capsys.readouterr().err


# -- readers -------------------------------------------------------------------------------------


def test_envelope_and_change_points_read_block_by_block(tmp_path, monkeypatch):
    """Buckets cut across read blocks give the same min, max and mean as the whole array at once."""
    import flowtact.pictures.bounded_read as pr

    rng = np.random.default_rng(3)
    n = 50_003
    t = np.arange(n) / 1000.0
    y = rng.normal(size=(n, 2))
    y[12_345, 1] = 40.0  # a one-sample spike survives decimation
    y[777, 0] = np.nan
    state = np.repeat(np.arange(7) % 3, n // 7 + 1)[:n].astype(float)
    path = tmp_path / "r.h5"
    specs = {"x.y": StreamSpec("float64", (2,), "V", 1000.0), "s.y": StreamSpec("float64", (), "1", 1000.0)}
    with Recorder(path, specs, {}) as rec:
        rec.write("x.y", Chunk(t, y))
        rec.write("s.y", Chunk(t, state))
    monkeypatch.setattr(pr, "BLOCK_BYTES", 8 * 2 * 997)  # 997 rows per block: buckets straddle blocks
    f, src, _ = pr.open_recording(path)
    with f:
        i, j = pr.index_range(src["x.y"], 1.0, 41.0)
        assert (i, j) == (1000, 41_001)
        env = pr.sample_envelope(src["x.y"], i, j, buckets=100)
        assert env.y.shape == (200, 2) and env.per_point == 401
        b = ((np.arange(i, j) - i) * 100) // (j - i)
        for k in (0, 37, 99):
            rows = y[i:j][b == k]
            np.testing.assert_array_equal(env.y[2 * k], np.nanmin(rows, axis=0))
            np.testing.assert_array_equal(env.y[2 * k + 1], np.nanmax(rows, axis=0))
            np.testing.assert_allclose(env.mean[k], np.nanmean(rows, axis=0))
        assert env.y[:, 1].max() == 40.0
        ct, cv = pr.change_points(src["s.y"], 0, n)
        edges = np.flatnonzero(np.diff(state)) + 1
        np.testing.assert_array_equal(ct, np.r_[t[0], t[edges]])
        np.testing.assert_array_equal(cv, np.r_[state[0], state[edges]])
        assert pr.change_points(src["s.y"], 0, n, limit=3) is None


def test_binned_rates():
    t = np.array([0.0, 0.001, 0.019, 0.02, 0.05, 0.999])
    u = np.array([0, 1, 0, 0, 1, 1])
    starts, r = binned_rates(t, u, 2, 0.0, 1.0)
    assert len(starts) == 50 and r.shape == (50, 2)
    np.testing.assert_allclose(r[0], [100.0, 50.0])  # 2 and 1 spikes in 20 ms
    np.testing.assert_allclose(r[1], [50.0, 0.0])
    assert r.sum() * 0.02 == 6


def test_empty_and_non_finite_streams_say_so(tmp_path):
    path = tmp_path / "quiet.h5"
    specs = {
        "a.x": StreamSpec("float64", (3,), "N", 100.0),
        "b.spikes": StreamSpec("int64", (), "1", None, events=True, n_units=5),
        "c.y": StreamSpec("float64", (2,), "V", 10.0),
        "d.y": StreamSpec("float64", (), "1", 10.0, categories=("x", "y")),
    }
    with Recorder(path, specs, {}) as rec:
        y = np.full((5, 2), np.nan)
        y[:2, 0] = 1.0
        rec.write("c.y", Chunk(np.arange(5) / 10, y))
    fig = recording_figure(path)
    said = {ax.get_title(loc="left"): [t.get_text() for t in ax.texts] for ax in fig.get_axes()}
    assert said["a.x — 3 channels as lines, N, 100 Hz; no samples"] == ["no samples in this time range"]
    assert said["b.spikes — spike raster: 0 spikes on 5 units"] == ["no spikes in this time range"]
    assert "c.y — 2 channels as lines, V, 10 Hz; 8 NaN/inf values (gaps)" in said
    assert said["d.y — categorical (x / y): no samples"] == ["no samples in this time range"]


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


# -- memory ----------------------------------------------------------------------------------------

_PEAK = textwrap.dedent(
    """
    import sys
    from flowtact.pictures.recording_figure import plot_recording
    plot_recording(sys.argv[1], sys.argv[2])
    # VmHWM: this process's own peak (ru_maxrss would carry the parent's across fork + exec)
    status = open("/proc/self/status").read()
    print(int(status.split("VmHWM:")[1].split()[0]) // 1024)
    """
)


def _big_recording(path, n_frames, n_samples):
    """Frames of 3×240×320 uint8 (230 kB each), a 1 kHz 4-channel stream and 20-unit spikes."""
    specs = {
        "cam.frames": StreamSpec("uint8", (3, 240, 320), "DN", 40.0),
        "sensor.x": StreamSpec("float64", (4,), "N", 1000.0),
        "pop.spikes": StreamSpec("int64", (), "1", None, events=True, n_units=20),
    }
    tile = np.random.default_rng(1).integers(0, 200, (3, 240, 320), dtype=np.uint8)
    with Recorder(path, specs, {}, flush_interval_s=0) as rec:
        for k in range(0, n_frames, 200):
            m = min(200, n_frames - k)
            frames = np.broadcast_to(tile, (m, 3, 240, 320)) + (
                np.arange(k, k + m)[:, None, None, None] % 50
            ).astype(np.uint8)
            rec.write("cam.frames", Chunk((k + np.arange(m)) / 40.0, frames))
        span = n_frames / 40.0
        for k in range(0, n_samples, 1_000_000):
            m = min(1_000_000, n_samples - k)
            t = (k + np.arange(m)) * (span / n_samples)
            rec.write("sensor.x", Chunk(t, np.sin(t)[:, None] * np.arange(1, 5)))
            rec.write("pop.spikes", Chunk(t[::20], np.arange(len(t[::20])) % 20, end=float(t[-1])))
    return path


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads the peak RSS from /proc")
def test_plot_memory_is_bounded_whatever_the_file_size(tmp_path):
    """Peak RSS plotting a 1.3 GB recording (frames alone 1.1 GB) stays < 500 MB, as for a small one."""
    small = _big_recording(tmp_path / "small.h5", 200, 100_000)
    big = _big_recording(tmp_path / "big.h5", 4800, 4_000_000)
    assert big.stat().st_size > 1.2e9 and 4800 * 3 * 240 * 320 > 1e9
    peaks = []
    for rec in (small, big):
        out = subprocess.run(
            [sys.executable, "-c", _PEAK, str(rec), str(tmp_path / f"{rec.stem}.png")],
            capture_output=True,
            text=True,
            check=True,
        )
        peaks.append(int(out.stdout.split()[-1]))
    assert peaks[1] < 500, f"peak RSS {peaks[1]} MB plotting {big.stat().st_size / 1e9:.2f} GB"
    assert peaks[1] - peaks[0] < 80, f"peak RSS grew from {peaks[0]} to {peaks[1]} MB with the file"


def test_categories_are_stored_in_the_recording_and_cross_processes(recording):
    import h5py

    from flowtact.recording.hdf5 import stream_specs
    from flowtact.runtime.protocol import spec_from_wire, spec_to_wire

    with h5py.File(recording) as f:
        assert f["streams/state.y"].attrs["categories"] == '["rest", "grasp", "hold"]'
        assert f["streams/force.f"].attrs["categories"] == "null"
    spec = stream_specs(recording)["state.y"][0]
    assert spec.categories == ("rest", "grasp", "hold")
    assert spec_from_wire(spec_to_wire(spec)) == spec


def test_too_many_events_for_ticks_become_counts_that_add_up(recording, monkeypatch):
    import flowtact.pictures.panels as pp

    monkeypatch.setattr(pp, "MAX_EVENT_TICKS", 100)
    ax = _one(recording_figure(recording, streams=["pop.spikes"]), "pop.spikes", "raster")
    (img,) = ax.get_images()
    counts = img.get_array()
    assert counts.shape == (30, 1000) and counts.sum() == 600  # every spike, in its unit's row
    assert img.norm.vmin == 0 and img.norm.vmax == counts.max()
    assert ax.get_title(loc="left").startswith(
        "pop.spikes — spike raster as counts per 1 ms bin (white 0, black"
    )


def test_text_from_the_file_is_drawn_escaped_and_warns_nothing(tmp_path):
    esc = "\x1b]0;pwned\x07\x1b[2J"
    spec = StreamSpec(
        dtype="float64", shape=(2,), units=f"N{esc}", rate_hz=10.0, labels=(f"a{esc}", "$\\frac{")
    )
    cats = StreamSpec(dtype="int64", shape=(), units="1", rate_hz=10.0, categories=(f"x{esc}", "y"))
    path = tmp_path / "esc.h5"
    with Recorder(path, {f"s{esc}.y": spec, "c.k": cats}, {"graph_name": f"g{esc}"}) as rec:
        rec.write(f"s{esc}.y", Chunk(np.arange(5) / 10.0, np.ones((5, 2))))
        rec.write("c.k", Chunk(np.arange(5) / 10.0, np.array([0, 1, 0, 1, 0])))
    code = textwrap.dedent(
        f"""
        import warnings
        warnings.simplefilter("always")
        from flowtact.pictures.recording_figure import plot_recording
        plot_recording({str(path)!r}, {str(tmp_path / "esc.png")!r})
        """
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "\x1b" not in r.stderr and "\x07" not in r.stderr  # no glyph warning carries them raw
    fig = recording_figure(path)
    text = " ".join(_all_text(fig))
    assert "\x1b" not in text and "\x07" not in text
    assert "s\\x1b]0;pwned\\x07\\x1b[2J.y — " in text and "g\\x1b]0;pwned" in text


def test_a_blocks_own_event_stream_is_drawn_with_its_name_and_labels(tmp_path):
    """Events that are not spikes (a block's crossings) are called events, not spikes, and their
    unit labels name the raster rows and the rate lines, also when the block left n_units unset."""
    path = tmp_path / "events.h5"
    specs = {
        "det.crossings": StreamSpec("int64", (), "1", None, events=True, n_units=2, labels=("rise", "fall")),
        "det.marks": StreamSpec("int64", (), "1", None, events=True, labels=("up", "down", "flat")),
    }
    with Recorder(path, specs, {}) as rec:
        rec.write("det.crossings", Chunk(np.array([0.1, 0.2, 0.3]), np.array([0, 1, 0]), end=1.0))
        rec.write("det.marks", Chunk(np.array([0.1, 0.5]), np.array([2, 1]), end=1.0))
    fig = recording_figure(path)
    raster = _one(fig, "det.crossings", "raster")
    assert raster.get_title(loc="left") == "det.crossings — event raster: 3 events on 2 units"
    assert [t.get_text() for t in raster.get_yticklabels()] == ["rise", "fall"]
    rate = _one(fig, "det.crossings", "rate")
    assert rate.get_title(loc="left").startswith("det.crossings — event rate per unit")
    assert _legend(rate) == ["rise", "fall"]
    marks = _one(fig, "det.marks", "raster")  # no n_units: one row per label, none dropped
    assert [t.get_text() for t in marks.get_yticklabels()] == ["up", "down", "flat"]
    assert _legend(_one(fig, "det.marks", "rate")) == ["up", "down", "flat"]
    assert not [t for t in _all_text(fig) if "spike" in t or "firing" in t]


def test_a_posterior_over_26_letters_names_its_rows_by_letter(tmp_path):
    """The Braille decoder's posterior (26 labelled channels, more than the 24 always written out)
    is a heat map whose rows read a..z, not 0..25."""
    import string

    path = tmp_path / "post.h5"
    letters = tuple(string.ascii_lowercase)
    specs = {"decoder.posterior": StreamSpec("float64", (26,), "1", None, labels=letters)}
    rng = np.random.default_rng(0)
    with Recorder(path, specs, {}) as rec:
        p = rng.dirichlet(np.ones(26), size=30)
        rec.write("decoder.posterior", Chunk(np.arange(30) * 0.1, p, end=3.0))
    heat = _one(recording_figure(path), "decoder.posterior", "heat map")
    assert [t.get_text() for t in heat.get_yticklabels()] == list(letters)


# -- registered figures (entry-point group flowtact.figures) ---------------------------------------


def _toy_figure(figure_cls, sources, t0, t1):
    """A toy figure: one axis titled with the stream names it was given."""
    fig = figure_cls(figsize=(2, 2), dpi=50)
    ax = fig.subplots()
    ax.set_title(",".join(sorted(sources)))
    ax.set_xlim(t0, t1)
    return fig


@pytest.fixture
def toy_figure(monkeypatch):
    from importlib import metadata

    from flowtact.pictures.figures import GROUP

    real = metadata.entry_points

    def with_toy(*, group: str):
        toy = metadata.EntryPoint(name="toy", value=f"{__name__}:_toy_figure", group=GROUP)
        return [*real(group=group), toy] if group == GROUP else real(group=group)

    monkeypatch.setattr(metadata, "entry_points", with_toy)


@pytest.mark.usefixtures("toy_figure")
def test_a_registered_toy_figure_is_drawn_by_name(recording, tmp_path, capsys):
    fig = recording_figure(recording, streams=["force.f", "state.y"], figure="toy")
    assert fig.get_axes()[0].get_title() == "force.f,state.y"
    assert main(["plot", str(recording), "--figure", "toy", "-o", str(tmp_path / "t.png")]) == 0
    assert (tmp_path / "t.png").stat().st_size > 0
    with pytest.raises(SystemExit):
        main(["plot", "--help"])
    listed = " ".join(capsys.readouterr().out.split())
    assert "installed: paper: the compact paper-style touch/slip figure" in listed and "; toy: " in listed


def test_an_unknown_figure_is_a_usage_error_with_a_guess(recording, tmp_path, capsys):
    assert main(["plot", str(recording), "--figure", "papr", "-o", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert "--figure papr: no such figure (did you mean 'paper'?); registered figures: paper" in err
    assert not (tmp_path / "x.png").exists()
