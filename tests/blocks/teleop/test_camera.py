"""The camera source: image folders, video files, device errors, end of data, tick invariance."""

import numpy as np
import pytest

from flowtact import ConfigError
from flowtact.blocks.teleop.camera import Camera, CameraError
from flowtact.blocks.teleop.hand import FINGERS
from flowtact.blocks.teleop.tactip_sim import render, scenario_contacts
from flowtact.testing import assert_same, run_source

cv2 = pytest.importorskip("cv2")

N = 12


@pytest.fixture(scope="module")
def frames():
    """N emulated TacTip frame stacks (N, 3, 240, 320): rest, then taps."""
    t = np.arange(N) / 10.0
    truth = scenario_contacts({"onset_s": 0.1, "tap_period_s": 0.4, "tap_s": 0.3, "levels": 3}, 2, t)
    return render(truth.force, truth.position, np.arange(N), 2, shear=truth.shear, size=truth.size)


@pytest.fixture(scope="module")
def folders(frames, tmp_path_factory):
    root = tmp_path_factory.mktemp("folders")
    out = []
    for s, name in enumerate(FINGERS):
        d = root / name
        d.mkdir()
        for k in range(N):
            assert cv2.imwrite(str(d / f"img_{k:04d}.png"), frames[k, s])
        (d / "notes.txt").write_text("not an image: ignored")
        out.append(str(d))
    return out


@pytest.fixture(scope="module")
def videos(frames, tmp_path_factory):
    root = tmp_path_factory.mktemp("videos")
    out = []
    for s, name in enumerate(FINGERS):
        path = str(root / f"{name}.avi")
        w = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*"MJPG"), 40.0, (320, 240), isColor=False)
        assert w.isOpened()
        for k in range(N):
            w.write(frames[k, s])
        w.release()
        out.append(path)
    return out


def run(devices, duration, tick=0.1, **params):
    b = Camera(devices=devices, **params)
    try:
        return b, run_source(b, duration, tick_s=tick)
    finally:
        b.close()


def test_png_folders_read_back_exactly(frames, folders):
    b, out = run(folders, N / 40)
    assert np.array_equal(out["frames"].data, frames)
    assert np.array_equal(out["frames"].t, np.arange(N) / 40)
    np.testing.assert_allclose(out["device_t"].data, np.tile(np.arange(N)[:, None] / 40, (1, 3)))
    assert b.output_specs["device_t"].labels == FINGERS
    assert b.output_specs["frames"].shape == (3, 240, 320) and b.output_specs["frames"].units == "DN"


def test_mjpg_videos_read_back_within_codec_tolerance(frames, videos):
    _, out = run(videos, N / 40)
    got = out["frames"].data.astype(float)
    assert got.shape == frames.shape
    err = np.abs(got - frames)
    assert err.mean() < 2.5 and np.percentile(err, 99) < 12
    # the pins moved between frames: the video shows the same motion
    moved = np.abs(frames[-1].astype(float) - frames[0]).mean()
    assert np.abs(got[-1] - got[0]).mean() == pytest.approx(moved, rel=0.3)
    np.testing.assert_allclose(out["device_t"].data[:, 0], np.arange(N) / 40, atol=1e-6)


def test_end_of_files_stops_or_loops(folders, videos):
    for devices in (folders, videos):
        b, out = run(devices, 0.5)
        assert len(out["frames"]) == N and b.counters == {"ended": 1}
        assert out["frames"].end == 0.5  # the watermark still advances
        _, looped = run(devices, 0.5, loop=True)
        assert len(looped["frames"]) == 20
        assert np.array_equal(looped["frames"].data[N:], looped["frames"].data[: 20 - N])


def test_shortest_device_ends_every_sensor(frames, folders, tmp_path):
    short = tmp_path / "short"
    short.mkdir()
    for k in range(5):
        cv2.imwrite(str(short / f"{k}.png"), frames[k, 2])
    b, out = run([folders[0], folders[1], str(short)], 0.5)
    assert len(out["frames"]) == 5 and b.counters == {"ended": 1}
    assert np.array_equal(out["frames"].data[:, :2], frames[:5, :2])


