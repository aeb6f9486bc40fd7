"""Tests of blocks/teleop/feedback.py: force_feedback (White 2023 §3.2.2) — control, safety limits, stalls, fuzzing."""

import doctest

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose, assert_array_equal

from flowtact import Chunk, ConfigError, SpecError, StreamSpec, concat
from flowtact.blocks.teleop.feedback import GAIN_US_PER_N, ForceFeedback
from flowtact.testing import assert_same, run_offline

SPEC = {
    "target": StreamSpec(shape=(3,), units="N", rate_hz=40.0),
    "finger": StreamSpec(shape=(3,), units="N", rate_hz=100.0),
}
EMPTY = Chunk(np.empty(0), np.empty((0, 3, 2)))


def drive(block, target, finger, bounds, *, ends=True, lag=None):
    """Feed two (t, x) streams cut at the times ``bounds``; every chunk carries ``end`` = its bound.

    ``target`` or ``finger`` may be None (the input never delivers anything, not even a
    watermark). ``lag`` (port -> number of bounds) delivers that port's chunks late.
    """
    block.bind(SPEC)
    bounds = [float(b) for b in bounds]
    per_port = {}
    for p, s in (("target", target), ("finger", finger)):
        if s is None:
            continue
        t, x = s
        lo, chunks = -np.inf, []
        for b in bounds:
            sel = (t >= lo) & (t < b)
            chunks.append(Chunk(t[sel], x[sel], b if ends else None))
            lo = b
        k = (lag or {}).get(p, 0)
        per_port[p] = [Chunk(np.empty(0), np.empty((0, 3)))] * k + chunks
    outs = []
    for i in range(max(len(c) for c in per_port.values())):
        kw = {p: cs[i] for p, cs in per_port.items() if i < len(cs)}
        outs.append(block(**kw)["cmd"])
    outs.append(block.flush().get("cmd", EMPTY))
    return concat(outs)


def grasp(duration=3.0, contact_at=0.5, ft=1.0, ff=3.0):
    tt = np.arange(int(duration * 40)) / 40.0
    tf = np.arange(int(duration * 100)) / 100.0
    target = np.where(tt[:, None] > contact_at, ft, 0.0) * np.ones((1, 3))
    return (tt, target), (tf, np.full((len(tf), 3), ff))


BOUNDS = np.arange(1, 31) / 10.0


def assert_safe(out, cfg):
    """The safety contract on every row: finite, engage ∈ {0, 1}, limits, rate, increasing times."""
    d = out.data
    assert np.isfinite(d).all()
    assert np.isin(d[:, :, 0], (0.0, 1.0)).all()
    assert (d[:, :, 1] >= cfg.min_us).all() and (d[:, :, 1] <= cfg.max_us).all()
    assert (d[:, :, 1][d[:, :, 0] == 0.0] == 0.0).all(), "a disengaged finger must carry deviation 0"
    assert (np.diff(out.t) > 0).all()
    if len(out) > 1:
        dt = np.diff(out.t)[:, None]
        step = np.abs(np.diff(d[:, :, 1], axis=0))
        engaged_after = d[1:, :, 0] == 1.0
        allowed = cfg.max_rate_us_per_s * dt * (1 + 1e-12) + 1e-9
        assert (step[engaged_after] <= np.broadcast_to(allowed, step.shape)[engaged_after]).all()


# -- control -------------------------------------------------------------------------------------------


def test_variable_steady_state_is_k_times_force_difference_per_finger():
    target, finger = grasp(ft=1.0, ff=3.0)
    out = drive(ForceFeedback(), target, finger, BOUNDS)
    assert_array_equal(out.data[-1, :, 0], 1.0)
    # deviation = K·(F_f − F_T): the thumb's K is 80, index and middle 100
    assert_allclose(out.data[-1, :, 1], np.array(GAIN_US_PER_N) * 2.0, rtol=1e-12)
    assert GAIN_US_PER_N == (80.0, 100.0, 100.0)


def test_variable_sign_soft_push_lets_the_finger_advance_and_object_pushes_back():
    target, finger = grasp(ft=2.5, ff=1.0)  # the object pushes harder than the finger: negative
    out = drive(ForceFeedback(), target, finger, BOUNDS)
    assert_allclose(out.data[-1, :, 1], np.array(GAIN_US_PER_N) * -1.5, rtol=1e-12)


