"""`flowtact info` and the refusal of damaged recordings by the command line (info, run, --replay)."""

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from flowtact.cli import main
from flowtact.recording.info import format_info, inspect_recording

ROOT = Path(__file__).resolve().parents[2]
TOUCH = str(ROOT / "graphs" / "touch.yaml")


@pytest.fixture(scope="module")
def touch(tmp_path_factory):
    """A fresh recording of the touch graph (1 s, in-process)."""
    path = tmp_path_factory.mktemp("info") / "touch.h5"
    assert (
        main(["run", TOUCH, "--fast", "--duration", "1", "--inproc", "--quiet", "--record", str(path)]) == 0
    )
    return path


def flip(src, dst, offset):
    shutil.copyfile(src, dst)
    with open(dst, "r+b") as fh:
        fh.seek(offset)
        b = fh.read(1)
        fh.seek(offset)
        fh.write(bytes([b[0] ^ 0x01]))
    return dst


def data_flipped(touch, tmp_path, dataset="/streams/sensor.r/data"):
    with h5py.File(touch, "r") as f:
        offset = f[dataset].id.get_chunk_info(0).byte_offset + 123
    return flip(touch, tmp_path / "bad.h5", offset)


def provenance_flipped(touch, tmp_path):
    raw = touch.read_bytes()
    needle = b"record:\n- sensor.r"  # block style: only in graph_yaml (the resolved graph), not the source
    assert raw.count(needle) == 1
    return flip(touch, tmp_path / "badprov.h5", raw.index(needle) + 3)


def test_info_of_an_intact_recording(touch, capsys):
    assert main(["info", str(touch)]) == 0
    out = capsys.readouterr().out
    assert "graph:      touch (seed 7), flowtact " in out
    assert "integrity:  ok (every checksum of 20 datasets and their attributes)" in out
    lines = {line.split()[0]: line.split() for line in out.splitlines() if line.startswith("  ")}
    assert lines["force.f"][:7] == ["force.f", "samples", "(3,)", "float64", "N", "1000", "Hz"]
    assert lines["sa1.spikes"][1] == "events" and "units" in lines["sa1.spikes"]
    assert lines["sa1_stim.y"][1] == "pulses"
    assert "1000" in lines["force.f"] and "0.000-0.999" in " ".join(lines["force.f"])
    assert "run:        1.000 s of graph time" in out and "error:      none" in out


