"""Numerical stress cases for ``nlif`` (issue 12, item 4): extreme τ, extreme drives, NaN/inf, long runs.

Each function runs the real block and returns a :class:`flowtact.verify.stress.Outcome`; ``CASES`` lists
them for the tests (tests/blocks/spiking/test_nlif_stress.py), the outcome table
(scripts/stress_outcomes.py) and the benchmark suite.
"""

from __future__ import annotations

import math
from functools import partial

import numpy as np

import flowtact.api as ft
from flowtact.testing import run_offline
from flowtact.verify.stress import EPS, Outcome, StressCase

from .naive_bayes_stress import CASES as NAIVE_BAYES_STRESS
from .nlif import Nlif

__all__ = ["CASES", "long_run"]

INTEGRATORS = ("exp", "euler", "exp_interp")
DT = 1e-3
RATE = 1.0 / DT


def _closed_form(u: float, tau: float, t: np.ndarray) -> np.ndarray:
    """Threshold-free membrane from v(0) = 0 under a constant drive: u·(1 − e^(−t/τ))."""
    return -u * np.expm1(-t / tau)


def _run(integrator: str, tau: float, u: float, n_steps: int = 1000, **kw: object) -> dict[str, ft.Chunk]:
    return run_offline(Nlif(n=2, tau_s=tau, integrator=integrator, **kw), x=np.full(n_steps, u), chunk=333)


# -- τ ≪ dt ---------------------------------------------------------------------------------------


def tau_tiny(integrator: str) -> Outcome:
    """τ = 1e-6 s at dt = 1 ms (dt/τ = 1000): subthreshold (u = 0.5) and suprathreshold (u = 2) drives."""
    cond = f"τ = 1e-6 s, dt = 1 ms, u = 0.5 and 2, {integrator}"
    if integrator == "euler":
        try:
            _run(integrator, 1e-6, 0.5)
        except ft.SpecError as e:
            msg = str(e)
            clean = "euler is unstable" in msg and "\n" not in msg
            return Outcome(
                f"tau_tiny_{integrator}", "nlif", cond, f"refused at bind: “{msg}”",
                "clean one-line refusal (dt ≥ 2τ)", clean,
            )  # fmt: skip
        return Outcome(f"tau_tiny_{integrator}", "nlif", cond, "ran (not refused)", "refused", False)
    sub = _run(integrator, 1e-6, 0.5)
    sup = _run(integrator, 1e-6, 2.0)
    v_err = float(np.abs(sub["v"].data[1:] - 0.5).max())  # v → u in one step (e^(−1000) = 0)
    n_sub, n_sup = len(sub["spikes"]), len(sup["spikes"])
    finite = bool(np.isfinite(sup["v"].data).all())
    ok = n_sub == 0 and v_err <= 2 * EPS * 0.5 and n_sup == 2 * 1000 and finite
    return Outcome(
        f"tau_tiny_{integrator}", "nlif", cond,
        "exact step: v jumps to u in one step; u = 2 fires once per step (rate 1/dt: the model's "
        "ceiling without a refractory period)"
        + ("; at most one spike per step, so the reported v may sit above threshold (= u)" if integrator == "exp_interp" else ""),
        "no spike and |v − u| ≤ 2ε·u for u = 0.5; one spike per neuron per step for u = 2; v finite",
        ok, f"|v − u| = {v_err:.1e}; spikes {n_sub} / {n_sup} (of 2000 steps·neurons)",
        {"v_err": v_err, "spikes_sub": n_sub, "spikes_sup": n_sup},
    )  # fmt: skip


# -- τ ≫ run length ---------------------------------------------------------------------------------


