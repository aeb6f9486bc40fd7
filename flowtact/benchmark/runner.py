"""``flowtact bench``: run suites, one after another, and write results/*.json, plots/*.png and REPORT.md."""

from __future__ import annotations

import importlib.util
import json
import shlex
import sys
import time
import traceback
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from flowtact.benchmark.machine import load_average, machine_info, pin_threads
from flowtact.benchmark.plots import draw_tradeoff, save_plot
from flowtact.benchmark.process_rounds import measure_children
from flowtact.benchmark.progress import Progress
from flowtact.benchmark.registry import Unavailable, in_process_only, suites
from flowtact.benchmark.suite import Context, Suite
from flowtact.errors import SuiteSkipped

__all__ = ["command_line", "list_suites", "run_suites"]


def command_line(names: Sequence[str], quick: bool, peers: bool) -> str:
    """The command that reproduces a suite or a run."""
    return shlex.join(
        ["flowtact", "bench", *names, *(["--quick"] if quick else []), *(["--peers"] if peers else [])]
    )


def list_suites(out: Any = None) -> int:
    """One line per suite with its budgets on an idle 2-core machine, and their sum."""
    out = out or sys.stdout
    found = suites()
    for name, s in found.items():
        if isinstance(s, Unavailable):
            print(f"{name:<18} (unavailable: {s.reason})", file=out)
        else:
            print(
                f"{name:<18} {s.title}  [~{s.minutes_quick:g} min quick, ~{s.minutes_full:g} min full]",
                file=out,
            )
    quick, full = estimate_minutes(list(found.values()), True), estimate_minutes(list(found.values()), False)
    print(
        f"{'(every suite)':<18} ~{quick:g} min quick, ~{full:g} min full on an idle 2-core machine", file=out
    )
    return 0


def _missing(suite: Suite) -> list[str]:
    return [m for m in suite.needs if importlib.util.find_spec(m) is None]


def run_one(
    suite: Suite | Unavailable, quick: bool, peers: bool, out: Path, progress: Progress
) -> dict[str, Any]:
    """Run one suite and write results/<name>.json (and its plots); never raises but KeyboardInterrupt."""
    name = suite.name
    rec: dict[str, Any] = {
        "suite": name,
        "quick": quick,
        "peers": peers,
        "command": command_line([name], quick, peers),
    }
    rec["load_before"] = load_average()
    rec["started"] = time.strftime("%Y-%m-%dT%H:%M:%S")
    t0 = time.perf_counter()
    ctx: Context | None = None
    if isinstance(suite, Unavailable):
        rec["status"] = "skipped" if suite.missing_module else "failed"
        rec["reason" if suite.missing_module else "error"] = suite.reason
    else:
        rec.update(title=suite.title, measures=suite.measures, baseline=suite.baseline)
        missing = _missing(suite)
        if missing:
            rec["status"], rec["reason"] = (
                "skipped",
                f"needs {', '.join(missing)} (pip install 'flowtact[dev]')",
            )
        else:
            parts = 1 if in_process_only(name) else suite.parts(quick)
            prior, failures = (
                measure_children(name, quick, peers, parts, progress.step) if parts > 1 else ({}, [])
            )
            ctx = Context(
                suite, quick, peers, on_step=progress.step, part=parts - 1, parts=parts, prior=prior
            )
            for line in failures:
                ctx.note(line)
            rec["processes"] = parts
            try:
                suite.run(ctx)
                rec["status"] = "ok"
            except SuiteSkipped as e:
                rec["status"], rec["reason"] = "skipped", str(e)
            except Exception as e:  # noqa: BLE001 — a failing suite is reported; the others still run
                rec["status"] = "failed"
                rec["error"] = f"{type(e).__name__}: {e}"
                rec["traceback"] = traceback.format_exc()
    rec["wall_s"] = round(time.perf_counter() - t0, 3)
    rec["load_after"] = load_average()
    if ctx is not None:
        rec.update(ctx.to_dict())
        rec["plots"] = _write_plots(ctx, out)
    (out / "results").mkdir(parents=True, exist_ok=True)
    (out / "results" / f"{name}.json").write_text(json.dumps(rec, indent=1, default=_json_default))
    why = rec.get("reason") or rec.get("error") or f"{len(rec.get('figures', {}))} figures"
    progress.end(f"{name}: {rec['status']} in {rec['wall_s']:.1f} s ({why.splitlines()[0]})")
    return rec


def _write_plots(ctx: Context, out: Path) -> list[dict[str, Any]]:
    plots = list(ctx.plots) + [draw_tradeoff(t) for t in ctx.tradeoffs if t.points]
    written = []
    for p in plots:
        ctx.step(f"plot {p.name}")
        try:
            save_plot(p, out / "plots" / f"{ctx.suite.name}-{p.name}.png")
        except Exception as e:  # noqa: BLE001 — a broken drawing loses that plot, not the suite's figures
            p.error = f"drawing failed: {type(e).__name__}: {e}"
        rel = str(Path(p.path).relative_to(out)) if p.path else None
        written.append({"name": p.name, "caption": p.caption, "path": rel, "error": p.error})
    return written


