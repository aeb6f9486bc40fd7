"""REPORT.md of a bench run: per suite what it measures, its figures with spread and ratios, its
tables, plots and verdicts, the command that reproduces it, and where flowtact is slower."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = ["fmt", "write_report"]


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
            "| figure | median | unit | IQR | min–max | n | vs baseline (> 1: flowtact better) |",
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
    for c in r.get("checks") or []:
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
    """Write OUT/REPORT.md and return its path; ``extra`` lines (a comparison) follow the summary table."""
    m = run["machine"]
    v = ", ".join(f"{k} {x}" for k, x in m["versions"].items())
    lines = [
        "# flowtact benchmark report",
        "",
        f"Made by `{run['command']}` ({'quick' if run['quick'] else 'full'} run) on {run['started']}, "
        f"{run['wall_s']:.0f} s wall. Generated: do not edit; rerun the command instead.",
        "",
        f"- Machine: {m['cpu']}, {m['cores']} cores ({m['cores_usable']} usable), {m['platform']}",
        f"- Software: {v}; git commit {m['git_commit'] or 'n/a (not a source checkout)'}",
        f"- Threads: {', '.join(f'{k}={x}' for k, x in m['threads'].items())} (every figure is one core's)",
        f"- Load average (1/5/15 min): {_load(run['load_before'])} before, {_load(run['load_after'])} after. "
        f"Above {m['cores']} the machine was oversubscribed and timings are pessimistic.",
        "",
        "Each speed figure is the median of its repeats (after warm-up), with its interquartile range and "
        "extremes; ratios compare it with a baseline measured in the same run, so they survive a "
        "busy machine better than absolute figures. A ratio's range spans its paired ratios, or every pairing of the two "
        "figures' samples (worst to best); a rerun reproduces a ratio when its median lands inside that range. A suite "
        "timed in this process shares its repeats out over several fresh processes (2 in a quick run, 3 in a full "
        "one): what moves from one process to the next (memory layout, compiled code, the core) is in the spread.",
        "",
        "| suite | status | wall s | load before → after |",
        "|---|---|---|---|",
    ]
    for r in records:
        lines.append(f"| [{r['suite']}](#{r['suite']}) | {r['status']} | {r['wall_s']:.1f} | "
                     f"{_load(r['load_before'])} → {_load(r['load_after'])} |")  # fmt: skip
    lines.append("")
    lines += extra
    for r in records:
        lines += _suite_section(r)
    path = out / "REPORT.md"
    path.write_text("\n".join(lines).rstrip() + "\n")
    return path
