"""docs/sweeps.md is true: its commands and snippets run in order in a fresh folder, the outputs it
quotes are the ones they print, and the numbers it reads off the figure are in the table."""

from __future__ import annotations

import itertools
import re
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
from doc_pages import clean_env

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "sweeps.md"

pytestmark = [pytest.mark.slow, pytest.mark.cli]


def fenced() -> list[tuple[str, str]]:
    return re.findall(r"```(bash|python|text)\n(.*?)```", DOC.read_text(), re.S)


@pytest.fixture(scope="module")
def walked(tmp_path_factory):
    here = tmp_path_factory.mktemp("sweepdoc")
    (here / "graphs").symlink_to(ROOT / "graphs")
    env = clean_env(here)
    results = []
    for lang, body in fenced():
        if lang == "python" and body.startswith("# ") and body.split("\n", 1)[0].endswith(".py"):
            (here / body.split("\n", 1)[0][2:].strip()).write_text(body)
            continue
        if lang == "text":
            results.append(("text", body, None))
            continue
        cmd = ["bash", "-e", "-c", body] if lang == "bash" else [sys.executable, "-c", body]
        proc = subprocess.run(cmd, cwd=here, capture_output=True, text=True, timeout=300, env=env)
        results.append((lang, body, proc))
    return here, results


def test_every_command_and_snippet_runs(walked):
    _, results = walked
    ran = [(body, p) for lang, body, p in results if lang != "text"]
    assert len(ran) >= 7
    for body, proc in ran:
        assert proc.returncode == 0, f"{body}\n{proc.stderr}"
        assert "Traceback" not in proc.stderr, body


def test_quoted_outputs_are_what_the_commands_print(walked):
    _, results = walked
    quoted = 0
    for (lang, _body, proc), (nlang, nbody, _) in itertools.pairwise(results):
        if lang == "bash" and nlang == "text" and "flowtact sweep:" in nbody:
            assert proc.stderr.strip().splitlines()[-1] == nbody.strip()
            quoted += 1
    assert quoted == 2


def test_the_numbers_the_page_reads_off_the_figure(walked):
    here, _ = walked
    df = pd.read_parquet(here / "sa1-grid.parquet")
    assert (here / "sa1-grid.png").stat().st_size > 50_000
    rate = df.set_index(["sensor.scenario", "sa1.sigma", "sa1.tau_s"])["rate_hz:sa1.spikes"]
    assert round(rate[("touch", 0.0, 0.005)], 1) == 10.7 and round(rate[("touch", 0.0, 0.04)], 1) == 6.7
    lift = [
        rate[(s, 3.0, t)] - rate[(s, 0.0, t)] for s in ("touch", "slip") for t in (0.005, 0.01, 0.02, 0.04)
    ]
    assert round(min(lift), 1) == 1.3 and round(max(lift), 1) == 3.4
    ratio = [rate[("slip", g, t)] / rate[("touch", g, t)] for g in (0.0, 1.5, 3.0) for t in (0.005, 0.04)]
    assert min(ratio) >= 2 and max(ratio) <= 3
    assert df["rate_hz:fa1.spikes"].groupby(df["sensor.scenario"]).nunique().eq(1).all()
    rmse = pd.read_parquet(here / "replays.parquet")["rmse:force.f"]
    assert (rmse * 1e3).round(2).eq(0.86).all()
    peaks = pd.read_parquet(here / "peaks.parquet")
    assert (peaks["peak_force:peak_N"] > 0.3).all() and (peaks["status"] == "ok").all()
