"""scripts/step_costs.py, which docs and bench/README cite: each node's step cost, hot or woken."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest
from runs import ROOT

NODES = ("sensor", "force", "savgol", "drive", "nlif")  # bench/graphs/chain.yaml, in order


def _costs(*args: str) -> str:
    cmd = [sys.executable, str(ROOT / "scripts" / "step_costs.py"), "bench/graphs/chain.yaml", *args]
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    return done.stdout


@pytest.mark.parametrize(
    ("args", "steps", "whole"),
    [(("--duration", "0.2"), 200, True), (("--duration", "0.05", "--wake", "0.0002"), 50, False)],
)
def test_every_node_gets_its_mean_and_median_step_cost(args, steps, whole):
    out = _costs(*args)
    for node in NODES:
        m = re.search(rf"^  {node} +([\d.]+) µs per step, median ([\d.]+)  \((\d+) steps\)$", out, re.M)
        assert m, (node, out)
        assert float(m[1]) > 0 and float(m[2]) > 0 and int(m[3]) == steps
    assert ("the whole run:" in out) == whole, out
    if not whole:  # a sleep before the first node of each of chain.yaml's three processes
        assert "a 0.2 ms sleep before drive, savgol, sensor" in out, out
