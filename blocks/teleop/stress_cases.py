"""Numerical stress cases for the teleop chain (issue 12, item 4): SSIM on uniform and saturated
images (against scikit-image, a test dependency imported only when a case runs), exoskeleton IK at
singular poses, out-of-range FSR readings through to the force-feedback command."""

from __future__ import annotations

import math
from functools import partial

import numpy as np

import flowtact.api as ft
from flowtact.testing import run_offline
from flowtact.verify.stress import EPS, Outcome, StressCase

from .exo import ExoKinematics, FingertipForce, FsrForce, GripperCommand, finger_forward, phi_from_theta
from .feedback import ForceFeedback, ForceFeedbackConfig
from .ssim import Ssim

__all__ = ["CASES"]

RATE = 100.0
_H, _W = 24, 32


def _textured(seed: int = 3) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (_H, _W), dtype=np.uint8)


def _uniform(v: int) -> np.ndarray:
    return np.full((_H, _W), v, np.uint8)


#: (name, reference, frame) pairs for the SSIM cases.
SSIM_PAIRS = {
    "uniform_same": [(_uniform(128), _uniform(128)), (_uniform(0), _uniform(0))],
    "uniform_different": [(_uniform(100), _uniform(150)), (_uniform(0), _uniform(255))],
    "saturated": [(_uniform(255), _uniform(255)), (_textured(), _uniform(255))],
    "uniform_ref_textured_frame": [(_uniform(128), _textured()), (_uniform(255), _textured(4))],
}


def ssim_case(name: str) -> Outcome:
    """The block (float64 and float32) on each pair of SSIM_PAIRS[name] against skimage's box-7 SSIM."""
    from skimage.metrics import structural_similarity

    errs = {"float64": 0.0, "float32": 0.0}
    values = []
    finite = True
    for ref, cur in SSIM_PAIRS[name]:
        want = structural_similarity(ref, cur, win_size=7, gaussian_weights=False, data_range=255)
        values.append(want)
        for prec in errs:
            y = run_offline(Ssim(precision=prec), x=np.stack([ref, cur]), rate_hz=40.0, units={"x": "DN"})[
                "y"
            ]
            finite &= bool(np.isfinite(y.data).all())
            errs[prec] = max(errs[prec], abs(float(y.data[1]) - want))
    ok = finite and errs["float64"] <= 1e-12 and errs["float32"] <= 1e-6
    return Outcome(
        name, "ssim", "; ".join(_describe(r, c) for r, c in SSIM_PAIRS[name]),
        "zero variance is regularised by C1, C2 exactly as scikit-image does: finite, equal values",
        "finite; |SSIM − skimage| ≤ 1e-12 (float64), ≤ 1e-6 (float32)", ok,
        f"skimage {', '.join(f'{v:.6g}' for v in values)}; error {errs['float64']:.1e} (f64), "
        f"{errs['float32']:.1e} (f32)",
        {"err64": errs["float64"], "err32": errs["float32"]},
    )  # fmt: skip


def _describe(ref: np.ndarray, cur: np.ndarray) -> str:
    def one(a: np.ndarray) -> str:
        return f"uniform {int(a.flat[0])}" if (a == a.flat[0]).all() else "textured"

    return f"ref {one(ref)} / frame {one(cur)}"


# -- inverse kinematics at singular poses ------------------------------------------------------------------

_FOLDED = np.array([[[0.3, np.pi, 0.0], [0.2, np.pi, 0.0], [0.2, np.pi, 0.0]]])
_EQUAL = ((30.0, 30.0, 0.0), (30.0, 30.0, 18.0), (30.0, 30.0, 20.0))  # l1 = l2: folded DIP sits on the MCP


