"""REPORT.md of a bench run: a one-screen summary (per suite its headline ratio, the checks that
failed, the time taken and the load), then per suite what it measures, its figures with spread and
ratios, its tables, plots and verdicts, the command that reproduces it, and where flowtact is slower.

Every ratio follows one convention, :data:`RATIO_CONVENTION`: a speed-up, > 1 when flowtact does
better than the figure it is compared with."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = [
    "RATIO_CONVENTION",
    "RATIO_HEADER",
    "duration_text",
    "fmt",
    "headline",
    "summary_lines",
    "write_report",
]

RATIO_HEADER = "speed-up vs baseline (> 1: flowtact better)"
"""The column header of every ratio in the report."""
RATIO_CONVENTION = (
    "Every ratio in this report is a **speed-up**: the reference's time (latency, CPU, error) over "
    "flowtact's, or flowtact's rate over the reference's. **> 1: flowtact is better**; 0.5: flowtact "
    "takes twice as long (or does half as much)."
)
"""The one ratio convention of the report, stated in its header."""
NAME_CHARS = 100
"""A failed check's name is cut to this many characters in the summary (the suite's section has it whole)."""


def fmt(x: Any) -> str:
    """A number in 3 significant digits (thousands plainly), anything else as text."""
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        return "—" if x is None else str(x)
    if not math.isfinite(x):
        return str(x)
    if x == 0 or 1e-3 <= abs(x) < 1e5:
        return f"{x:,.3g}" if abs(x) < 1000 else f"{x:,.0f}"
    return f"{x:.3g}"


def _load(v: list[float] | None) -> str:
    return "n/a" if not v else " / ".join(f"{x:.2f}" for x in v)


def _md_table(header: list[str], rows: list[list[Any]]) -> list[str]:
    cell = lambda v: fmt(v).replace("|", "\\|")  # noqa: E731
    lines = ["| " + " | ".join(cell(h) for h in header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cell(v) for v in r) + " |" for r in rows]
    return lines


def duration_text(seconds: float) -> str:
    """``22 min 47 s`` or ``48 s``: a wall time a person reads at a glance."""
    m, sec = divmod(round(seconds), 60)
    return f"{m} min {sec} s" if m else f"{sec} s"


def _cut(text: str, n: int) -> str:
    return text if len(text) <= n else text[: n - 1].rstrip() + "…"


def headline(r: dict[str, Any]) -> str:
    """A suite's headline ratio: the figure it names (``ctx.headline``), else its first figure
    against an outside reference, else its first with a ratio; "—" when it has none."""
    figures = r.get("figures") or {}
    rated = [(k, f) for k, f in figures.items() if f.get("ratio") is not None]
    named = r.get("headline")
    pick = next(((k, f) for k, f in rated if k == named), None)
    pick = pick or next(((k, f) for k, f in rated if figures.get(f["baseline"], {}).get("reference")), None)
    pick = pick or (rated[0] if rated else None)
    if pick is None:
        return "—"
    key, f = pick
    return f"**{fmt(f['ratio'])}×** {_cut(key, NAME_CHARS // 2)}, vs {_cut(f['baseline'], NAME_CHARS // 2)}"


def _suite_row(r: dict[str, Any]) -> list[str]:
    checks = r.get("checks") or []
    failed = [c["name"] for c in checks if not c["passed"]]
    if r["status"] == "failed":
        result = f"**FAILED**: {_cut(r['error'].splitlines()[0], 100)}"
    elif r["status"] == "skipped":
        result = f"skipped: {_cut(r['reason'].splitlines()[0], 80)}"
    else:
        result = "ok"
    verdicts = f"{len(checks) - len(failed)} pass" + (
        f", **{len(failed)} FAIL**: " + "; ".join(_cut(n, NAME_CHARS) for n in failed) if failed else ""
    )
    return [f"[{r['suite']}](#{r['suite']})", result, headline(r), verdicts if checks else "—",
            duration_text(r["wall_s"])]  # fmt: skip


def _peak_load(run: dict[str, Any], records: list[dict[str, Any]]) -> float | None:
    ones = [v[0] for r in (run, *records) for v in (r.get("load_before"), r.get("load_after")) if v]
    return max(ones) if ones else None


def summary_lines(run: dict[str, Any], records: list[dict[str, Any]]) -> list[str]:
    """The report's first screen: time and load, machine, ratio convention, one row per suite."""
    m = run["machine"]
    py = m["versions"].get("python", "?")
    estimate = run.get("estimate_min")
    failed = [r["suite"] for r in records if r["status"] == "failed"]
    checks = [c for r in records for c in r.get("checks") or []]
    n_fail = sum(not c["passed"] for c in checks)
    peak = _peak_load(run, records)
    lines = [
        "## Summary",
        "",
        f"- **Took {duration_text(run['wall_s'])}**"
        + (f" (the suites' estimates for an idle {m['cores']}-core machine add to {estimate:g} min)" if estimate else "")
        + f"; load average (1 min) {_one(run['load_before'])} before, {_one(run['load_after'])} after"
        + (f", {peak:.1f} at the busiest" if peak is not None else "")
        + _busy(peak, m["cores"]),
        f"- Machine: {m['cpu']}, {m['cores']} cores ({m['cores_usable']} usable), {m['platform']}, python {py}; "
        f"git commit {m['git_commit'] or 'n/a'}.",
        f"- {len(records)} suites: {sum(r['status'] == 'ok' for r in records)} ran"
        + (f", **{len(failed)} failed to run ({', '.join(failed)})**" if failed else "")
        + (f", {sum(r['status'] == 'skipped' for r in records)} skipped" if any(r["status"] == "skipped" for r in records) else "")
        + f"; checks: {len(checks) - n_fail} pass, {n_fail} FAIL.",
        f"- {RATIO_CONVENTION}",
        "",
        *_md_rows(["suite", "result", "headline ratio (> 1: flowtact better)", "checks", "wall"],
                  [_suite_row(r) for r in records]),
        "",
    ]  # fmt: skip
    return lines