def run_suites(
    names: Sequence[str],
    quick: bool,
    peers: bool,
    out: Path,
    as_json: bool = False,
    bar: bool | None = None,
    compare: Path | None = None,
) -> int:
    """Run the named suites (all when none) into ``out``. Exit status: 0 all ran (a check may FAIL:
    REPORT.md's summary lists those); 1 a suite failed to run (stderr names it; the others' results
    and the report are written all the same); 130 stopped by Ctrl-C (the report holds what ran); 2 an
    unknown name or an unreadable ``compare`` folder (an earlier run whose ratios this one is held to)."""
    from flowtact.benchmark.compare import compare_records, load_results, report_lines, shift_percentiles
    from flowtact.benchmark.report import duration_text, write_report
    from flowtact.errors import UsageError
    from flowtact.params import did_you_mean

    pin_threads()
    available = suites()
    for n in names:
        if n not in available:  # usage errors take the commands' one error path (exit 2)
            raise UsageError(f"unknown benchmark suite '{n}'{did_you_mean(n, available)}")
    try:
        before = load_results(compare) if compare is not None else None
    except (OSError, ValueError) as e:
        raise UsageError(f"--compare: {e}") from e
    chosen = list(dict.fromkeys(names)) or list(available)
    out.mkdir(parents=True, exist_ok=True)
    run: dict[str, Any] = {
        "command": command_line(names, quick, peers),
        "quick": quick,
        "peers": peers,
        "estimate_min": estimate_minutes([available[n] for n in chosen], quick),
        "machine": machine_info(),
        "load_before": load_average(),
        "started": time.strftime("%Y-%m-%dT%H:%M:%S"),
    }
    t0 = time.perf_counter()
    records = []
    stream = sys.stderr if as_json else sys.stdout
    interrupted = False
    with Progress(len(chosen), stream, bar) as progress:
        for i, n in enumerate(chosen):
            progress.begin(n)
            try:
                records.append(run_one(available[n], quick, peers, out, progress))
            except KeyboardInterrupt:  # Ctrl-C: what ran so far still gets its report
                records.append(_interrupted(n, chosen[i + 1 :], quick, peers))
                interrupted = True
                break
    run["wall_s"] = round(time.perf_counter() - t0, 3)
    run["load_after"] = load_average()
    run["suites"] = {r["suite"]: r["status"] for r in records}
    extra: list[str] = []
    if before is not None and compare is not None:
        checks = compare_records(before, records)
        run["reproducibility"] = {
            "compared_with": str(compare),
            "ratios": len(checks),
            "within_earlier_range": sum(c.within for c in checks),
            "ranges_overlap": sum(c.overlaps for c in checks),
            "shift": shift_percentiles(checks),
        }
        extra = report_lines(checks, compare)
    (out / "results").mkdir(parents=True, exist_ok=True)
    (out / "results" / "run.json").write_text(json.dumps(run, indent=1))
    report = write_report(out, run, records, extra)
    if as_json:
        print(json.dumps({**run, "report": str(report), "results": str(out / "results")}, indent=1))
    else:
        n_fail = sum(not c["passed"] for r in records for c in r.get("checks") or [])
        load = (
            f"load {run['load_before'][0]:.1f} → {run['load_after'][0]:.1f}"
            if run["load_before"] and run["load_after"]
            else "load n/a"
        )
        print(f"report: {report} ({duration_text(run['wall_s'])}, {load}; "
              f"{n_fail} failed check{'s' * (n_fail != 1)}: see its summary)")  # fmt: skip
        if "reproducibility" in run:
            r = run["reproducibility"]
            print(
                f"reproduced: {r['within_earlier_range']} of {r['ratios']} ratios inside the range of "
                f"{compare} ({r['ranges_overlap']} ranges overlap; ratios moved {r['shift']['median']:.1%} "
                f"median, {r['shift']['p90']:.1%} at the 90th percentile)"
            )
    failed = [r for r in records if r["status"] == "failed"]
    for r in failed:  # the exit code says that a suite failed; this line says which and why
        print(f"flowtact bench: suite '{r['suite']}' failed: {r['error'].splitlines()[0]}", file=sys.stderr)
    return INTERRUPTED if interrupted else 1 if failed else 0


INTERRUPTED = 130
"""Exit status of a run stopped by Ctrl-C (128 + SIGINT, as a shell reports it); its report is written."""


def _interrupted(name: str, not_run: Sequence[str], quick: bool, peers: bool) -> dict[str, Any]:
    """The record of the suite Ctrl-C stopped: failed, naming the suites that did not run."""
    rest = f"; not run: {', '.join(not_run)}" if not_run else ""
    return {"suite": name, "status": "failed", "error": f"interrupted (Ctrl-C){rest}", "wall_s": 0.0,
            "load_before": None, "load_after": load_average(), "command": command_line([name], quick, peers)}  # fmt: skip


def estimate_minutes(chosen: Sequence[Suite | Unavailable], quick: bool) -> float:
    """The suites' own budgets added up (``--list`` shows each): what the run should take on an idle machine."""
    return round(sum(s.minutes_quick if quick else s.minutes_full for s in chosen if isinstance(s, Suite)), 1)


def _json_default(x: Any) -> Any:
    if hasattr(x, "item"):  # numpy scalars
        return x.item()
    if hasattr(x, "tolist"):
        return x.tolist()
    raise TypeError(f"not JSON serialisable: {type(x).__name__}")
