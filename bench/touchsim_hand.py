"""The whole hand in real time (issue 33, Deliver 4): graphs/hand.yaml run by `flowtact run` at 1 and
2 shards, its real-time factor, p99 lateness and CPU per graph second, with the load average.

Each run is a fresh `flowtact run GRAPH --duration D --json` (worker processes, the real-time clock):
the real-time factor and whether it kept up are the run's own; lateness is the p99 latency of a
deadline path ``probe → afferents`` added to a copy of the graph (from a tick's stimulus samples to
the afferents' spikes of them, across the shards' processes and the merge); CPU is that of every
process while the graph ran (each process' CPU share × the running time), per graph second. The
machine's load average before and after is reported beside: other work on the 2 cores slows a
real-time run, not its CPU per graph second.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import yaml

__all__ = ["hand_graph", "run_hand"]

BUDGET_MS = 5.0
"""The lateness the issue allows (p99, ms): the deadline path's budget."""


def hand_graph(src: Path, shards: int, out: Path) -> Path:
    """A copy of ``src`` (graphs/hand.yaml) with every node at ``shards`` shards and the deadline
    path probe → afferents, written to ``out``."""
    doc = yaml.safe_load(src.read_text())
    for node in doc["nodes"].values():
        node["shards"] = shards
    doc["deadlines"] = [{"from": "probe", "to": "afferents", "budget": f"{BUDGET_MS:g}ms"}]  # one per shard
    out.write_text(yaml.safe_dump(doc, sort_keys=False))
    return out


def run_hand(src: Path, shards: int, duration_s: float) -> dict[str, Any]:
    """One real-time run of the whole hand at ``shards`` shards: the run's summary figures."""
    with tempfile.TemporaryDirectory() as tmp:
        graph = hand_graph(src, shards, Path(tmp) / f"hand_{shards}.yaml")
        load0 = os.getloadavg()[0]
        proc = subprocess.run(
            [sys.executable, "-c", "import sys; from flowtact.cli import main; sys.exit(main())", "run", str(graph),
             "--duration", f"{duration_s:g}", "--json", "--quiet"],
            capture_output=True, text=True, timeout=600 + 20 * duration_s, check=False,
        )  # fmt: skip
        load1 = os.getloadavg()[0]
    if proc.returncode != 0:
        raise RuntimeError(f"flowtact run failed ({proc.returncode}): {proc.stderr.strip()[-400:]}")
    r = json.loads(proc.stdout)
    running = float(r["running_s"])
    cpu = sum(p["cpu_pct"] for p in r["processes"].values()) + r["supervisor"]["cpu_pct"]
    paths = r.get("paths") or {}
    worst = [p["p99_us"] for p in paths.values() if p.get("p99_us") is not None]  # one path per shard
    p99 = max(worst) / 1e3 if worst else None
    return {
        "shards": shards,
        "duration_s": duration_s,
        "realtime_factor": float(r["realtime_factor"]),
        "kept_up": bool(r["realtime"]),
        "max_lag_s": float(r["max_lag_s"]),
        "p99_ms": p99,
        "cpu_per_graph_s": cpu / 100.0 * running / duration_s,
        "load": (load0, load1),
        "spikes": sum(v for k, v in r["events"].items() if "__" not in k),
    }