def _busy(peak: float | None, cores: int) -> str:
    """What the load says about the times: above the core count the machine was oversubscribed."""
    if peak is None:
        return "."
    if peak > cores:
        return f": above {cores} the machine was busy, and every time here is pessimistic."
    return f": at most {cores}, the machine was not oversubscribed."


def _one(v: list[float] | None) -> str:
    return "n/a" if not v else f"{v[0]:.2f}"


def _md_rows(header: list[str], rows: list[list[str]]) -> list[str]:
    """A Markdown table of text cells (already formatted)."""
    cell = lambda v: str(v).replace("|", "\\|")  # noqa: E731
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return lines + ["| " + " | ".join(cell(v) for v in row) + " |" for row in rows]


def _figure_rows(figures: dict[str, dict[str, Any]]) -> list[list[Any]]:
    rows = []
    for key, f in figures.items():
        if f["is_baseline"]:
            vs = "baseline"
        elif f["baseline"]:
            lo, hi = f["ratio_range"] or (None, None)
            vs = (
                f"{fmt(f['ratio'])}× ({fmt(lo)}–{fmt(hi)}) vs {f['baseline']}"
                if f["ratio"]
                else f"vs {f['baseline']}"
            )
        else:
            vs = "—"
        spread = f"{fmt(f['q1'])}–{fmt(f['q3'])}" if f["q1"] != f["q3"] else "—"
        rows.append(
            [
                key,
                fmt(f["median"]),
                f["unit"],
                spread,
                f"{fmt(f['min'])}–{fmt(f['max'])}",
                len(f["samples"]),
                vs,
            ]
        )
    return rows


def _slower(figures: dict[str, dict[str, Any]]) -> tuple[list[str], list[str]]:
    """Plain statements for every figure worse than its baseline (and whether beyond the spread):
    against outside references, and against flowtact's own settings (its trade-offs)."""
    refs, own = [], []
    for key, f in figures.items():
        r = f.get("ratio")
        if r is None or r >= 1:
            continue
        lo, hi = f["ratio_range"]
        sure = "beyond the spread" if hi < 1 else "the spreads overlap"
        what = "slower" if f["better"] == "higher" or "s" in f["unit"] else "worse"
        line = f"- **{key}** is {what} than {f['baseline']}: {fmt(r)}× ({sure}; range {fmt(lo)}–{fmt(hi)})."
        (refs if figures.get(f["baseline"], {}).get("reference") else own).append(line)
    return refs, own


