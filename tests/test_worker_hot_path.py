"""The worker's hot path: what its latency figures mean, and that fast runs stay exact."""

from __future__ import annotations

import json

import pytest
from runs import flowtact

pytestmark = pytest.mark.slow

SLOW_SOURCE = """
name: slow_source
tick_s: 0.1
nodes:
  src:  {block: "hotpathblocks:SlowRamp", process: a, params: {rate_hz: 100, step_delay_s: 0.06}}
  gain: {block: "toyblocks:Scale", process: b}
edges:
  - src.y -> gain.x
record: [gain.y]
"""


def test_a_source_s_own_step_time_is_not_counted_as_transport_latency(tmp_path):
    """Each source step takes 60 ms; the message's latency starts once the data exists."""
    path = tmp_path / "slow.yaml"
    path.write_text(SLOW_SOURCE)
    proc = flowtact("run", str(path), "--duration", "3", "--json")
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 0, stderr
    summary = json.loads(stdout)
    lat = summary["streams"]["src.y"]["latency_us"]
    assert lat["n"] >= 5, lat
    # stamped before the step, every latency would be >= 60 000 µs
    assert lat["p50"] < 30_000, lat
