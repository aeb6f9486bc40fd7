"""Suite ``hostile_input``: wall time and peak RSS of `flowtact validate` refusing each hostile input
(50 MB file, alias bomb, 5 000 nested lists, /dev/zero, a FIFO, a population of 1e14 neurons, ...).

Each case runs in a fresh child Python (interpreter start and flowtact's imports included), which
reports its own peak resident set size. The cases are those of tests/inputs/test_hostile_input.py
(bench/hostile_cases.py), where the refusal, its place and the 500 MiB bound are asserted. The
baseline is the same child validating the shipped graphs/touch.yaml: what any `flowtact validate`
costs.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from flowtact.bench.hostile_cases import CASES, TOUCH, run_measured
from flowtact.benchmark import Context, Suite
from flowtact.benchmark.suite import MIN_RATIO_SAMPLES

PEAK_MIB = 500


def run(ctx: Context) -> None:
    repeats = MIN_RATIO_SAMPLES if ctx.quick else 5
    ctx.step("baseline: validate touch.yaml")
    base = [run_measured(["validate", TOUCH]) for _ in range(repeats)]
    if any(m.returncode != 0 for m in base):
        raise RuntimeError(f"flowtact validate {TOUCH} failed: {base[0].stderr.strip()[-500:]}")
    ctx.figure("validate touch.yaml (benign)", [m.seconds for m in base], "s wall", "lower", is_baseline=True)
    ctx.figure(
        "validate touch.yaml (benign), peak RSS", [m.peak_mib for m in base], "MiB", "lower", is_baseline=True
    )
    rows = []
    for name, case in CASES.items():
        ctx.step(name)
        runs = []
        for _ in range(repeats):
            with tempfile.TemporaryDirectory() as folder:
                cli_args, expect = case(Path(folder))
                m = run_measured(cli_args)
                runs.append((m, expect in m.stderr))
        ok = all(found and m.returncode == 2 for m, found in runs)
        ctx.figure(
            name, [m.seconds for m, _ in runs], "s wall", "lower", baseline="validate touch.yaml (benign)"
        )
        peak = ctx.figure(f"{name}, peak RSS", [m.peak_mib for m, _ in runs], "MiB", "lower",
                          baseline="validate touch.yaml (benign), peak RSS")  # fmt: skip
        first = runs[0][0].stderr.splitlines()[0] if runs[0][0].stderr else ""
        rows.append([name, runs[0][0].returncode, first[:100]])
        ctx.check(f"{name}: refused (exit 2) at its place", ok, first[:100])
        ctx.check(f"{name}: peak RSS < {PEAK_MIB} MiB", peak.max < PEAK_MIB, f"{peak.max:.0f} MiB")
    ctx.table("How each hostile input is refused", ["case", "exit", "first line of the refusal"], rows)
    ctx.note("A ratio < 1 here means refusing the case costs more than validating a benign graph.")


SUITE = Suite(
    name="hostile_input",
    title="Hostile inputs: time and memory of a refusal",
    measures="Wall time and peak RSS of `flowtact validate` (a fresh child Python) refusing each hostile "
    "input of tests/inputs/test_hostile_input.py, and whether each was refused with exit 2 at its place.",
    baseline="the same child validating the shipped graphs/touch.yaml",
    run=run,
    minutes_quick=0.7,
    minutes_full=1.5,
    processes=(1, 1),  # every sample already comes from fresh processes
)