def _suite_section(r: dict[str, Any]) -> list[str]:
    lines = [f"## {r['suite']}" + (f" — {r['title']}" if r.get("title") else ""), ""]
    status = r["status"].upper() if r["status"] != "ok" else "ok"
    lines.append(
        f"Status: **{status}** · wall {r['wall_s']:.1f} s · load average before {_load(r['load_before'])}, "
        f"after {_load(r['load_after'])} · "
        + (f"samples from {r['processes']} fresh processes · " if r.get("processes", 1) > 1 else "")
        + f"reproduce: `{r['command']}`"
    )
    lines.append("")
    if r.get("measures"):
        lines += [r["measures"], "", f"Baseline (same run): {r['baseline']}.", ""]
    if r["status"] == "skipped":
        lines += [f"Skipped: {r['reason']}", ""]
    if r["status"] == "failed":
        lines += [f"**Failed**: `{r['error'].splitlines()[0]}`", ""]
        if r.get("traceback"):
            lines += [
                "<details><summary>traceback</summary>",
                "",
                "```",
                r["traceback"].rstrip(),
                "```",
                "</details>",
                "",
            ]
    figures = r.get("figures") or {}
    if figures:
        lines += [
            f"| figure | median | unit | IQR | min–max | n | {RATIO_HEADER} |",
            "|---|---|---|---|---|---|---|",
        ]
        lines += [
            "| " + " | ".join(str(c).replace("|", "\\|") for c in row) + " |" for row in _figure_rows(figures)
        ]
        lines.append("")
        refs, own = _slower(figures)
        if any(f.get("reference") for f in figures.values()):
            lines += (["Where flowtact is slower or worse than an outside reference (a plain list, from the ratios "
                       "above):", "", *refs, ""] if refs else
                      ["flowtact is not slower than its outside reference in any figure of this suite.", ""])  # fmt: skip
        if own:
            lines += ["Settings slower or worse than the flowtact setting they are measured against (trade-offs, "
                      "not shortfalls):", "", *own, ""]  # fmt: skip
    for c in sorted(r.get("checks") or [], key=lambda c: c["passed"]):  # failures first
        lines.append(
            f"- {'PASS' if c['passed'] else '**FAIL**'} {c['name']}"
            + (f": {c['detail']}" if c["detail"] else "")
        )
    if r.get("checks"):
        lines.append("")
    for t in r.get("tables") or []:
        lines += [f"**{t['title']}**", "", *_md_table(t["header"], t["rows"]), ""]
        if t["note"]:
            lines += [t["note"], ""]
    for p in r.get("plots") or []:
        lines += [
            f"![{p['caption']}]({p['path']})" if p["path"] else f"(plot {p['name']}: {p['error']})",
            "",
            f"*{p['caption']}*",
            "",
        ]
    for n in r.get("notes") or []:
        lines += [f"> {n}", ""]
    return lines


def write_report(
    out: Path, run: dict[str, Any], records: list[dict[str, Any]], extra: Sequence[str] = ()
) -> Path:
    """Write OUT/REPORT.md and return its path: the summary first, then how to read it, ``extra``
    lines (a comparison), and one section per suite."""
    m = run["machine"]
    v = ", ".join(f"{k} {x}" for k, x in m["versions"].items())
    lines = [
        "# flowtact benchmark report",
        "",
        f"Made by `{run['command']}` ({'quick' if run['quick'] else 'full'} run) on {run['started']}. "
        "Generated: do not edit; rerun the command instead.",
        "",
        *summary_lines(run, records),
        "## How to read it",
        "",
        f"- Software: {v}; git commit {m['git_commit'] or 'n/a (not a source checkout)'}",
        f"- Threads: {', '.join(f'{k}={x}' for k, x in m['threads'].items())} (every figure is one core's)",
        f"- Load average (1/5/15 min): {_load(run['load_before'])} before, {_load(run['load_after'])} after.",
        "",
        "Each speed figure is the median of its repeats (after warm-up), with its interquartile range and "
        "extremes; ratios compare it with a baseline measured in the same run, so they survive a "
        "busy machine better than absolute figures. A ratio's range spans its paired ratios, or every pairing of the two "
        "figures' samples (worst to best); a rerun reproduces a ratio when its median lands inside that range. A suite "
        "timed in this process shares its repeats out over several fresh processes (2 in a quick run, 3 in a full "
        "one): what moves from one process to the next (memory layout, compiled code, the core) is in the spread. "
        "A check that FAILs is a finding about this machine and this run, not a crash: the suite's section says "
        "what it measured against what bar.",
        "",
    ]
    lines += extra
    for r in records:
        lines += _suite_section(r)
    path = out / "REPORT.md"
    path.write_text("\n".join(lines).rstrip() + "\n")
    return path
