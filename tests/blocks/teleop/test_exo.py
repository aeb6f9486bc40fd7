"""Tests of blocks/teleop/exo.py: fsr_force (eq. 3.10), exo_kinematics (eqs. 3.3–3.8), fingertip_force (eq. 3.9),
gripper_command (§3.2.3) of White 2023."""

import doctest
import math

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from flowtact import BadDataError, Chunk, ConfigError, SpecError, StreamSpec
from flowtact.blocks.teleop.exo import (
    EXO_A_MM,
    EXO_S_A_MM,
    EXO_ZETA_RAD,
    FINGER_MM,
    ExoKinematics,
    FingertipForce,
    FsrForce,
    GripperCommand,
    exo_forward,
    finger_forward,
    phi_from_theta,
)
from flowtact.errors import MisalignedError
from flowtact.testing import assert_same, run_offline

ADC = {"x": "ADC"}
RAD = {"phi": "rad"}


def random_poses(n, seed=0):
    """Finger poses in the working range: MCP −10…80°, PIP 0…100°, DIP ⅔ PIP; thumb MCP, IP."""
    rng = np.random.default_rng(seed)
    th = np.zeros((n, 3, 3))
    th[:, :, 0] = rng.uniform(-0.17, 1.4, (n, 3))
    th[:, :, 1] = rng.uniform(0.05, 1.75, (n, 3))
    th[:, 1:, 2] = th[:, 1:, 1] * 2 / 3 + rng.uniform(-0.1, 0.1, (n, 2))
    return th


# -- fsr_force ----------------------------------------------------------------------------------------


def eq310(r):
    return 0.6867 * np.exp(0.0023 * np.asarray(r, np.float64))


def test_fsr_eq_3_10_minus_rest_offset_of_20_readings():
    rng = np.random.default_rng(1)
    rest = 300 + rng.integers(-5, 6, (20, 3))
    push = np.array([[300.0, 500.0, 700.0], [250.0, 300.0, 1023.0]])
    r = np.vstack([rest, push]).astype(float)
    out = run_offline(FsrForce(), x=r, units=ADC)["y"]
    offset = eq310(rest).mean(axis=0)
    assert len(out) == 22
    assert_allclose(out.data, eq310(r) - offset, rtol=1e-12, atol=1e-12)
    assert_allclose(out.data[:20].mean(axis=0), 0.0, atol=1e-12)  # the rest readings come out tared
    assert out.data[-1, 0] < 0 < out.data[-2, 1]  # below rest: pulling open; above: pushing closed


def test_fsr_holds_back_until_the_offset_is_known():
    block = FsrForce()
    block.bind({"x": StreamSpec(shape=(3,), units="ADC", rate_hz=100.0)})
    r = np.full((25, 3), 300.0)
    t = np.arange(25) / 100.0
    sizes = []
    for i in range(25):
        out = block(x=Chunk(t[i : i + 1], r[i : i + 1], t[i] + 0.005))["y"]
        sizes.append(len(out))
        if i < 19:
            assert out.end == 0.0  # the watermark stays at the first held sample
    assert sizes == [0] * 19 + [20] + [1] * 5


def test_fsr_invert_short_stream_and_no_offset():
    r = np.array([[300.0, 300.0, 300.0], [400.0, 200.0, 300.0]])
    inv = run_offline(FsrForce(rest_readings=1, invert=True), x=r, units=ADC)["y"].data
    assert_allclose(inv[1], -(eq310(r[1]) - eq310(r[0])), rtol=1e-12)
    block = FsrForce(rest_readings=5)
    short = run_offline(block, x=r, units=ADC)["y"].data  # tared with the mean of what came, at flush
    assert_allclose(short, eq310(r) - eq310(r).mean(axis=0), rtol=1e-12, atol=1e-15)
    assert block.counters["rest_short"] == 1
    absolute = run_offline(FsrForce(rest_readings=0), x=r, units=ADC)["y"].data
    assert_allclose(absolute, eq310(r), rtol=1e-15)


