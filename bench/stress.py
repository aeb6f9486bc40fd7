"""Suite ``stress``: every numerical stress case (flowtact.verify.stress) run on the real blocks, one verdict each.

The cases live next to their blocks, registered in the entry-point group ``flowtact.stress_cases``; ``--quick`` runs the
short variants (1e7-step long runs), the full run the 1e8-step ones. A case that crashes is a failed
check with the exception in its detail (``flowtact.verify.stress.run_case``), never a crashed suite. The
same table is docs/numerical-stress.md (``python scripts/stress_outcomes.py``).
"""

from __future__ import annotations

import time

from flowtact.benchmark import Context, Suite


def run(ctx: Context) -> None:
    from flowtact.verify.stress import collect, run_case

    cases = collect()
    rows, raw = [], []
    for case in cases:
        ctx.step(f"{case.block}/{case.name}")
        t0 = time.perf_counter()
        out = run_case(case, full=not ctx.quick)
        secs = time.perf_counter() - t0
        name = out.case or case.name
        ctx.check(f"{case.block}/{name}: {out.criterion}", out.passed, out.measured or out.behaviour)
        rows.append([out.block, name, out.condition, out.behaviour, "pass" if out.passed else "**FAIL**",
                     out.measured, f"{secs:.2f}"])  # fmt: skip
        raw.append({"block": out.block, "case": name, "passed": out.passed, "seconds": secs,
                    "crashed": out.behaviour.startswith("CRASH"), "metrics": dict(out.metrics)})  # fmt: skip
    ctx.data["outcomes"] = raw
    ctx.table(
        "Numerical stress outcomes"
        + (" (short variants: 1e7-step long runs)" if ctx.quick else " (1e8-step long runs)"),
        ["block", "case", "input", "what the block does", "result", "measured", "s"],
        rows,
        "Criteria are in the checks below; docs/numerical-stress.md explains each case and the fixes made.",
    )
    passed = sum(r["passed"] for r in raw)
    crashed = sum(r["crashed"] for r in raw)
    ctx.note(
        f"{len(raw)} stress cases: {passed} pass, {len(raw) - passed} fail ({crashed} of them crashed); "
        f"{sum(c.slow for c in cases)} long runs at {'1e7' if ctx.quick else '1e8'} steps."
    )


SUITE = Suite(
    name="stress",
    title="Numerical stress: what each block does with hostile numbers",
    measures="Every numerical stress case of docs/numerical-stress.md (τ ≪ dt and τ ≫ run length, inputs of 1e6 and "
    "1e-12, NaN/inf samples under each `on_bad_data` policy, 10⁸ steps, irregular sampling and gaps into the "
    "differentiator, uniform and saturated images into SSIM, singular poses into inverse kinematics, "
    "out-of-range FSR readings) run on the real blocks, each with its recorded outcome and a pass/fail "
    "against its own criterion (analytic references, scipy, scikit-image).",
    baseline="each case's own criterion (an analytic value or an independent implementation); no speed ratio",
    run=run,
    minutes_quick=0.3,
    minutes_full=2,
    processes=(1, 1),  # outcomes, not timings
)
