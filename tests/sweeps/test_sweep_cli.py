"""``flowtact sweep`` as a user runs it: usage errors (exit 2), failed rows (exit 1), replays, Ctrl-C."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest
from runs import allow_args, env, flowtact
from sweepblocks import TOY_GRAPH

from flowtact.cli import main

pytestmark = pytest.mark.cli


def sweep(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "flowtact.cli", *allow_args(["sweep", *args])], capture_output=True,
                          text=True, env=env(), cwd=cwd, timeout=300)  # fmt: skip


@pytest.fixture
def toy(tmp_path: Path) -> Path:
    p = tmp_path / "toy.yaml"
    p.write_text(TOY_GRAPH)
    return p


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["--set-grid", "src.noise"], "--set-grid 'src.noise': expected node.param=v1,v2,..."),
        (["--set-grid", "src.noise=[1,"], "--set-grid 'src.noise=[1,': the value is not valid YAML"),
        (["--set-grid", "nosuch.gain=1,2"], "nosuch.gain: the graph has no node 'nosuch'"),
        (["--set-grid", "src.nosuch=1,2"], "src.nosuch: block toyblocks:Ramp has no parameter 'nosuch'"),
        (["--set-grid", "src.noise=1,1"], "a value is listed twice"),
        (["--replay", "src=/nonexistent/*.h5"], "--replay src=/nonexistent/*.h5: no file matches"),
        (["--metrics", "spikes,wobble"], "--metrics: unknown metric 'wobble'"),
        (["--metrics", "nosuchmodule:f"], "--metrics nosuchmodule:f: cannot import module 'nosuchmodule'"),
        (["--rmse", "probe.y=nosuch.y"], "'nosuch.y' is not a recorded stream of the graph"),
        (["--table", "missing.csv"], "--table missing.csv: "),
        (["--set", "src.noise=0"], "the graph has no duration_s and replays no file: give --duration"),
    ],
)
def test_usage_errors_are_one_line_and_exit_2(toy: Path, args: list[str], says: str, capsys) -> None:
    if "--duration" in says:
        toy.write_text(toy.read_text().replace("duration_s: 0.3\n", ""))
    assert main(allow_args(["sweep", str(toy), *args])) == 2
    err = capsys.readouterr().err.strip()
    assert says in err and len(err.splitlines()) == 1, err


def test_without_pandas_it_names_the_extra(toy: Path, monkeypatch, capsys) -> None:
    import flowtact.graphfile.extras

    real = flowtact.graphfile.extras.module_available
    monkeypatch.setattr(flowtact.graphfile.extras, "module_available", lambda m: m != "pandas" and real(m))
    assert main(allow_args(["sweep", str(toy), "--set-grid", "src.noise=0,1"])) == 2
    assert 'flowtact sweep needs pandas: pip install "flowtact[sweep]"' in capsys.readouterr().err


def test_core_commands_do_not_import_pandas_or_dask() -> None:
    code = ("import sys, flowtact, flowtact.cli; flowtact.cli.build_parser(); "
            "print(sorted(m for m in ('pandas', 'pyarrow', 'dask', 'distributed') if m in sys.modules))")  # fmt: skip
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_table_and_replayed_recordings_with_a_failing_row(toy: Path, tmp_path: Path) -> None:
    recs = tmp_path / "recs"
    recs.mkdir()
    for noise in (0.0, 0.2):
        done = subprocess.run([sys.executable, "-m", "flowtact.cli", *allow_args(["run", str(toy), "--fast", "--quiet",
                               "--set", f"src.noise={noise}", "--record", str(recs / f"n{noise}.h5")])],
                              env=env(), capture_output=True, text=True, timeout=120)  # fmt: skip
        assert done.returncode == 0, done.stderr
    table = tmp_path / "rows.csv"
    table.write_text("probe.mode,probe.flag\nok,\nraise,/\n")  # '/' exists: the raise row raises
    out = tmp_path / "res.parquet"
    done = sweep(str(toy), "--table", str(table), "--replay", f"src={recs}/*.h5", "--out", str(out),
                 "--workers", "2", "--metrics", "sweepblocks:mean_y")  # fmt: skip
    assert done.returncode == 1, done.stderr
    assert "4 runs (4 run now, 0 kept from before): 2 ok, 2 failed" in done.stderr
    assert "failed: probe.flag=/ probe.mode=raise src=" in done.stderr
    df = pd.read_parquet(out)
    assert sorted(df["recording:src"].map(lambda p: Path(p).name)) == [
        "n0.0.h5",
        "n0.0.h5",
        "n0.2.h5",
        "n0.2.h5",
    ]
    ok = df[df["status"] == "ok"].set_index("recording:src")["mean_y:mean"]
    assert ok.nunique() == 2  # each run played its own recording


def test_ctrl_c_keeps_finished_rows(toy: Path, tmp_path: Path) -> None:
    out = tmp_path / "res.parquet"
    slow = toy.read_text().replace("duration_s: 0.3", "duration_s: 1000")
    toy.write_text(slow.replace("noise: 0.1", "noise: 0.1, rate_hz: 20000"))
    p = flowtact("sweep", str(toy), "--set-grid", "src.noise=" + ",".join(str(i / 100) for i in range(40)),
                 "--workers", "1", "--out", str(out), "--duration", "2")  # fmt: skip
    deadline = time.monotonic() + 120
    lines = []
    while time.monotonic() < deadline:
        line = p.stderr.readline()
        lines.append(line)
        if line.startswith("sweep: 4 done"):
            break
    else:
        p.kill()
        pytest.fail(f"no progress line: {lines}")
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=120)
    assert p.returncode == 130, err
    assert f"interrupted; finished runs are in {out}" in err
    df = pd.read_parquet(out)
    assert 4 <= len(df) < 40 and (df["status"] == "ok").all()