def test_info_json(touch, capsys):
    assert main(["info", str(touch), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["integrity"] == "ok" and doc["problems"] == [] and doc["format_version"] == 2
    streams = {s["name"]: s for s in doc["streams"]}
    f = streams["force.f"]
    assert (f["kind"], f["shape"], f["units"], f["rate_hz"], f["samples"]) == (
        "samples",
        [3],
        "N",
        1000.0,
        1000,
    )
    assert f["t_first"] == 0.0 and f["t_last"] == 0.999 and f["bytes"] > 1000 * 3 * 8
    assert streams["sa1.spikes"]["n_units"] == 20 and streams["sa1.spikes"]["end_s"] == 1.0
    p = doc["provenance"]
    assert p["graph_name"] == "touch" and p["graph_seed"] == 7 and p["host"] and p["created_utc"]
    assert p["command"].startswith("flowtact") and p["flowtact_version"]
    assert doc["summary"]["duration_s"] == 1.0


def test_flipped_byte_in_stream_data(touch, tmp_path, capsys):
    bad = data_flipped(touch, tmp_path)
    assert main(["info", str(bad)]) == 1
    out = capsys.readouterr().out
    assert "integrity:  CORRUPTED (1 damaged):" in out
    assert "CORRUPTED: /streams/sensor.r/data: checksum mismatch in samples 0-" in out
    assert "force.f" in out  # what is intact is still described
    info = inspect_recording(bad)
    assert not info.ok and info.integrity == "CORRUPTED"


@pytest.mark.parametrize("inproc", [True, False])
def test_replay_refuses_a_flipped_byte_before_it_starts(touch, tmp_path, inproc):
    bad = data_flipped(touch, tmp_path)
    cmd = ["run", TOUCH, "--replay", f"sensor={bad}", "--fast", "--duration", "1", "--quiet"]
    r = subprocess.run(
        [sys.executable, "-m", "flowtact.cli", *cmd, *(["--inproc"] if inproc else [])],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
    )
    assert r.returncode == 1, r.stderr
    assert (
        "bad.h5: /streams/sensor.r/data: checksum mismatch in samples 0-999 (the file is corrupted)"
        in r.stderr
    )
    assert "Traceback" not in r.stderr and r.stdout == ""


def test_replay_of_the_intact_recording_runs(touch):
    assert (
        main(
            ["run", TOUCH, "--replay", f"sensor={touch}", "--fast", "--duration", "1", "--inproc", "--quiet"]
        )
        == 0
    )


def test_flipped_byte_in_provenance(touch, tmp_path, capsys):
    bad = provenance_flipped(touch, tmp_path)
    assert main(["info", str(bad)]) == 1
    out = capsys.readouterr().out
    assert "CORRUPTED: /: attribute 'graph_yaml' does not match its checksum" in out
    assert "graph:      touch (seed 7)" in out  # the intact attributes are still shown
    for cmd in (
        ["run", str(bad), "--fast", "--duration", "1", "--inproc"],
        ["run", TOUCH, "--replay", f"sensor={bad}", "--fast", "--duration", "1", "--inproc"],
    ):
        assert main(cmd) != 0, cmd  # 1 as a run error, or 2 where the replay is refused as the graph loads
        err = capsys.readouterr().err
        assert re.search(  # a replay's refusal is located at the file: badprov.h5:1:1: node ...
            r"badprov\.h5(:1:1: node 'sensor' \(replay\))?: /: attribute 'graph_yaml' does not match its "
            r"checksum \(the file is corrupted\)",
            err,
        ), err
        assert "Traceback" not in err


def test_truncated_and_foreign_files_one_line(touch, tmp_path, capsys):
    cut = tmp_path / "cut.h5"
    shutil.copyfile(touch, cut)
    os.truncate(cut, os.path.getsize(touch) - 5000)
    assert main(["info", str(cut)]) == 1
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.count("\n") == 1 and "cut.h5: truncated:" in captured.err
    (tmp_path / "notes.h5").write_text("just text\n")
    assert main(["info", str(tmp_path / "notes.h5")]) == 2  # refused as input, not damage
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert err.startswith(
        f"flowtact: error: {tmp_path / 'notes.h5'}: not a readable HDF5 file (it has no HDF5 signature)"
    )
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f["x"] = 1
    assert main(["info", str(tmp_path / "other.h5")]) == 2
    assert "not a flowtact recording (no /streams group)" in capsys.readouterr().err
    assert main(["info", str(tmp_path / "missing.h5")]) == 2  # a missing input file: bad input
    assert "recording not found" in capsys.readouterr().err


def test_old_recording_says_no_checksums(tmp_path, capsys):
    from test_record_integrity import write_format1

    path = write_format1(tmp_path / "old.h5")
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "(format 1)" in out and "integrity:  no checksums" in out
    assert "force.f" in out and "run:        no summary" in out


def test_format_info_lists_run_errors_and_counters(touch):
    info = inspect_recording(touch)
    info.summary = {
        "duration_s": 2.5,
        "wall_s": 3.0,
        "stopped_by": "error",
        "realtime": False,
        "error": "node 'sa1' (nlif) failed at t=1.2 s: boom",
        "counters": {"sa1_stim": {"dropped_rate": 4, "clipped_charge": 0}},
        "processes": {"afferents": {"restarts": 2}},
    }
    text = format_info(info)
    assert "stopped by error, NOT real time" in text
    assert "error:      node 'sa1' (nlif) failed at t=1.2 s: boom" in text
    assert "counters:   sa1_stim.dropped_rate 4" in text and "clipped_charge" not in text
    assert "restarts:   afferents 2" in text


ESC = "\x1b]0;pwned\x07\x1b[2J\x1b[H"  # retitle the terminal, clear the screen, cursor home
FORGED = "\nintegrity:  ok\u202e"


def _hostile_names(path):
    """A checksummed recording whose stream name, units, labels, command, host and an attribute
    name carry terminal escapes and a forged line."""
    from flowtact.chunk import Chunk, StreamSpec
    from flowtact.recording.hdf5 import Recorder

    spec = StreamSpec(dtype="float64", shape=(2,), units=f"N{ESC}", rate_hz=10.0, labels=(f"a{ESC}", "b"))
    prov = {"graph_name": f"g{ESC}", "command": f"flowtact run {ESC}{FORGED}", "host": f"h{ESC}"}
    with Recorder(path, {f"s{ESC}.y": spec}, prov) as rec:
        rec.write(f"s{ESC}.y", Chunk(np.arange(3) / 10.0, np.zeros((3, 2))))
    return path


def test_info_shows_text_from_the_file_as_data(tmp_path, capsys):
    path = _hostile_names(tmp_path / "esc.h5")
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "\x1b" not in out and "\x07" not in out and "\u202e" not in out  # no raw control character
    assert "s\\x1b]0;pwned\\x07\\x1b[2J\\x1b[H.y" in out  # the name, escaped, on its row
    assert "command:    flowtact run \\x1b]0;pwned" in out and "\\nintegrity:  ok\\u202e" in out
    assert sum(line.startswith("integrity:") for line in out.splitlines()) == 1  # no forged line
    assert main(["info", str(path), "--json"]) == 0
    raw = capsys.readouterr().out
    assert "\x1b" not in raw and json.loads(raw)["provenance"]["host"] == f"h{ESC}"  # JSON escapes itself


def test_info_cuts_long_text(tmp_path, capsys):
    from flowtact.chunk import StreamSpec
    from flowtact.recording.hdf5 import Recorder

    with Recorder(
        tmp_path / "long.h5", {"s.y": StreamSpec(dtype="float64", shape=(1,))}, {"host": "h" * 5000}
    ):
        pass
    assert main(["info", str(tmp_path / "long.h5")]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("recorded:"))
    assert line.endswith("h… (5,000 characters)") and len(line) < 300


def test_a_stream_that_cannot_be_described_fails_info(tmp_path, capsys):
    from test_record_integrity import write_format1

    path = write_format1(tmp_path / "old.h5")
    with h5py.File(path, "r+") as f:
        del f["streams/force.f/data"]  # an unchecksummed file: nothing else notices
    assert main(["info", str(path)]) == 1
    out = capsys.readouterr().out
    assert "damaged streams (not described): force.f" in out
    assert "CORRUPTED: /streams/force.f: cannot be described (missing" in out
