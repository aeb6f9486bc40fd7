"""Tests of blocks/teleop/grasp_sim.py: the simulated T-MO gripper and its objects, and a Python closed loop
with force_feedback that shows the thesis' Fig. 4.6 effect (a softer object spreads the deviations wider)."""

import doctest
import math

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from flowtact import BadDataError, Chunk, ConfigError, SpecError, StreamSpec
from flowtact.blocks.teleop.feedback import ForceFeedback
from flowtact.blocks.teleop.grasp_sim import GraspSim, object_index
from flowtact.testing import assert_same, run_offline

RATE = 100.0


def test_steady_force_is_stiffness_times_penetration_per_object():
    grip = np.tile([0.5, 0.6, 0.7], (1000, 1))  # 10 s: the strawberry, then the bottle (torque limit)
    out = run_offline(GraspSim(), grip=grip, rate_hz=RATE)
    f, obj = out["force"].data, out["object"].data
    assert_array_equal(obj, (np.arange(1000) >= 500).astype(float))
    assert_allclose(f[499], 4.0 * (np.array([0.5, 0.6, 0.7]) - 0.45), rtol=1e-9)
    assert_allclose(f[-1], np.minimum(40.0 * (np.array([0.5, 0.6, 0.7]) - 0.45), 6.0), rtol=1e-9)


def test_closure_follows_the_command_with_a_first_order_lag():
    n = 100
    t = np.cumsum(np.random.default_rng(0).uniform(0.007, 0.013, n))  # jittered stamps
    out = run_offline(
        GraspSim(contact=[0.0, 0.0, 0.0], stiffness_n=[1.0, 1.0], max_force_n=10.0, tau_s=0.2),
        grip=np.ones((n, 3)),
        t=t,
        rate_hz=RATE,
    )
    closure = 1.0 - np.exp(-(t - t[0] + 0.01) / 0.2)  # the first step is one nominal period
    assert_allclose(out["force"].data[:, 1], closure, rtol=1e-12)


def test_motor_stalls_at_max_force_and_releases_at_once():
    grip = np.r_[np.ones((200, 3)), np.zeros((50, 3))]
    out = run_offline(GraspSim(max_force_n=5.0, stiffness_n=[40.0, 40.0]), grip=grip, rate_hz=RATE)
    f = out["force"].data
    assert f.max() == pytest.approx(5.0) and (f <= 5.0).all()
    assert f[200, 0] < 5.0 and f[-1, 0] == 0.0  # no wind-up past the object: backs off on the next sample


def test_object_schedule_and_swap_time():
    t = np.array([0.0, 1.0, 1.99, 2.0, 4.0, 5.0, 7.0])
    assert_array_equal(object_index(t, 2, 5.0, 2.0), [0, 0, 0, 1, 1, 1, 0])
    assert_array_equal(object_index(t, 3, 2.0, 0.0), [0, 0, 0, 1, 2, 2, 0])
    with pytest.raises(ConfigError, match="swap_at_s"):
        GraspSim(period_s=2.0, swap_at_s=2.0)
    with pytest.raises(ConfigError, match="stiffness_n"):
        GraspSim(object_names=["a", "b", "c"])


def test_clipping_bad_data_and_specs():
    grip = np.array([[1.5, -0.2, 0.5], [np.nan, 0.5, 0.5]])
    with pytest.raises(BadDataError):
        run_offline(GraspSim(), grip=grip, rate_hz=RATE)
    block = GraspSim(on_bad_data="hold")
    out = run_offline(block, grip=grip, rate_hz=RATE)["force"].data
    assert np.isfinite(out).all() and block.counters["clipped"] == 2
    with pytest.raises(SpecError, match="'1'"):
        GraspSim().bind({"grip": StreamSpec(shape=(3,), units="rad", rate_hz=RATE)})
    block = GraspSim()
    block.bind({"grip": StreamSpec(shape=(3,), units="1", rate_hz=RATE)})
    out = block(grip=Chunk(np.array([0.0]), np.zeros((1, 3)), 0.005))
    assert out["force"].end == 0.005 and out["object"].end == 0.005


def test_chunking_invariance_with_damping_and_jitter():
    n = 700
    t = np.cumsum(np.random.default_rng(1).uniform(0.005, 0.015, n))
    grip = np.clip(np.sin(t)[:, None] * [0.8, 0.9, 1.0], 0, 1)
    block = GraspSim(damping_n_s=0.3, period_s=2.0, swap_at_s=1.0)
    whole = run_offline(block, grip=grip, t=t, rate_hz=RATE)
    for chunk in (1, 7, [3, 250, 1, 64]):
        assert_same(
            run_offline(
                GraspSim(damping_n_s=0.3, period_s=2.0, swap_at_s=1.0),
                grip=grip,
                t=t,
                rate_hz=RATE,
                chunk=chunk,
            ),
            whole,
        )
    assert whole["force"].data.max() > 0