def tau_huge(integrator: str) -> Outcome:
    """τ = 1e6 s over a 1 s run, u = 1.5: v(t) = 1.5·(1 − e^(−t/τ)) ≈ 1.5e-6·t, far below threshold."""
    tau, u = 1e6, 1.5
    out = _run(integrator, tau, u)
    v = out["v"].data[:, 0]
    ref = _closed_form(u, tau, out["v"].t)
    rel = float(np.abs(v[1:] - ref[1:]).max() / np.abs(ref[1:]).max())
    # exp is exact for held input (rounding only: ~ steps·ε); euler errs by dt/(2τ) per unit (first order)
    bound = 1000 * 4 * EPS if integrator != "euler" else DT / tau
    ok = len(out["spikes"]) == 0 and rel <= bound
    return Outcome(
        f"tau_huge_{integrator}", "nlif", f"τ = 1e6 s, 1 s run, u = 1.5, {integrator}",
        "integrates the tiny slope; no stagnation in float64 (increment ≈ 1.5e-9 per step)",
        f"no spike; max rel. error vs 1.5·(1−e^(−t/τ)) ≤ {bound:.1e}"
        + (" (first order: dt/τ)" if integrator == "euler" else " (steps·4ε)"),
        ok, f"rel. error {rel:.1e}", {"rel_err": rel},
    )  # fmt: skip


# -- extreme drives ------------------------------------------------------------------------------------


def drive_extreme(u: float) -> Outcome:
    """Drive of 1e6 (fires at its ceiling) or 1e-12 (v must follow it to relative accuracy), exp."""
    tau = 0.01
    rows = []
    ok = True
    errs: dict[str, float] = {}
    for integ in INTEGRATORS:
        out = _run(integ, tau, u)
        v = out["v"].data
        finite = bool(np.isfinite(v).all())
        if u < 1:
            ref = _closed_form(u, tau, out["v"].t)[:, None]
            scale = 40 * EPS if integ != "euler" else 0.06  # euler at dt/τ = 0.1: ~5 % transient error
            rel = float(np.abs(v - ref).max() / u)
            good = finite and len(out["spikes"]) == 0 and rel <= scale
            errs[integ] = rel
            rows.append(f"{integ}: rel. err {rel:.1e}")
        else:
            n_spk = len(out["spikes"])
            capped = run_offline(
                Nlif(n=2, tau_s=tau, integrator=integ, refractory_s=0.0035), x=np.full(1000, u), chunk=333
            )
            cs = capped["spikes"]
            isi = min(float(np.diff(cs.t[cs.data == k]).min()) for k in (0, 1))
            good = finite and n_spk == 2000 and isi >= 0.0035 - 1e-12
            errs[integ] = isi
            rows.append(f"{integ}: {n_spk} spikes; min ISI {isi * 1e3:.3g} ms with 3.5 ms refractory")
        ok &= good
    if u < 1:
        what = "v follows u·(1−e^(−t/τ)) at 1e-12 scale (no underflow, no spike)"
        crit = "relative error ≤ 40ε (exp, exp_interp), ≤ 6 % (euler's own transient error)"
    else:
        what = "fires once per step (1/dt) with v finite; a refractory period caps the rate"
        crit = "2000 spikes / 2000 neuron-steps; with refractory_s = 3.5 ms every ISI ≥ 3.5 ms"
    return Outcome(
        f"drive_{u:g}", "nlif", f"constant drive u = {u:g}, τ = 10 ms, all integrators", what, crit, ok,
        "; ".join(rows), errs,
    )  # fmt: skip


# -- NaN / inf ------------------------------------------------------------------------------------------