def test_fsr_out_of_range_and_nonfinite_readings():
    r = np.full((6, 3), 300.0)
    r[3, 1] = 5000.0
    r[4, 2] = np.nan
    with pytest.raises(BadDataError, match="'x'"):
        run_offline(FsrForce(rest_readings=2), x=r, units=ADC)
    block = FsrForce(rest_readings=2, on_bad_data="drop")
    out = run_offline(block, x=r, units=ADC)["y"]
    assert len(out) == 4 and block.counters["out_of_range"] == 1 and block.counters["nonfinite_drop"] == 2
    held = run_offline(FsrForce(rest_readings=2, on_bad_data="hold"), x=r, units=ADC)["y"].data
    assert_array_equal(held, 0.0)


def test_fsr_spec_errors():
    with pytest.raises(SpecError, match="ADC"):
        FsrForce().bind({"x": StreamSpec(shape=(3,), units="N", rate_hz=100.0)})
    with pytest.raises(SpecError, match="shape"):
        FsrForce().bind({"x": StreamSpec(shape=(5,), units="ADC", rate_hz=100.0)})


# -- exo_kinematics ------------------------------------------------------------------------------------


def test_fk_eq_3_3_hand_computed():
    a = ((10.0, 20.0, 0.0), (10.0, 20.0, 5.0), (1.0, 1.0, 1.0))
    zeta = ((0.0, 0.0, 0.0), (math.pi / 2, 0.1, -0.1), (0.0, 0.0, 0.0))
    s_a = ((1.0, 2.0), (0.0, 0.0), (0.0, -1.0))
    phi = np.array([[[0.0, math.pi / 2, 9.9], [0.0, -math.pi / 2, math.pi / 2], [0.0, 0.0, 0.0]]])
    s_q, psi_sum = exo_forward(phi, a, zeta, s_a)
    # thumb: a3 = ψ3 = 0 whatever φ3 says: 10·[1, 0] + 20·[0, 1] + (1, 2)
    assert_allclose(s_q[0, 0], [11.0, 22.0], atol=1e-12)
    # index: ψ1 = π/2, ψ2 = −π/2 (ζ2 + ζ3 = 0), ψ3 = π/2: 10·[0, 1] + 20·[1, 0] + 5·[0, 1]
    assert_allclose(s_q[0, 1], [20.0, 15.0], atol=1e-12)
    assert_allclose(s_q[0, 2], [3.0, -1.0], atol=1e-12)
    assert_allclose(psi_sum[0], [math.pi / 2, math.pi / 2, 0.0], atol=1e-15)


def test_ik_recovers_the_finger_pose_the_exoskeleton_was_worn_on():
    theta = random_poses(400)
    theta[:, 0, 2] = 0.0  # the thumb has two joints
    block = ExoKinematics()
    out = run_offline(block, phi=phi_from_theta(theta), units=RAD, chunk=37)
    assert_allclose(out["theta"].data, theta, atol=1e-7)
    assert_allclose(out["s_q"].data, finger_forward(theta), atol=1e-9)
    assert block.counters.get("ik_out_of_reach", 0) == 0


def test_ik_equations_3_4_to_3_8_independently():
    """Rebuild the index finger from θ with the thesis' geometry: DIP from s_Q and the angle sum."""
    theta = random_poses(50, seed=3)
    out = run_offline(ExoKinematics(), phi=phi_from_theta(theta), units=RAD)
    th = out["theta"].data[:, 1]
    l1, l2, l3 = FINGER_MM[1]
    total = th.sum(axis=1)
    _, psi_sum = exo_forward(phi_from_theta(theta))
    assert_allclose(total, psi_sum[:, 1] - math.pi / 2, atol=1e-12)  # the right-angle attachment
    dip = out["s_q"].data[:, 1] - 0.5 * l3 * np.stack([np.cos(total), np.sin(total)], 1)  # eq. 3.4
    r2 = (dip**2).sum(axis=1)
    assert_allclose(r2, l1**2 + l2**2 - 2 * l1 * l2 * np.cos(math.pi - th[:, 1]), rtol=1e-9)  # eq. 3.5
    pip = l1 * np.stack([np.cos(th[:, 0]), np.sin(th[:, 0])], 1)
    assert_allclose(np.linalg.norm(dip - pip, axis=1), l2, rtol=1e-9)  # eq. 3.7: |DIP − PIP| = l2