def test_blocking_engages_on_contact_and_releases_on_negative_finger_force():
    tt = np.arange(120) / 40.0
    tf = np.arange(300) / 100.0
    target = np.where((tt > 0.5)[:, None], 2.0, 0.1) * np.ones((1, 3))
    finger = np.where((tf > 2.0)[:, None], -0.3, 1.0) * np.ones((1, 3))
    out = drive(ForceFeedback(mode="blocking"), (tt, target), (tf, finger), BOUNDS)
    eng = out.data[:, :, 0]
    assert_array_equal(out.data[:, :, 1], 0.0)  # blocking: hold the contact position
    first = out.t[np.argmax(eng[:, 1] == 1.0)]
    assert first == pytest.approx(0.53)  # the first finger sample after the 0.525 s contact sample
    assert (eng[(out.t > 0.6) & (out.t <= 2.0)] == 1.0).all()
    assert (eng[out.t > 2.0] == 0.0).all()  # released, and not re-engaged while still in contact


def test_reengages_only_after_a_fresh_contact():
    tt = np.arange(160) / 40.0
    tf = np.arange(400) / 100.0
    ft = np.where((tt > 0.5) & ((tt < 2.2) | (tt > 2.8)), 2.0, 0.0)
    ff = np.where((tf > 1.5) & (tf < 1.7), -1.0, 1.0)
    target = ft[:, None] * np.ones((1, 3))
    finger = ff[:, None] * np.ones((1, 3))
    out = drive(ForceFeedback(mode="blocking"), (tt, target), (tf, finger), np.arange(1, 41) / 10.0)
    eng = out.data[:, 0, 0]
    assert (eng[(out.t > 1.5) & (out.t < 2.8)] == 0.0).all()  # finger back at 1 N but same contact
    assert (eng[out.t > 2.85] == 1.0).all()  # contact lost at 2.2 s, fresh contact at 2.8 s


def test_no_engage_when_loaded_at_start():
    target, finger = grasp(contact_at=-1.0)  # F_T above contact_n from the first sample
    out = drive(ForceFeedback(), target, finger, BOUNDS)
    assert_array_equal(out.data[:, :, 0], 0.0)


def test_clamp_and_rate_limit():
    target, finger = grasp(ft=1.0, ff=40.0)  # K·39 N = 3900 µs ≫ max_us
    cfg = dict(max_us=500.0, max_rate_us_per_s=1000.0)
    block = ForceFeedback(**cfg)
    out = drive(block, target, finger, BOUNDS)
    assert_safe(out, block.config)
    dev = out.data[:, 1, 1]
    on = out.t[np.argmax(out.data[:, 1, 0] == 1.0)]
    ramp = (out.t >= on) & (out.t < on + 0.4)  # from 0 at the row before the engage, at the limit
    assert_allclose(dev[ramp], 1000.0 * (out.t[ramp] - (on - 0.01)), atol=1e-9)
    assert dev[-1] == 500.0
    target, finger = grasp(ft=30.0, ff=0.5)
    out = drive(ForceFeedback(**cfg), target, finger, BOUNDS)
    assert out.data[-1, 1, 1] == -300.0


# -- stalls ------------------------------------------------------------------------------------------


def test_target_stall_disengages_within_stall_s_plus_one_sample_and_counts():
    (tt, target), finger = grasp()
    keep = tt < 1.5  # the camera dies; its watermark still advances
    block = ForceFeedback()
    out = drive(block, (tt[keep], target[keep]), finger, BOUNDS)
    last = tt[keep][-1]
    off = out.t[(out.t > 1.0) & (out.data[:, 1, 0] == 0.0)][0]
    assert last + 0.2 < off <= last + 0.2 + 0.01 + 1e-9
    assert (out.data[out.t >= off, :, 0] == 0.0).all()
    assert block.counters["stalled"] == 1 and block.counters["stalled_target"] == 1


def test_finger_stall_emits_a_disengaging_row_at_last_sample_plus_stall_s():
    target, (tf, finger) = grasp()
    keep = tf < 2.0  # the serial line is unplugged at 2 s; the camera keeps going
    block = ForceFeedback()
    out = drive(block, target, (tf[keep], finger[keep]), BOUNDS)
    assert out.data[-2, :, 0].tolist() == [1.0, 1.0, 1.0]
    assert_allclose(out.t[-1], tf[keep][-1] + 0.2)
    assert_array_equal(out.data[-1], 0.0)
    assert block.counters["stalled"] == 1 and block.counters["stalled_finger"] == 1


