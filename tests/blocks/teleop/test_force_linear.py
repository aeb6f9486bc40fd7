"""Tests of blocks/teleop/force_linear.py: the SSIM→force line, its least-squares fit, and the fit from a recording."""

import doctest
import json

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

import flowtact.blocks.teleop.force_linear as force_linear_module
from flowtact import BadDataError, Chunk, ConfigError, SpecError, StreamSpec
from flowtact.blocks.teleop.fit_force import fit_from_recording, fit_linear_force, main
from flowtact.blocks.teleop.force_linear import LinearForce
from flowtact.blocks.teleop.hand import FINGERS
from flowtact.recording.hdf5 import Recorder
from flowtact.testing import run_offline

RATE = 40.0
SLOPE = (-18.0, -26.0, -13.5)
INTERCEPT = (15.5, 22.0, 11.0)


def ssim_series(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.uniform(0.65, 0.86, (n, 3))


# -- the fit ---------------------------------------------------------------------------------------


def test_fit_recovers_exact_coefficients():
    x = ssim_series(200)
    f = np.array(INTERCEPT) + np.array(SLOPE) * x
    slope, intercept, mae = fit_linear_force(x, f)
    assert_allclose(slope, SLOPE, rtol=1e-12)
    assert_allclose(intercept, INTERCEPT, rtol=1e-12)
    assert np.max(mae) < 1e-12


def test_fit_with_noise_matches_numpy_lstsq_and_reports_mae():
    rng = np.random.default_rng(1)
    x = ssim_series(3000, seed=1)
    f = np.array(INTERCEPT) + np.array(SLOPE) * x + rng.normal(0, 0.3, x.shape)
    slope, intercept, mae = fit_linear_force(x, f)
    for s in range(3):
        a = np.column_stack([np.ones(len(x)), x[:, s]])
        (b0, b1), *_ = np.linalg.lstsq(a, f[:, s], rcond=None)
        assert abs(slope[s] - b1) < 1e-9 and abs(intercept[s] - b0) < 1e-9
        assert abs(slope[s] - SLOPE[s]) < 1.0
        resid = f[:, s] - (intercept[s] + slope[s] * x[:, s])
        assert mae[s] == pytest.approx(np.mean(np.abs(resid)), rel=1e-12)
    assert_allclose(mae, 0.3 * np.sqrt(2 / np.pi), rtol=0.08)  # E|N(0, σ)| = σ·√(2/π)


def test_fit_skips_non_finite_pairs_and_rejects_degenerate_data():
    x = ssim_series(50)
    f = np.array(INTERCEPT) + np.array(SLOPE) * x
    x[3, 0], f[7, 1] = np.nan, np.inf
    slope, _, _ = fit_linear_force(x, f)
    assert_allclose(slope, SLOPE, rtol=1e-12)
    one, _, _ = fit_linear_force(x[:, 2], f[:, 2])  # 1-D: one sensor
    assert one == pytest.approx((SLOPE[2],))
    with pytest.raises(ValueError, match="constant"):
        fit_linear_force(np.full((10, 1), 0.8), np.arange(10.0)[:, None])
    with pytest.raises(ValueError, match="at least 2"):
        fit_linear_force(x[:1], f[:1])
    with pytest.raises(ValueError, match="shape"):
        fit_linear_force(x, f[:, :2])


# -- the block -------------------------------------------------------------------------------------


def test_block_applies_each_sensors_line_and_clips():
    x = ssim_series(100)
    x[0] = [0.99, 0.99, 0.99]  # beyond the undeformed SSIM: the lines go negative
    raw = np.array(INTERCEPT) + np.array(SLOPE) * x
    assert (raw[0] < 0).all()
    out = LinearForce(slope_n=list(SLOPE), intercept_n=list(INTERCEPT))
    y = run_offline(out, x=x, rate_hz=RATE, chunk=7)["y"]
    assert_allclose(y.data, np.maximum(raw, 0.0), rtol=1e-15, atol=0)
    assert_array_equal(y.data[0], [0.0, 0.0, 0.0])
    free = LinearForce(slope_n=list(SLOPE), intercept_n=list(INTERCEPT), clip_negative=False)
    assert_allclose(run_offline(free, x=x, rate_hz=RATE)["y"].data, raw, rtol=1e-15, atol=0)


def test_block_specs_and_broadcast():
    spec = StreamSpec(shape=(3,), units="1", rate_hz=RATE, labels=FINGERS)
    out = LinearForce().bind({"x": spec})["y"]
    assert (out.units, out.shape, out.labels, out.rate_hz) == ("N", (3,), FINGERS, RATE)
    with pytest.raises(SpecError, match="'1'"):
        LinearForce().bind({"x": spec.with_(units="N")})
    with pytest.raises(SpecError, match="2 sensors"):
        LinearForce().bind({"x": spec.with_(shape=(2,), labels=None)})
    with pytest.raises(ConfigError, match="intercept_n"):
        LinearForce(slope_n=[1.0, 2.0], intercept_n=[1.0, 2.0, 3.0])
    block = LinearForce(slope_n=[-10.0], intercept_n=[9.0])
    block.bind({"x": spec})
    y = block(x=Chunk(np.array([0.0]), np.array([[0.5, 0.6, 0.7]]), 0.025))["y"]
    assert_allclose(y.data, [[4.0, 3.0, 2.0]], rtol=1e-15)
    assert y.end == 0.025  # the watermark is passed on


def test_block_bad_data():
    x = ssim_series(5)
    x[2, 1] = np.nan
    with pytest.raises(BadDataError):
        run_offline(LinearForce(), x=x, rate_hz=RATE)
    block = LinearForce(on_bad_data="hold")
    y = run_offline(block, x=x, rate_hz=RATE)["y"].data
    assert np.isfinite(y).all() and y[2, 1] == y[1, 1]
    assert block.counters == {"nonfinite_hold": 1}


# -- the fit from a recording ----------------------------------------------------------------------


def write_recording(path, n=120, force_rate=80.0, noise=0.0, seed=0):
    rng = np.random.default_rng(seed)
    x = ssim_series(n, seed)
    t = np.arange(n) / RATE
    tf = np.arange(int(n * force_rate / RATE)) / force_rate  # a faster force stream
    xf = np.array([np.interp(tf, t, x[:, s]) for s in range(3)]).T
    force = np.array(INTERCEPT) + np.array(SLOPE) * xf + rng.normal(0, noise, xf.shape)
    specs = {
        "ssim.y": StreamSpec(shape=(3,), units="1", rate_hz=RATE, labels=FINGERS),
        "sim.force": StreamSpec(shape=(3,), units="N", rate_hz=force_rate, labels=FINGERS),
        "other.z": StreamSpec(shape=(), units="N", rate_hz=RATE),
    }
    with Recorder(path, specs, {"graph_yaml": ""}) as rec:
        for i in range(0, n, 16):  # written in several chunks
            rec.write("ssim.y", Chunk(t[i : i + 16], x[i : i + 16]))
        rec.write("sim.force", Chunk(tf, force))
        rec.write("other.z", Chunk(t, x[:, 0]))
    return x


def test_fit_from_recording_pairs_equal_times(tmp_path):
    path = tmp_path / "rec.h5"
    write_recording(path, n=120, force_rate=80.0)
    fit = fit_from_recording(path)
    assert fit["pairs"] == 120  # every SSIM sample has a force sample at the same time
    assert_allclose(fit["slope_n"], SLOPE, rtol=1e-10)
    assert_allclose(fit["intercept_n"], INTERCEPT, rtol=1e-10)
    assert max(fit["mae_n"]) < 1e-10
    assert fit["sensors"] == list(FINGERS)
    block = LinearForce(slope_n=fit["slope_n"], intercept_n=fit["intercept_n"])  # ready to use
    assert block.config.slope_n == tuple(fit["slope_n"])


def test_fit_from_recording_with_a_slower_force_stream(tmp_path):
    path = tmp_path / "rec.h5"
    x = write_recording(path, n=120, force_rate=20.0, noise=0.05, seed=3)
    fit = fit_from_recording(path)
    assert fit["pairs"] == 60  # only every other frame has a force sample at its time
    assert_allclose(fit["slope_n"], SLOPE, rtol=0.1)
    assert x.shape == (120, 3)


def test_fit_from_recording_errors(tmp_path):
    path = tmp_path / "rec.h5"
    write_recording(path)
    with pytest.raises(KeyError, match=r"no stream 'nope\.y'"):
        fit_from_recording(path, ssim_stream="nope.y")
    with pytest.raises(ValueError, match="units '1'"):
        fit_from_recording(path, ssim_stream="sim.force", force_stream="sim.force")
    with pytest.raises(ValueError, match="shape"):
        fit_from_recording(path, force_stream="other.z")


def test_fit_force_command(tmp_path, capsys):
    path = tmp_path / "rec.h5"
    write_recording(path)
    out = tmp_path / "fit.json"
    assert main([str(path), "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "120 (SSIM, force) pairs" in text and "slope_n: [-18, -26, -13.5]" in text
    assert "intercept_n: [15.5, 22, 11]" in text
    assert json.loads(out.read_text())["pairs"] == 120
    assert main([str(path), "--force", "nope.f"]) == 2  # a flag the recording cannot serve: usage
    assert "no stream 'nope.f'" in capsys.readouterr().err
    assert main([str(tmp_path / "missing.h5")]) == 2  # a missing input file: usage


def test_docstring_examples():
    assert doctest.testmod(force_linear_module, raise_on_error=True).failed == 0
