"""``flowtact bench --compare DIR``: does this run reproduce an earlier run's ratios within the spread
that run reported? Ratios (against a baseline measured in the same run) are what a report claims,
so they are what a second run is held to; absolute figures move with the machine's load."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["RatioCheck", "compare_records", "load_results", "report_lines", "shift_percentiles"]


@dataclass(frozen=True)
class RatioCheck:
    """One figure's ratio now against the same figure's ratio and reported range before."""

    suite: str
    figure: str
    before: float
    before_range: tuple[float, float]
    now: float
    now_range: tuple[float, float] | None

    @property
    def within(self) -> bool:
        """This run's ratio lies inside the range the earlier report gave."""
        lo, hi = self.before_range
        return lo <= self.now <= hi

    @property
    def shift(self) -> float:
        """How far the ratio moved between the runs, as a fraction (|log(now / before)|)."""
        return abs(math.log(self.now / self.before)) if self.now > 0 and self.before > 0 else math.inf

    @property
    def overlaps(self) -> bool:
        """The two runs' ranges share a value (each run's spread allowed for)."""
        lo, hi = self.before_range
        a, b = self.now_range or (self.now, self.now)
        return a <= hi and lo <= b


def load_results(folder: Path) -> dict[str, dict[str, Any]]:
    """The per-suite results of an earlier run: ``folder/results/<suite>.json`` (``run.json`` aside)."""
    results = folder / "results"
    if not results.is_dir():
        raise FileNotFoundError(f"{folder}: no results/ folder (an output folder of flowtact bench)")
    out = {}
    for path in sorted(results.glob("*.json")):
        if path.name != "run.json":
            try:
                rec = json.loads(path.read_text())
            except (ValueError, RecursionError) as e:  # the file's name, not only the parser's words
                raise ValueError(f"{path}: not a results file of flowtact bench ({e})") from None
            if not isinstance(rec, dict):
                raise ValueError(f"{path}: not a results file of flowtact bench (not a JSON object)")
            out[rec.get("suite", path.stem)] = rec
    return out


def compare_records(before: dict[str, dict[str, Any]], now: list[dict[str, Any]]) -> list[RatioCheck]:
    """Every figure with a ratio in both runs (same suite, same key)."""
    checks = []
    for rec in now:
        old = before.get(rec["suite"], {}).get("figures", {})
        for key, fig in rec.get("figures", {}).items():
            prev = old.get(key)
            if not prev or prev.get("ratio") is None or fig.get("ratio") is None:
                continue
            prev_range = prev.get("ratio_range") or (prev["ratio"], prev["ratio"])
            now_range = fig.get("ratio_range")
            checks.append(
                RatioCheck(
                    rec["suite"],
                    key,
                    float(prev["ratio"]),
                    (float(prev_range[0]), float(prev_range[1])),
                    float(fig["ratio"]),
                    (float(now_range[0]), float(now_range[1])) if now_range else None,
                )
            )
    return checks


def shift_percentiles(checks: list[RatioCheck]) -> dict[str, float]:
    """Median and 90th percentile of the ratios' run-to-run shifts (fractions): how far a ratio
    moves between two runs, which a within-run spread cannot show (process layout, JIT, load)."""
    shifts = sorted(c.shift for c in checks)
    if not shifts:
        return {}

    def pct(q: float) -> float:
        return shifts[min(len(shifts) - 1, math.ceil(q * len(shifts)) - 1)]

    return {"median": pct(0.5), "p90": pct(0.9)}


def report_lines(checks: list[RatioCheck], folder: Path) -> list[str]:
    """The REPORT.md section: counts, then every ratio outside the earlier range."""
    if not checks:
        return ["## Reproducibility", "", f"No figure of this run has a ratio in `{folder}` to compare.", ""]
    within = sum(c.within for c in checks)
    overlap = sum(c.overlaps for c in checks)
    shift = shift_percentiles(checks)
    lines = [
        "## Reproducibility",
        "",
        f"Against the run in `{folder}`: {within} of {len(checks)} ratios lie inside the range that run "
        f"reported; {overlap} of {len(checks)} ranges overlap. Between the two runs a ratio moved by "
        f"{shift['median']:.1%} (median) and {shift['p90']:.1%} (90th percentile): a within-run spread "
        "does not see what changes from one process to the next (memory layout, compiled code, load), "
        "so differences of that size between runs are noise.",
        "",
    ]
    outside = [c for c in checks if not c.within]
    if outside:
        lines += [
            "| suite | figure | before (range) | now (range) | ranges overlap |",
            "|---|---|---|---|---|",
        ]
        for c in outside:
            now_range = f"{c.now_range[0]:.3g}–{c.now_range[1]:.3g}" if c.now_range else "—"
            lines.append(
                f"| {c.suite} | {c.figure} | {c.before:.3g} ({c.before_range[0]:.3g}–{c.before_range[1]:.3g}) "
                f"| {c.now:.3g} ({now_range}) | {'yes' if c.overlaps else 'no'} |"
            )
        lines.append("")
    return lines