def test_ik_unreachable_pose_is_clipped_finite_and_counted():
    phi = phi_from_theta(np.zeros((3, 3, 3)))
    phi[1, :, 0] += 1.5  # the servo arm swung far: s_Q out of the finger's reach
    block = ExoKinematics()
    out = run_offline(block, phi=phi, units=RAD)["theta"]
    assert np.isfinite(out.data).all()
    assert block.counters["ik_out_of_reach"] >= 1
    _, psi_sum = exo_forward(phi)
    assert_allclose(out.data[:, 1:].sum(axis=2), psi_sum[:, 1:] - math.pi / 2, atol=1e-12)


def test_only_demanded_outputs_and_watermark():
    block = ExoKinematics()
    block.bind({"phi": StreamSpec(shape=(3, 3), units="rad", rate_hz=100.0)}, demanded=frozenset({"s_q"}))
    out = block(phi=Chunk(np.array([0.0]), phi_from_theta(np.zeros((1, 3, 3))), 0.005))
    assert set(out) == {"s_q"} and out["s_q"].end == 0.005


def test_kinematics_config_and_spec_errors():
    with pytest.raises(ConfigError, match="exo_s_a_mm"):
        ExoKinematics(exo_s_a_mm=[[0.0, 0.0, 0.0]] * 3)
    with pytest.raises(ConfigError, match="finger_mm"):
        ExoKinematics(finger_mm=[[34.0, 23.0, 0.0], [0.0, 27.0, 18.0], [50.0, 32.0, 20.0]])
    with pytest.raises(SpecError, match="rad"):
        ExoKinematics().bind({"phi": StreamSpec(shape=(3, 3), units="deg", rate_hz=100.0)})
    assert (
        ExoKinematics().config.finger_mm,
        ExoKinematics().config.exo_a_mm,
        ExoKinematics().config.exo_zeta_rad,
        ExoKinematics().config.exo_s_a_mm,
    ) == (FINGER_MM, EXO_A_MM, EXO_ZETA_RAD, EXO_S_A_MM)


# -- fingertip_force -----------------------------------------------------------------------------------


def eq39(f_abs, psi_sum, a1):
    """Eq. 3.9 exactly as printed, for one finger."""
    alpha = math.pi - psi_sum
    tau1 = 0.02 * f_abs
    norm = math.hypot(-math.sin(alpha), -math.cos(alpha))
    return np.array([-f_abs, 0.0]) - tau1 / (a1 * 1e-3 * norm) * np.array([math.cos(alpha), math.sin(alpha)])


def test_fingertip_force_eq_3_9_as_printed_and_signed():
    theta = random_poses(30, seed=5)
    phi = phi_from_theta(theta)
    fsr = np.random.default_rng(2).uniform(-3, 3, (30, 3))
    out = run_offline(
        FingertipForce(), fsr=fsr, phi=phi, units={"fsr": "N", "phi": "rad"}, rate_hz=100.0, chunk=4
    )
    _, psi_sum = exo_forward(phi)
    for k in range(30):
        for i in range(3):
            v = eq39(abs(fsr[k, i]), psi_sum[k, i], EXO_A_MM[i][0])
            assert_allclose(out["f"].data[k, i], math.copysign(np.linalg.norm(v), fsr[k, i]), rtol=1e-12)
            assert_allclose(
                out["f_vec"].data[k, i], math.copysign(1.0, fsr[k, i]) * v, rtol=1e-12, atol=1e-14
            )