def test_finger_stall_is_seen_from_its_own_watermark_too():
    _, (tf, finger) = grasp()
    keep = tf < 2.0
    out = drive(ForceFeedback(), None, (tf[keep], finger[keep]), BOUNDS)  # no target at all
    assert len(out) == keep.sum() + 1 and out.t[-1] == pytest.approx(2.19)
    assert_array_equal(out.data[:, :, 0], 0.0)  # never engaged without a target


def test_resumes_after_a_finger_gap_and_needs_a_fresh_contact():
    target, (tf, finger) = grasp()
    keep = (tf < 1.5) | (tf > 2.0)
    out = drive(ForceFeedback(), target, (tf[keep], finger[keep]), BOUNDS)
    assert 1.69 in np.round(out.t, 9)  # the stall row
    assert (out.data[out.t > 1.6, :, 0] == 0.0).all()  # contact persists: no fresh contact


def test_frozen_target_watermark_does_not_hold_commands_forever():
    (tt, target), finger = grasp()
    block = ForceFeedback()
    block.bind(SPEC)
    outs = []
    lo = -np.inf
    for b in BOUNDS:  # the target chain stops delivering anything (not even watermarks) at 1.5 s
        sel_t = (tt >= lo) & (tt < b)
        sel_f = (finger[0] >= lo) & (finger[0] < b)
        kw = {"finger": Chunk(finger[0][sel_f], finger[1][sel_f], float(b))}
        if b <= 1.5:
            kw["target"] = Chunk(tt[sel_t], target[sel_t], float(b))
        outs.append(block(**kw)["cmd"])
        lo = b
    out = concat(outs)
    assert out.t[-1] > 2.9 - 0.05 - 1e-9  # rows keep coming, at most max_wait_s behind
    off = out.t[(out.t > 1.0) & (out.data[:, 0, 0] == 0.0)][0]
    assert off <= 1.475 + 0.2 + 0.01 + 1e-9
    assert block.counters["target_late"] > 0 and block.counters["stalled_target"] == 1


def test_nan_and_inf_are_missing_data_never_propagated():
    (tt, target), (tf, finger) = grasp()
    target = target.copy()
    finger = finger.copy()
    target[60:63, 0] = np.nan
    finger[150:155, 1] = np.inf
    finger[160, 2] = 1e300
    block = ForceFeedback()
    out = drive(block, (tt, target), (tf, finger), BOUNDS)
    assert_safe(out, block.config)
    assert (out.data[out.t > 1.0, :, 0] == 1.0).all()  # short gaps: no stall
    assert block.counters["nonfinite_target"] == 3
    assert block.counters["nonfinite_finger"] == 5
    assert block.counters["out_of_range_finger"] == 1


def test_chunking_invariance_multirate():
    (tt, target), (tf, finger) = grasp(duration=4.0)
    rng = np.random.default_rng(0)
    target = target + rng.normal(0, 0.2, target.shape)
    finger = finger * np.sin(tf)[:, None] * 2 + rng.normal(0, 0.2, finger.shape)
    ref = drive(ForceFeedback(), (tt, target), (tf, finger), [4.0])
    for bounds in (np.arange(1, 401) / 100.0, [*np.sort(rng.uniform(0, 4, 37)), 4.0]):
        assert_same({"c": drive(ForceFeedback(), (tt, target), (tf, finger), bounds)}, {"c": ref})
    assert ref.data[:, :, 0].any() and (ref.data[:, :, 0] == 0).any()


def test_lagging_target_within_max_wait_is_exact():
    (tt, target), (tf, finger) = grasp(duration=3.0)
    bounds = np.arange(1, 301) / 100.0
    ref = drive(ForceFeedback(), (tt, target), (tf, finger), bounds)
    late = drive(ForceFeedback(), (tt, target), (tf, finger), bounds, lag={"target": 3})
    assert_same({"c": late}, {"c": ref})  # 30 ms behind: paired by timestamps, not arrival


