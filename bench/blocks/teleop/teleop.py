"""Suite ``teleop``: frame-to-servo-command latency of the teleoperation loop, live, with the real serial path.

Runs ``graphs/teleop.yaml`` in real time (three worker processes; `flowtact sim exo` on a
pseudo-terminal; 3 TacTips at 40 FPS) and reads the graph's deadline path ``cams -> exo``: from
the moment `tactip_sim` emits a frame stack to the moment `serial_io` has written the servo
command computed from it (crop → SSIM → linear force → controller → one-tick loop delay → serial
write). Only data-carrying messages count; the first second (JIT loading) is skipped by the
runtime. Bar (issue 4): p99 ≤ 10 ms. For scale, the thesis reports a 250–600 ms force step
response and the RML glove 30 ms. The same run with ``teleop_cnn.yaml`` (the shipped CNN instead
of SSIM) when torch is installed; the SSIM graph is the CNN graph's baseline.
"""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from importlib.resources import files
from pathlib import Path

from flowtact.benchmark import Context, Suite

BAR_P99_US = 10_000.0


def run_graph(graph: Path, duration_s: float) -> dict:
    """One real-time run; returns the summary's deadline path and counters."""
    cmd = [sys.executable, "-m", "flowtact.cli", "run", str(graph), "--duration", str(duration_s)]
    p = subprocess.run([*cmd, "--json", "--quiet"], capture_output=True, text=True, timeout=duration_s + 120)
    if p.returncode != 0:
        raise RuntimeError(f"{graph.name} exited with {p.returncode}:\n{p.stderr.strip()[-2000:]}")
    summary = json.loads(p.stdout)
    path = summary["paths"]["cams -> exo"]
    return {
        "graph": graph.name,
        "duration_s": duration_s,
        "frames": path["n"],
        "p50_us": path["p50_us"],
        "p99_us": path["p99_us"],
        "max_us": path["max_us"],
        "missed_10ms": path["violations"],
        "packets": summary["counters"]["exo"]["packets"],
        "pass": path["p99_us"] <= BAR_P99_US,
    }


ROUNDS = 3
"""Rounds of live runs, each running every graph once, so p50/p99 have a spread across runs."""


def run(ctx: Context) -> None:
    duration = 2.5 if ctx.quick else 10.0
    graphs = [Path(str(files("flowtact.graphs") / "teleop.yaml"))]
    if importlib.util.find_spec("torch") is not None:
        graphs.append(Path(str(files("flowtact.graphs") / "teleop_cnn.yaml")))
    else:
        ctx.note("teleop_cnn.yaml not run: torch is not installed (pip install 'flowtact[cnn]').")
    runs: dict[str, list[dict]] = {g.name: [] for g in graphs}
    for i in range(ROUNDS):
        for g in graphs:
            ctx.step(f"round {i + 1}/{ROUNDS}: {g.name}, {duration:g} s live")
            runs[g.name].append(run_graph(g, duration))
    for g in graphs:
        rs = runs[g.name]
        base = "teleop.yaml (SSIM)" if g.name != "teleop.yaml" else None
        label = "teleop.yaml (SSIM)" if base is None else "teleop_cnn.yaml (CNN)"
        for q in ("p50", "p99"):
            ctx.figure(f"{label}, {q} frame → servo command", [r[f"{q}_us"] / 1e3 for r in rs], "ms", "lower",
                       is_baseline=base is None, baseline=f"{base}, {q} frame → servo command" if base else None,
                       paired=base is not None,
                       params={"frames": [r["frames"] for r in rs]})  # fmt: skip
        worst = max(rs, key=lambda r: r["p99_us"])
        ctx.check(
            f"{g.name}: p99 ≤ 10 ms in every run",  # the project's bar (issue 4)
            all(r["pass"] for r in rs),
            f"worst p99 {worst['p99_us'] / 1e3:.2f} ms over {worst['frames']} frames",
        )
    rows = [r for rs in runs.values() for r in rs]
    ctx.table("Frame → servo command, live (cams -> exo deadline path), every run",
              ["graph", "frames", "p50 (ms)", "p99 (ms)", "max (ms)", "> 10 ms", "serial packets"],
              [[r["graph"], r["frames"], r["p50_us"] / 1e3, r["p99_us"] / 1e3, r["max_us"] / 1e3, r["missed_10ms"],
                r["packets"]] for r in rows])  # fmt: skip
    ctx.data["rows"] = rows
    ctx.note(f"Latency is absolute (its bar is p99 ≤ 10 ms); each figure's samples are {ROUNDS} live runs of "
             f"{duration:g} s (the graphs alternate), each a percentile over the run's frames. The loop's "
             "one-step delay alone costs up to one tick (2 ms in these graphs).")  # fmt: skip


SUITE = Suite(
    name="teleop",
    title="Teleoperation loop: frame → servo command latency, live",
    measures="graphs/teleop.yaml (SSIM) and teleop_cnn.yaml (CNN) in real time with `flowtact sim exo` on a "
    "pseudo-terminal: latency p50/p99 from a TacTip frame's emission to the servo command written to the "
    "serial line.",
    baseline="the SSIM graph for the CNN graph; absolute against the bar p99 ≤ 10 ms",
    run=run,
    minutes_quick=0.75,
    minutes_full=2.0,
    processes=(1, 1),  # every sample already comes from fresh processes
)