def ik_pose(name: str) -> Outcome:
    """ExoKinematics on φ worn on a singular finger pose: stretched, folded, DIP coincident with MCP."""
    finger_mm = _EQUAL if name == "coincident" else None
    theta = np.zeros((1, 3, 3)) if name == "stretched" else _FOLDED
    kw = {} if finger_mm is None else {"finger_mm": finger_mm}
    blk = ExoKinematics(**kw)
    phi = phi_from_theta(theta, **kw)
    out = run_offline(blk, phi=phi, units={"phi": "rad"})["theta"].data
    finite = bool(np.isfinite(out).all())
    fk = finger_forward(out, **kw) - finger_forward(theta, **kw)
    sum_err = float(np.abs(out.sum(-1) - theta.sum(-1)).max())
    pos_err = float(np.abs(fk).max())
    ang_err = float(np.abs(out - theta).max())
    # arccos at ±1: a rounding δ ≈ few ε in the cosine becomes √(2δ) in the angle
    tol = 3 * math.sqrt(8 * EPS)
    if name == "coincident":
        crit = f"finite; same s_Q (FK of the answer, ≤ {tol * 60:.0e} mm) and Σθ (≤ {tol:.0e}); θ1 is arbitrary there"
        ok = finite and pos_err <= tol * 60 and sum_err <= tol
        what = (
            "θ1 is undetermined (any θ1 puts the DIP on the MCP): returns a valid pose, finite, not flagged"
        )
    else:
        crit = f"finite; |θ − θ_true| ≤ 3·√(8ε) = {tol:.1e} rad (arccos at ±1)"
        ok = finite and ang_err <= tol
        what = "arccos at ±1 clipped: finite, accurate to √ε (the singularity's conditioning)"
    return Outcome(
        name, "exo_kinematics", {"stretched": "all joints 0 (fully stretched)", "folded": "PIP = π (folded)",
                                 "coincident": "PIP = π with l1 = l2 (DIP on the MCP: r = 0)"}[name],
        what, crit, ok, f"|Δθ| = {ang_err:.1e} rad, |ΔΣθ| = {sum_err:.1e}, |Δs_Q| = {pos_err:.1e} mm; "
        f"counters {blk.counters}", {"ang_err": ang_err, "sum_err": sum_err, "pos_err": pos_err},
    )  # fmt: skip


def _feedback_chain(fsr_r: np.ndarray, phi: np.ndarray, policy: str) -> tuple[np.ndarray, dict[str, int]]:
    """FSR readings and φ → fsr_force → fingertip_force → force_feedback (target 1 N after 0.1 s)."""
    n = len(fsr_r)
    fsr_blk = FsrForce(on_bad_data=policy, rest_readings=5)
    fsr = run_offline(fsr_blk, x=fsr_r, rate_hz=RATE, units={"x": "ADC"})["y"]
    keep = np.isin(np.round(np.arange(n) / RATE, 9), np.round(fsr.t, 9))
    finger = run_offline(
        FingertipForce(), fsr=fsr.data, phi=phi[keep], t=fsr.t, units={"fsr": "N", "phi": "rad"}
    )["f"]
    target = np.where(np.arange(n)[:, None] >= 10, 1.0, 0.0) * np.ones((1, 3))
    fb = ForceFeedback()
    cmd = run_offline(
        fb, target=target[keep], finger=finger.data, t=finger.t, units={"target": "N", "finger": "N"}
    )
    counters = {
        **{f"fsr.{k}": v for k, v in fsr_blk.counters.items()},
        **{f"control.{k}": v for k, v in fb.counters.items()},
    }
    return cmd["cmd"].data, counters


def _cmd_safe(cmd: np.ndarray) -> bool:
    cfg = ForceFeedbackConfig()
    dev = cmd[..., 1]
    return bool(
        np.isfinite(cmd).all() and np.isin(cmd[..., 0], (0.0, 1.0)).all()
        and (dev >= cfg.min_us).all() and (dev <= cfg.max_us).all()
    )  # fmt: skip


def _grasp(n: int) -> tuple[np.ndarray, np.ndarray]:
    """A closing grasp: φ worn on it and FSR readings rising from a 300 rest to full scale (1023)."""
    g = np.clip((np.arange(n) - 10) / 50.0, 0.0, 1.0)
    theta = np.stack([np.outer(g, [0.8, 1.0, 0.0])] + [np.outer(g, [1.0, 1.3, 0.87])] * 2, axis=1)
    r = 300.0 + np.outer(g, [723.0, 723.0, 723.0])
    return phi_from_theta(theta), r