def test_output_watermark_never_passes_a_row_still_to_come():
    (tt, target), (tf, finger) = grasp()
    block = ForceFeedback()
    block.bind(SPEC)
    last_end, lo = -np.inf, -np.inf
    for b in np.arange(1, 31) / 10.0 - 0.013:  # the target's chunks lag 50 ms behind the finger's
        st_, sf = (tt >= lo - 0.05) & (tt < b - 0.05), (tf >= lo) & (tf < b)
        out = block(target=Chunk(tt[st_], target[st_], b - 0.05), finger=Chunk(tf[sf], finger[sf], b))["cmd"]
        assert not len(out) or out.t[0] >= last_end
        assert out.end is None or out.end >= last_end
        last_end = out.end if out.end is not None else last_end
        lo = b
    assert np.isfinite(last_end)


# -- fuzzing -----------------------------------------------------------------------------------------

_values = st.one_of(  # mostly plausible forces (so fingers engage), some garbage
    st.floats(-5.0, 12.0),
    st.floats(0.0, 5.0),
    st.floats(0.0, 5.0),
    st.sampled_from([np.nan, np.inf, -np.inf, 1e300, -1e300, 1e6, -40.0, 49.0]),
)


@st.composite
def streams(draw):
    def one(rate, n_max):
        n = draw(st.integers(0, n_max))
        gaps = draw(st.lists(st.one_of(st.just(1.0 / rate), st.floats(1e-4, 0.5)), min_size=n, max_size=n))
        t = np.cumsum(gaps) if n else np.empty(0)
        x = np.array(draw(st.lists(st.lists(_values, min_size=3, max_size=3), min_size=n, max_size=n)))
        return t, x.reshape(n, 3)

    target = one(40.0, 60)
    finger = one(100.0, 120)
    horizon = max([0.1, *(s[0][-1] for s in (target, finger) if len(s[0]))]) + 0.5
    cuts = sorted(draw(st.lists(st.floats(0.0, horizon), max_size=15)))
    lag = draw(st.sampled_from([None, {"target": 2}, {"finger": 3}]))
    ends = draw(st.booleans())  # with or without watermarks
    params = draw(
        st.fixed_dictionaries(
            {
                "mode": st.sampled_from(["blocking", "variable"]),
                "min_us": st.floats(-500.0, 0.0),
                "max_us": st.floats(1.0, 900.0),
                "max_rate_us_per_s": st.floats(10.0, 1e5),
                "stall_s": st.floats(0.05, 0.5),
                "contact_n": st.floats(0.0, 3.0),
                "release_n": st.floats(-1.0, 0.5),
            }
        )
    )
    return target, finger, [*cuts, horizon], lag, ends, params


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(streams())
def test_fuzzed_inputs_never_produce_a_command_outside_the_limits(case):
    target, finger, bounds, lag, ends, params = case
    block = ForceFeedback(**params, max_wait_s=min(0.05, params["stall_s"]))
    out = drive(block, target, finger, bounds, lag=lag, ends=ends)
    assert out.data.shape[1:] == (3, 2)
    assert_safe(out, block.config)


# -- config, specs, docs ----------------------------------------------------------------------------


def test_config_and_spec_errors():
    with pytest.raises(ConfigError, match="max_wait_s"):
        ForceFeedback(stall_s=0.1, max_wait_s=0.2)
    with pytest.raises(ConfigError, match="min_us"):
        ForceFeedback(min_us=10.0)
    with pytest.raises(ConfigError, match="gain_us_per_n"):
        ForceFeedback(gain_us_per_n=[100.0, 100.0])
    with pytest.raises(SpecError, match="'N'"):
        ForceFeedback().bind({**SPEC, "target": SPEC["target"].with_(units="mN")})
    with pytest.raises(SpecError, match="shape"):
        ForceFeedback().bind({**SPEC, "finger": SPEC["finger"].with_(shape=(5,))})


def test_run_offline_same_rate():
    n = 100
    out = run_offline(
        ForceFeedback(mode="blocking"),
        target=np.r_[np.zeros((10, 3)), np.ones((n - 10, 3))],
        finger=np.ones((n, 3)),
        rate_hz=100.0,
        units={"target": "N", "finger": "N"},
        chunk=7,
    )["cmd"]
    assert out.data.shape == (n, 3, 2) and out.data[-1, :, 0].tolist() == [1.0, 1.0, 1.0]


def test_docstring_examples():
    import flowtact.blocks.teleop.feedback as module

    result = doctest.testmod(module, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted >= 3 and result.failed == 0