def bad_samples(policy: str) -> Outcome:
    """One NaN, +inf and −inf sample each into a suprathreshold drive, for every integrator."""
    ok = True
    notes = []
    for integ in INTEGRATORS:
        for bad in (math.nan, math.inf, -math.inf):
            x = np.full(200, 1.5)
            x[100] = bad
            blk = Nlif(n=2, integrator=integ, on_bad_data=policy)
            try:
                out = run_offline(blk, x=x, chunk=7)
            except ft.BadDataError as e:
                ok &= policy == "raise" and "non-finite" in str(e) and "\n" not in str(e)
                continue
            v, spk = out["v"], out["spikes"]
            finite = bool(np.isfinite(v.data).all() and np.isfinite(spk.t).all())
            counted = blk.counters.get(f"nonfinite_{policy}", 0) == 1
            n_v = len(v) == (199 if policy == "drop" else 200)
            alive = bool((spk.t > 0.101).any())  # still firing after the bad sample
            ok &= policy != "raise" and finite and counted and n_v and alive
            if not (finite and counted and n_v and alive):
                notes.append(f"{integ} {bad}: finite={finite} counted={counted} alive={alive}")
    what = {
        "raise": "stops with BadDataError naming node, port and time",
        "drop": "removes the sample (one step skipped), counts nonfinite_drop; v finite, keeps firing",
        "hold": "repeats the last finite drive, counts nonfinite_hold; v finite, keeps firing",
    }[policy]
    return Outcome(
        f"nonfinite_{policy}", "nlif", f"NaN, +inf, −inf samples, on_bad_data: {policy}, all integrators",
        what, "raise: clean one-line error; else counted once, outputs finite, neuron not dead", ok,
        "; ".join(notes) or "9/9 combinations as described",
    )  # fmt: skip


def float32_input() -> Outcome:
    """A float32 drive: the block's port is float64 (state is float64): refused at bind, or not."""
    try:
        run_offline(Nlif(n=2), x=np.full(10, 0.5, np.float32))
    except ft.SpecError as e:
        return Outcome(
            "float32", "nlif", "float32 drive", f"not supported (state and ports are float64): refused at "
            f"bind: “{e}”", "clean refusal", "\n" not in str(e),
        )  # fmt: skip
    return Outcome("float32", "nlif", "float32 drive", "accepted", "clean refusal", False)


# -- long runs -----------------------------------------------------------------------------------------


def long_run(integrator: str, n_steps: int, u: float, n: int = 4, chunk: int = 1_000_000) -> dict[str, float]:
    """Drive ``n`` neurons (τ = 10 ms, σ = 0) with a constant ``u`` for ``n_steps`` at 1 kHz, chunk by chunk.

    Timestamps are the exact grid ``i / 1000`` (integer i). Returns ``v_first``/``v_last`` (neuron
    0 after the first and last chunks) and, for neuron 0's spikes: ``spikes``, ``period`` (mean
    interval, s), ``max_t_err`` (largest |t_k − (t_0 + k·P)| in s with P the first interval,
    grid methods) and ``t_ulp`` (one ulp of the last time).
    """
    blk = Nlif(n=n, tau_s=0.01, integrator=integrator)
    blk.bind({"x": ft.StreamSpec(dtype="float64", shape=(), units="1", rate_hz=RATE)})
    x = np.full(chunk, u)
    times: list[np.ndarray] = []
    v_first = v_last = math.nan
    for i0 in range(0, n_steps, chunk):
        m = min(chunk, n_steps - i0)
        t = (i0 + np.arange(m)) / RATE
        out = blk(x=ft.Chunk(t, x[:m]))
        v_last = float(out["v"].data[-1, 0])
        if i0 == 0:
            v_first = v_last
        s = out["spikes"]
        times.append(s.t[s.data == 0])
    s = blk.flush().get("spikes")
    if s is not None and len(s):
        times.append(s.t[s.data == 0])
    ts = np.concatenate(times)
    out_m = {"v_first": v_first, "v_last": v_last, "spikes": float(len(ts))}
    out_m["t_ulp"] = float(np.spacing((n_steps - 1) / RATE))
    if len(ts) > 1:
        out_m["period"] = float((ts[-1] - ts[0]) / (len(ts) - 1))
        steps = np.round(ts * RATE).astype(np.int64)  # grid methods: the step each spike is stamped at
        p = int(steps[1] - steps[0])
        k = np.arange(len(ts))
        out_m["max_t_err"] = float(np.abs(ts - (steps[0] + k * p) / RATE).max())
    return out_m