def fsr_out_of_range(policy: str) -> Outcome:
    """Readings −5, 2000 (> 1023), NaN and +inf into fsr_force, on to the feedback controller."""
    n = 150
    phi, r = _grasp(n)
    r[[40, 41, 80, 120], [0, 1, 2, 1]] = [-5.0, 2000.0, math.nan, math.inf]
    try:
        cmd, counters = _feedback_chain(r, phi, policy)
    except ft.BadDataError as e:
        return Outcome(
            f"fsr_bad_{policy}", "fsr_force → force_feedback", "readings −5, 2000, NaN, +inf", f"stops: “{e}”",
            "raise: clean one-line error", policy == "raise" and "\n" not in str(e),
        )  # fmt: skip
    counted = counters.get("fsr.out_of_range") == 3 and counters.get(f"fsr.nonfinite_{policy}") == 4
    safe = _cmd_safe(cmd)
    top = float(cmd[..., 1].max())
    return Outcome(
        f"fsr_bad_{policy}", "fsr_force → force_feedback", "readings −5, 2000, NaN, +inf during a full-scale grasp",
        f"fsr_force counts out_of_range (−5, 2000, +inf) and {policy}s all 4; the command stays "
        "finite and within its limits",
        "all counted; cmd finite, engage ∈ {0, 1}, deviation in [min_us, max_us]", counted and safe,
        f"max deviation {top:.0f} µs (max_us 600); counters {counters}", {"max_dev": top},
    )  # fmt: skip


def ik_unreachable() -> Outcome:
    """φ far outside the exoskeleton's range (±1e6 rad, NaN under hold): IK flags, gripper and
    feedback commands stay clamped."""
    n = 60
    rng = np.random.default_rng(2)
    phi = rng.uniform(-1e6, 1e6, (n, 3, 3))
    phi[30] = math.nan
    kin = ExoKinematics(on_bad_data="hold")
    theta = run_offline(kin, phi=phi, rate_hz=RATE, units={"phi": "rad"})["theta"]
    grip = run_offline(GripperCommand(), x=theta.data, rate_hz=RATE, units={"x": "rad"})["y"].data
    r = np.full((n, 3), 600.0)
    phi_ok = np.where(np.isfinite(phi), phi, 0.0)
    cmd, _ = _feedback_chain(r, phi_ok, "raise")
    ok = (
        bool(np.isfinite(theta.data).all()) and kin.counters.get("ik_out_of_reach", 0) > 0
        and kin.counters.get("nonfinite_hold") == 1 and bool(((grip >= 0) & (grip <= 1)).all()) and _cmd_safe(cmd)
    )  # fmt: skip
    return Outcome(
        "unreachable", "exo_kinematics → gripper_command, force_feedback",
        "φ uniform in ±1e6 rad, one NaN sample (hold)",
        "IK clips to the nearest reachable pose and counts it; θ finite; gripper command in [0, 1]; "
        "feedback command finite and clamped",
        "θ finite, counted; grip ∈ [0, 1]; cmd within limits", ok,
        f"ik_out_of_reach {kin.counters.get('ik_out_of_reach', 0)}/{n}; grip range "
        f"[{grip.min():.2f}, {grip.max():.2f}]; max |deviation| {np.abs(cmd[..., 1]).max():.0f} µs",
    )  # fmt: skip


def feedback_extreme() -> Outcome:
    """Fingertip forces of 49 N (in range, huge), 1e6 N and NaN straight into force_feedback."""
    n = 100
    target = np.where(np.arange(n)[:, None] >= 10, 1.0, 0.0) * np.ones((1, 3))
    finger = np.full((n, 3), 49.0)
    finger[50:60, 0] = 1e6
    finger[70:75, 1] = math.nan
    fb = ForceFeedback()
    cmd = run_offline(fb, target=target, finger=finger, rate_hz=RATE, units={"target": "N", "finger": "N"})[
        "cmd"
    ].data
    ok = (
        _cmd_safe(cmd)
        and fb.counters.get("out_of_range_finger") == 10
        and fb.counters.get("nonfinite_finger") == 5
    )
    return Outcome(
        "extreme_force", "force_feedback", "finger force 49 N (K·F ≫ max_us), 1e6 N and NaN",
        "49 N: deviation clamped at max_us (and rate-limited); 1e6 N and NaN: counted, ignored",
        "cmd finite, engage ∈ {0, 1}, deviation in [min_us, max_us]; bad samples counted", ok,
        f"max deviation {cmd[..., 1].max():.0f} µs; counters {fb.counters}", {"max_dev": float(cmd[..., 1].max())},
    )  # fmt: skip


CASES: tuple[StressCase, ...] = (
    *(StressCase(k, "ssim", partial(ssim_case, k)) for k in SSIM_PAIRS),
    *(StressCase(k, "exo_kinematics", partial(ik_pose, k)) for k in ("stretched", "folded", "coincident")),
    StressCase("unreachable", "exo_kinematics", ik_unreachable),
    StressCase("extreme_force", "force_feedback", feedback_extreme),
    *(
        StressCase(f"fsr_bad_{p}", "fsr_force", partial(fsr_out_of_range, p))
        for p in ("raise", "drop", "hold")
    ),
)