@pytest.mark.parametrize("tick", [0.025, [0.013, 0.1, 0.0071, 0.25], 0.2])
def test_any_tick_pattern_gives_the_same_frames(folders, videos, tick):
    for devices in (folders, videos):
        _, whole = run(devices, 0.4, tick=0.4, loop=True)
        _, ticked = run(devices, 0.4, tick=tick, loop=True)
        assert_same(ticked, whole, f"tick={tick}")


def test_resize_and_colour(frames, tmp_path):
    small, colour = tmp_path / "small", tmp_path / "colour"
    small.mkdir()
    colour.mkdir()
    half = frames[:4, 0].reshape(4, 120, 2, 160, 2).mean(axis=(2, 4)).round().astype(np.uint8)
    for k in range(4):
        cv2.imwrite(str(small / f"{k}.png"), half[k])
        bgr = np.stack([frames[k, 1], frames[k, 1] // 2, 255 - frames[k, 1]], axis=-1)
        cv2.imwrite(str(colour / f"{k}.png"), bgr)
    b, out = run([str(small), str(colour)], 0.1)
    assert b.output_specs["frames"].shape == (2, 240, 320) and b.output_specs["device_t"].labels is None
    assert out["frames"].data.shape == (4, 2, 240, 320)
    up = out["frames"].data[:, 0].astype(float)
    assert np.abs(up - frames[:4, 0]).mean() < 3.0  # 2× down then up again: close to the original
    for k in range(4):
        bgr = cv2.imread(str(colour / f"{k}.png"), cv2.IMREAD_COLOR)
        assert np.abs(out["frames"].data[k, 1].astype(int) - cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)).max() <= 1
    # an output size equal to the files' size keeps them exactly
    _, same = run([str(small)], 0.1, size=[160, 120])
    assert np.array_equal(same["frames"].data[:, 0], half)


def test_one_sensor(folders, frames):
    _, out = run(folders[1:2], 0.1)
    assert out["frames"].data.shape == (4, 1, 240, 320)
    assert np.array_equal(out["frames"].data[:, 0], frames[:4, 1])


def test_missing_devices_fail_clearly_at_open(folders, tmp_path):
    b = Camera(devices=[folders[0], str(tmp_path / "nope.avi"), folders[2]])
    with pytest.raises(CameraError, match=r"sensor 1 \(index\).*nope\.avi.*tactip_sim"):
        b.open()
    assert b.sources == []
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(CameraError, match="no image files"):
        Camera(devices=[str(empty)]).open()
    with pytest.raises(CameraError, match=r"cannot open camera device 57.*tactip_sim"):
        Camera(devices=[57]).open()


def test_corrupt_image_and_stalled_device(frames, videos, tmp_path):
    bad = tmp_path / "bad"
    bad.mkdir()
    cv2.imwrite(str(bad / "0.png"), frames[0, 0])
    (bad / "1.png").write_bytes(b"not a png")
    with pytest.raises(CameraError, match=r"cannot read image .*1\.png"):
        run([str(bad)], 0.1)
    # a live device that stops delivering raises (emulated: a video treated as live, read past its end)
    b = Camera(devices=[videos[0]], fps=40.0)
    b.bind({})
    b.open()
    b.sources[0].live = True
    with pytest.raises(CameraError, match=r"stopped delivering frames after 12 frame"):
        b(1.0)
    b.close()


def test_reset_rewinds(folders, frames):
    b = Camera(devices=folders)
    b.bind({})
    b.open()
    first = b(0.1)["frames"].data
    b.restart()
    again = b(0.1)["frames"].data
    b.close()
    assert np.array_equal(first, again) and np.array_equal(first, frames[:4])


def test_config_rules():
    with pytest.raises(ConfigError, match="devices"):
        Camera(devices=[0, 1, 2, 3])
    with pytest.raises(ConfigError, match="devices"):
        Camera(devices=[])
    with pytest.raises(ConfigError, match="size"):
        Camera(size=[320])
    Camera(devices=["/dev/video0", 2, "clips/index.avi"])