def long_run_case(integrator: str, n_steps: int) -> Outcome:
    """V drift (subthreshold, u = 0.9: stationary V = 0.9) and spike-time drift (u = 1.5) over ``n_steps``."""
    sub = long_run(integrator, n_steps, 0.9)
    sup = long_run(integrator, n_steps, 1.5)
    tau = 0.01
    a = math.exp(-DT / tau)
    # fixed point of v ← a·v + b·u: each step rounds by ≲ 2ε·V and the error decays by a per step
    v_tol = 4 * EPS * 0.9 / (1 - a)
    v_drift = abs(sub["v_last"] - 0.9)
    v_change = abs(sub["v_last"] - sub["v_first"])
    exact_period = tau * math.log(1.5 / 0.5)  # continuous model: v = 1.5(1 − e^(−t/τ)) hits 1
    if integrator == "exp_interp":
        # linear interpolation of the crossing errs by ≤ dt²·|v''|/(8|v'|) per spike (|v''/v'| = 1/τ)
        t_tol = DT * DT / (8 * tau)
        t_err = abs(sup["period"] - exact_period)
        t_crit = f"|mean ISI − τ·ln 3| ≤ dt²/(8τ) = {t_tol:.1e} s (interpolation, does not accumulate)"
        t_meas = f"mean ISI {sup['period'] * 1e3:.6f} ms vs τ·ln 3 = {exact_period * 1e3:.6f} ms"
    else:
        t_tol = 2 * sup["t_ulp"]
        t_err = sup["max_t_err"]
        t_crit = f"spikes on the exact k·P·dt grid: |t − k·dt| ≤ 2 ulp(t_end) = {t_tol:.1e} s"
        t_meas = f"period {sup['period'] * 1e3:.0f} ms, max |t − k·dt| = {t_err:.1e} s"
    ok = v_drift <= v_tol and v_change <= v_tol and t_err <= t_tol
    return Outcome(
        f"long_{integrator}_1e{round(math.log10(n_steps))}", "nlif",
        f"1e{round(math.log10(n_steps))} steps at 1 kHz, float64, τ = 10 ms, σ = 0, {integrator}; "
        "u = 0.9 (V → 0.9) and u = 1.5 (periodic spikes)",
        "V stays at its fixed point; spike times are stamped from the input's own timestamps (no "
        "accumulated time), so they do not drift",
        f"|V − 0.9| and |V(end) − V(1e6 steps)| ≤ 4ε·V/(1−a) = {v_tol:.1e}; {t_crit}",
        ok,
        f"|V − 0.9| = {v_drift:.1e}, V change {v_change:.1e}; {sup['spikes']:.0f} spikes, {t_meas}",
        {"v_drift": v_drift, "v_change": v_change, "t_err": t_err, "t_tol": t_tol, "v_tol": v_tol},
    )  # fmt: skip


CASES: tuple[StressCase, ...] = (
    *(StressCase(f"tau_tiny_{i}", "nlif", partial(tau_tiny, i)) for i in INTEGRATORS),
    *(StressCase(f"tau_huge_{i}", "nlif", partial(tau_huge, i)) for i in INTEGRATORS),
    StressCase("drive_1e6", "nlif", partial(drive_extreme, 1e6)),
    StressCase("drive_1e-12", "nlif", partial(drive_extreme, 1e-12)),
    *(StressCase(f"nonfinite_{p}", "nlif", partial(bad_samples, p)) for p in ("raise", "drop", "hold")),
    StressCase("float32", "nlif", float32_input),
    *(
        StressCase(
            f"long_{i}", "nlif", partial(long_run_case, i, 10**7), full=partial(long_run_case, i, 10**8)
        )
        for i in INTEGRATORS
    ),
    *NAIVE_BAYES_STRESS,  # the room's other blocks (naive_bayes_stress.py)
)