# -- the emulated loop: Fig. 4.6 ---------------------------------------------------------------------


def closed_loop(duration_s=20.0, mode="variable"):
    """Simulated user + force_feedback + grasp_sim at 100 Hz, stepped one sample at a time.

    Per 5 s period (one object each, swapped while the hand is open): the hand opens for 0.5 s,
    closes freely until the controller engages on contact, then pushes with a force ramping to
    3 N over 2 s — the same user for both objects — and pulls back open at 3.5 s. While engaged
    the servo holds the finger at the contact position plus the commanded deviation
    (``GAMMA`` of gripper command per µs: MG90S ≈ π/2000 rad/µs, linkage ×1.5, closed at 3.2 rad).
    The target force is the gripper's true force one sample earlier (the loop delay).
    """
    gamma = math.pi / 2000 * 1.5 / 3.2
    dt = 1.0 / RATE
    fb = ForceFeedback(mode=mode)
    gs = GraspSim()
    fb.bind(
        {
            "target": StreamSpec(shape=(3,), units="N", rate_hz=RATE),
            "finger": StreamSpec(shape=(3,), units="N", rate_hz=RATE),
        }
    )
    gs.bind({"grip": StreamSpec(shape=(3,), units="1", rate_hz=RATE)})
    g = np.zeros(3)
    g_contact = np.zeros(3)
    engaged_since = np.full(3, np.nan)
    f_prev, t_prev = None, None
    rows = []
    for k in range(int(duration_s * RATE)):
        t = k * dt
        phase = t % 5.0
        target = (
            Chunk(np.array([t_prev]), f_prev[None], t + dt / 2)
            if f_prev is not None
            else Chunk(np.empty(0), np.empty((0, 3)), t + dt / 2)
        )
        push = np.where(
            np.isnan(engaged_since), 0.05, np.minimum(3.0, 1.5 * (t - np.nan_to_num(engaged_since)))
        )
        f_user = np.where(phase >= 3.5, -1.0, push)
        cmd = fb(target=target, finger=Chunk(np.array([t]), f_user[None], t + dt / 2))["cmd"]
        assert len(cmd) == 1 and cmd.t[0] == t
        eng, dev = cmd.data[0, :, 0] == 1.0, cmd.data[0, :, 1]
        newly = eng & np.isnan(engaged_since)
        g_contact[newly] = g[newly]
        engaged_since[newly] = t
        engaged_since[~eng] = np.nan
        if phase < 0.5 or phase >= 3.5:
            g = np.where(eng, g, np.maximum(g - 1.0 * dt, 0.0))
        else:
            g = np.where(eng, g_contact + dev * gamma, np.minimum(g + 0.5 * dt, 1.0))
        out = gs(grip=Chunk(np.array([t]), g[None], t + dt / 2))
        f_prev, t_prev = out["force"].data[0], t
        rows.append((t, out["object"].data[0], eng.copy(), dev.copy(), f_prev.copy()))
    return rows


def test_softer_object_gives_the_wider_deviation_spread_fig_4_6():
    rows = closed_loop()
    spread = {}
    for obj in (0.0, 1.0):  # 0 strawberry (soft), 1 bottle (firm)
        devs = np.concatenate([r[3][r[2]] for r in rows if r[1] == obj])
        assert len(devs) > 300  # engaged through two grasps of each object
        spread[obj] = (np.percentile(devs, 95) - np.percentile(devs, 5), devs.std())
    assert spread[0.0][0] > 2.0 * spread[1.0][0]
    assert spread[0.0][1] > 2.0 * spread[1.0][1]
    # each object was grasped and released in every period (engaged, then not)
    for p in range(4):
        eng = np.array([r[2].any() for r in rows if p * 5 <= r[0] < (p + 1) * 5])
        assert eng.any() and not eng[-60:].any()


def test_blocking_feedback_holds_every_object_at_contact():
    rows = closed_loop(duration_s=10.0, mode="blocking")
    devs = np.concatenate([r[3][r[2]] for r in rows])
    assert len(devs) > 300 and (devs == 0.0).all()


def test_docstring_examples():
    import flowtact.blocks.teleop.grasp_sim as module

    result = doctest.testmod(module, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted >= 3 and result.failed == 0
