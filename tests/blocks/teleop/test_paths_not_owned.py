"""A graph's serial_io never steers the emulator to a file, nor writes to a port that is a file; the
emulator itself (`flowtact sim exo`) never replaces, deletes or appends to an existing file (issue 30:
"a graph file touches files it does not own"), and its bad flags are one-line usage errors."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from flowtact.blocks.teleop.exo_emulator import main as sim_exo
from flowtact.blocks.teleop.serial_io import SerialIo, SerialIoConfig
from flowtact.errors import ConfigError

PRECIOUS = "t,x\n0,1\n"


def precious(tmp_path: Path) -> Path:
    f = tmp_path / "data.csv"
    f.write_text(PRECIOUS)
    return f


def flowtact(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "flowtact.cli", *args], capture_output=True, text=True, cwd=cwd, timeout=300
    )


# -- the graph: serial_io's config -------------------------------------------------------------


@pytest.mark.parametrize(
    "args,rule",
    [
        (["--link", "{f}"], "must not hold --link: a graph never names files"),
        (["--log", "{f}"], "must not hold --log: a graph never names files"),
        (["--truth", "--log={f}"], "must not hold --log"),
        (["--li", "{f}"], "must hold flags of `flowtact sim exo` only; got '--li'"),  # no abbreviations
        (["--lo", "{f}"], "must hold flags of `flowtact sim exo` only; got '--lo'"),
        (["{f}"], "must hold flags of `flowtact sim exo` only"),
        (["--rate-hz", "5"], "must not hold --rate-hz: serial_io sets it (set rate_hz)"),
        (["--help"], "must not hold --help"),
        (["--seed", "-1"], "--seed: must be an integer in [0, 9223372036854775807], got '-1'"),
        (["--drift-ppm", "nan"], "--drift-ppm: must be a finite number in [-10000, 10000] ppm, got 'nan'"),
        (["--user", "idle", "grasp"], "--user takes 1 or 3 values"),
        (["--truth=yes"], "--truth takes no value"),
        (["--jitter-ms"], "--jitter-ms needs a value"),
    ],
)
def test_emulator_args_may_not_name_files_or_unknown_flags(tmp_path, args, rule):
    f = precious(tmp_path)
    with pytest.raises(ConfigError) as e:
        SerialIoConfig.build(
            {"port": "emulator", "emulator_args": [a.format(f=f) for a in args]}, owner="exo (serial_io)"
        )
    assert e.value.field == "emulator_args"
    assert rule in str(e.value) and "\n" not in str(e.value)
    assert f.read_text() == PRECIOUS


def test_the_emulators_own_flags_are_accepted():
    args = [
        "--truth",
        "--drift-ppm",
        "-120",
        "--replug-s=0.3",
        "--user",
        "idle",
        "grasp",
        "idle",
        "--no-noise",
    ]
    assert SerialIoConfig.build({"port": "emulator", "emulator_args": args}).emulator_args == tuple(args)


def test_a_port_that_is_not_a_device_is_refused(tmp_path):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    for path in (precious(tmp_path), tmp_path, fifo):
        with pytest.raises(ConfigError, match="is not a character device") as e:
            SerialIoConfig.build({"port": str(path)})
        assert e.value.field == "port"
    for port in ("sim", "emulator", "/dev/null", str(tmp_path / "ttyACM9")):  # absent: plugged in later
        assert SerialIoConfig.build({"port": port}).port == port
    with pytest.raises(ConfigError, match="'port' must be 'sim', 'emulator' or a serial device"):
        SerialIoConfig.build({"port": ""})
    assert (tmp_path / "data.csv").read_text() == PRECIOUS


def test_a_port_that_became_a_file_is_never_opened(tmp_path, caplog):
    pytest.importorskip("serial")
    port = tmp_path / "ttyUSB7"
    block = SerialIo(port=str(port), reconnect_s=0.001)  # absent when checked: accepted
    port.write_text(PRECIOUS)  # then a file appears there
    block.bind({})
    block.open()
    try:
        for k in range(1, 20):
            block(k * 0.001)
        assert "connects" not in block.counters
    finally:
        block.close()
    assert port.read_text() == PRECIOUS
    said = [r.getMessage() for r in caplog.records if "not a character device" in r.getMessage()]
    assert len(said) == 1 and str(port) in said[0]  # said once, not per retry


GRAPHS = {
    "link": "nodes:\n  exo: {{block: serial_io, params: {{port: emulator, emulator_args: [--link, {f}]}}}}\n",
    "log": "nodes:\n  exo: {{block: serial_io, params: {{port: emulator, emulator_args: [--log, {f}]}}}}\n",
    "port": "nodes:\n  exo: {{block: serial_io, params: {{port: {f}}}}}\n",
}


@pytest.mark.parametrize("case", sorted(GRAPHS))
def test_a_graph_naming_a_file_is_refused_before_anything_runs(tmp_path, case):
    f = precious(tmp_path)
    (tmp_path / "g.yaml").write_text(GRAPHS[case].format(f=f))
    before = sorted(os.listdir(tmp_path))
    r = flowtact("run", "g.yaml", "--duration", "1", cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    assert r.stderr.startswith("g.yaml:2:") and "exo (serial_io):" in r.stderr.splitlines()[0], r.stderr
    assert "Traceback" not in r.stderr
    assert f.read_text() == PRECIOUS and sorted(os.listdir(tmp_path)) == before


# -- the emulator: flowtact sim exo --------------------------------------------------------------


def test_sim_exo_never_links_over_an_existing_file_or_folder(tmp_path):
    f = precious(tmp_path)
    (tmp_path / "folder").mkdir()
    for path, what in ((f, "a regular file"), (tmp_path / "folder", "a folder")):
        r = flowtact("sim", "exo", "--link", str(path), cwd=tmp_path)
        assert r.returncode == 2, r.stderr
        assert (
            r.stderr
            == f"flowtact sim exo: error: --link {path}: exists and is {what}; it is never replaced "
            + ("(give a new path, or a stale pty link)\n")
        )
    assert f.read_text() == PRECIOUS and (tmp_path / "folder").is_dir()
    assert sorted(os.listdir(tmp_path)) == ["data.csv", "folder"]


def test_sim_exo_writes_its_log_to_a_new_file_only(tmp_path, capsys):
    f = precious(tmp_path)
    assert sim_exo(["--log", str(f)]) == 2
    assert capsys.readouterr().err == (
        f"flowtact sim exo: error: --log {f}: is an existing file; the log is only ever written to a new file\n"
    )
    assert sim_exo(["--log", str(tmp_path)]) == 2
    assert "is a folder" in capsys.readouterr().err
    (tmp_path / "to_new").symlink_to(tmp_path / "new.log")  # a dangling link is not followed either
    assert sim_exo(["--log", str(tmp_path / "to_new")]) == 2
    capsys.readouterr()
    assert f.read_text() == PRECIOUS and not (tmp_path / "new.log").exists()