def test_fingertip_force_text_form_uses_a3_and_the_perpendicular_direction():
    phi = phi_from_theta(np.zeros((1, 3, 3)))  # fingers: Σψ = π/2, α = π/2: [−sin α, −cos α] = [−1, 0]
    out = run_offline(
        FingertipForce(form="text"), fsr=np.ones((1, 3)), phi=phi, units={"fsr": "N", "phi": "rad"}
    )["f"].data
    assert_allclose(out[0, 1:], 1.0 - 0.02 / 0.020, atol=1e-12)  # [−1 + 1, 0]: a3 = 20 mm cancels it


def test_fingertip_force_pairs_by_timestamp():
    spec = {
        "fsr": StreamSpec(shape=(3,), units="N", rate_hz=100.0),
        "phi": StreamSpec(shape=(3, 3), units="rad", rate_hz=100.0),
    }
    block = FingertipForce()
    block.bind(spec)
    phi = phi_from_theta(np.zeros((2, 3, 3)))
    out = block(
        fsr=Chunk(np.array([0.0, 0.01]), np.ones((2, 3)), 0.015), phi=Chunk(np.array([0.0]), phi[:1], 0.005)
    )
    assert len(out["f"]) == 1 and out["f"].end == 0.005  # the lower watermark
    with pytest.raises(MisalignedError):
        block(phi=Chunk(np.array([0.02]), phi[1:], 0.025))
    with pytest.raises(SpecError, match="Hz"):
        FingertipForce().bind({**spec, "phi": spec["phi"].with_(rate_hz=50.0)})


# -- gripper_command -----------------------------------------------------------------------------------


def test_gripper_command_scales_and_clips():
    theta = np.array(
        [
            [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [-0.2, 0.0, 0.0]],
            [[0.9, 0.0, 0.0], [1.0, 0.6, 0.0], [2.0, 2.0, 2.0]],
        ]
    )
    out = run_offline(
        GripperCommand(open_rad=[0.0, 0.0, 0.0], closed_rad=[1.8, 3.2, 3.2]), x=theta, units={"x": "rad"}
    )
    assert_allclose(out["y"].data, [[0.0, 0.0, 0.0], [0.5, 0.5, 1.0]], rtol=1e-15)
    rev = run_offline(
        GripperCommand(open_rad=[2.0, 2.0, 2.0], closed_rad=[0.0, 0.0, 0.0]), x=theta, units={"x": "rad"}
    )
    assert_allclose(rev["y"].data[1], [0.55, 0.2, 0.0], rtol=1e-12)


def test_gripper_command_from_the_kinematics_chain():
    theta = random_poses(100, seed=9)
    theta[:, 0, 2] = 0.0
    th = run_offline(ExoKinematics(), phi=phi_from_theta(theta), units=RAD)["theta"].data
    y = run_offline(GripperCommand(open_rad=[0.0, 0.0, 0.0]), x=th, units={"x": "rad"})["y"].data
    want = np.clip(theta.sum(axis=2) / np.array([1.8, 3.2, 3.2]), 0, 1)
    assert_allclose(y, want, atol=1e-7)


def test_gripper_command_config_errors():
    with pytest.raises(ConfigError, match="closed_rad"):
        GripperCommand(open_rad=[0.0, 1.0, 0.0], closed_rad=[1.0, 1.0, 1.0])
    with pytest.raises(ConfigError, match="open_rad"):
        GripperCommand(open_rad=[0.0, 1.0])


def test_kinematics_chunking_with_irregular_timestamps():
    theta = random_poses(200, seed=4)
    t = np.cumsum(np.random.default_rng(0).uniform(0.005, 0.015, 200))
    phi = phi_from_theta(theta)
    a = run_offline(ExoKinematics(), phi=phi, t=t, units=RAD)
    b = run_offline(ExoKinematics(), phi=phi, t=t, units=RAD, chunk=[1, 13, 2])
    assert_same(a, b)


def test_docstring_examples():
    import flowtact.blocks.teleop.exo as module

    result = doctest.testmod(module, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted >= 12 and result.failed == 0
