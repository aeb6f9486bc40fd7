"""Sweeps that cannot mix results, lose rows or hang (issue 30): a table from another setup is
never resumed into, a bad --out is refused before any run, a hung row times out alone, and the
sweep's numbers are range-checked."""

from __future__ import annotations

import os
from pathlib import Path

import pandas as pd
import pytest
from runs import TEST_BLOCKS, allow_args
from sweepblocks import TOY_GRAPH_SCALED

import flowtact
from flowtact.cli import main as cli_main
from flowtact.errors import SweepSpecError
from flowtact.sweeps import store


def main(argv: list[str]) -> int:
    """The ``flowtact`` command with the test blocks' modules allowed (docs/security.md)."""
    return cli_main(allow_args(argv))


GRID = ["src.noise=0,0.1"]


@pytest.fixture
def toy(tmp_path: Path) -> Path:
    p = tmp_path / "toy.yaml"
    p.write_text(TOY_GRAPH_SCALED)
    return p


def runs_logged(log: Path) -> int:
    return len(log.read_text().splitlines()) if log.exists() else 0


def test_a_table_from_another_setup_is_refused_and_left_as_it_was(toy: Path, tmp_path: Path, capsys) -> None:
    out, log = tmp_path / "sa1.parquet", tmp_path / "opens.log"
    fixed = [f"probe.log={log}"]
    first = flowtact.sweep(
        toy, allow_modules=TEST_BLOCKS, grid=GRID, overrides=fixed, duration_s=0.3, workers=1, out=out
    )
    assert (first["status"] == "ok").all() and first["setup"].nunique() == 1
    before, opened = out.read_bytes(), runs_logged(log)

    others = {  # each changes what a row computes while keeping every row's key
        "--duration 0.3 vs 0.2": dict(overrides=fixed, duration_s=0.2),
        "--set adds [dbl.gain=3]": dict(overrides=[*fixed, "dbl.gain=3"], duration_s=0.3),
        "--metrics drops [runtime]": dict(overrides=fixed, duration_s=0.3, metrics="spikes"),
    }
    for says, kwargs in others.items():
        with pytest.raises(SweepSpecError) as e:
            flowtact.sweep(toy, allow_modules=TEST_BLOCKS, grid=GRID, workers=1, out=out, **kwargs)
        assert str(e.value) == f"{out}: made by another setup ({says}); use another --out or --fresh"
    toy.write_text(TOY_GRAPH_SCALED.replace("gain: 2.0", "gain: 3.0"))  # another graph, the same grid
    assert main(["sweep", str(toy), "--set-grid", "src.noise=0,0.1", "--set", fixed[0], "--duration", "0.3",
                 "--workers", "1", "--out", str(out)]) == 2  # fmt: skip
    err = capsys.readouterr().err.strip()
    assert (
        err
        == f"flowtact sweep: error: {out}: made by another setup (the graph differs); use another --out or --fresh"
    )
    assert out.read_bytes() == before and runs_logged(log) == opened  # nothing ran, nothing was touched

    again = flowtact.sweep(
        toy,
        allow_modules=TEST_BLOCKS,
        grid=GRID,
        overrides=fixed,
        duration_s=0.3,
        workers=1,
        out=out,
        fresh=True,
    )
    assert again.attrs == {"executed": 2, "kept": 0}
    assert (pd.read_parquet(out)["setup"] != first["setup"].iloc[0]).all()
    resumed = flowtact.sweep(
        toy, allow_modules=TEST_BLOCKS, grid=GRID, overrides=fixed, duration_s=0.3, workers=1, out=out
    )
    assert resumed.attrs == {"executed": 0, "kept": 2}


def test_a_table_without_a_setup_record_is_refused(toy: Path, tmp_path: Path) -> None:
    out = tmp_path / "old.parquet"  # as an older flowtact (or pandas by hand) wrote it: keys, no setup
    key = '{"params":{"src.noise":0},"recordings":{}}'
    pd.DataFrame([{"src.noise": 0, "key": key, "status": "ok", "error": ""}]).to_parquet(out)
    with pytest.raises(SweepSpecError, match=r"old\.parquet: made by another setup \(it records none"):
        flowtact.sweep(toy, allow_modules=TEST_BLOCKS, grid=["src.noise=0"], workers=1, out=out)


def test_a_changed_replayed_file_is_another_setup(toy: Path, tmp_path: Path) -> None:
    log = tmp_path / "log.csv"
    log.write_text("t,y\n" + "".join(f"{i / 1000},{i}\n" for i in range(200)))
    out = tmp_path / "r.parquet"
    kwargs = dict(grid=["dbl.gain=2,3"], replay={"src": str(log)}, workers=1, out=out)
    assert (flowtact.sweep(toy, allow_modules=TEST_BLOCKS, **kwargs)["status"] == "ok").all()
    log.write_text(log.read_text().replace(",5\n", ",7\n"))  # the same name, other data
    with pytest.raises(SweepSpecError, match="a row's setup differs: a file it replayed has changed"):
        flowtact.sweep(toy, allow_modules=TEST_BLOCKS, **kwargs)


@pytest.mark.parametrize("where", ["missing-folder", "folder", "fifo", "unwritable-folder"])
def test_an_unwritable_out_is_refused_before_the_first_run(
    toy: Path, tmp_path: Path, where: str, capsys
) -> None:
    log = tmp_path / "opens.log"
    out = {
        "missing-folder": tmp_path / "nosuch" / "r.parquet",
        "folder": tmp_path,
        "fifo": tmp_path / "fifo.parquet",
        "unwritable-folder": Path("/proc/r.parquet"),  # no file can be made there, even by root
    }[where]
    if where == "fifo":
        os.mkfifo(out)
    says = {
        "missing-folder": f"the folder {out.parent} does not exist",
        "folder": "is a folder; give a file name (FILE.parquet)",
        "fifo": "is not a regular file",
        "unwritable-folder": "cannot write in /proc: ",
    }[where]
    code = main(["sweep", str(toy), "--set-grid", "src.noise=0,0.1", "--set", f"probe.log={log}",
                 "--out", str(out), "--workers", "1"])  # fmt: skip
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    assert err.startswith(f"flowtact sweep: error: --out {out}: {says}"), err
    assert runs_logged(log) == 0


def test_a_hung_row_times_out_its_process_is_killed_and_the_others_finish(toy: Path, tmp_path: Path) -> None:
    flag, log = tmp_path / "armed", tmp_path / "opens.log"
    flag.touch()
    fixed = [f"probe.flag={flag}", f"probe.log={log}"]
    # one worker: the hung row comes first, so the rows after it run only if the pool recovers
    df = flowtact.sweep(
        toy,
        allow_modules=TEST_BLOCKS,
        grid=["probe.mode=hang,ok,raise"],
        overrides=fixed,
        workers=1,
        row_timeout_s=2,
    )
    by = df.set_index("probe.mode")
    assert by.loc["hang", "status"] == "failed"
    assert by.loc["hang", "error"] == "timed out after 2 s (--row-timeout)"
    assert by.loc["ok", "status"] == "ok", by.loc["ok", "error"]
    assert "probe raised as asked" in by.loc["raise", "error"]
    hung = [int(line.split()[1]) for line in log.read_text().splitlines() if line.startswith("hang ")]
    assert len(hung) == 1
    with pytest.raises(ProcessLookupError):  # the hung run's process was killed (and reaped)
        os.kill(hung[0], 0)


@pytest.mark.parametrize(
    ("kwargs", "says"),
    [
        ({"workers": 0}, "--workers: expected a whole number from 1 to 4096; got 0"),
        ({"workers": True}, "--workers: expected a whole number from 1 to 4096; got True"),
        ({"duration_s": float("nan")}, "--duration: must be a finite number of seconds > 0; got nan"),
        ({"duration_s": -1}, "--duration: must be a finite number of seconds > 0; got -1"),
        ({"row_timeout_s": 0}, "--row-timeout: must be a finite number of seconds > 0; got 0"),
        ({"row_timeout_s": float("inf")}, "--row-timeout: must be a finite number of seconds > 0; got inf"),
    ],
)
def test_numbers_are_range_checked(toy: Path, kwargs: dict, says: str) -> None:
    with pytest.raises(SweepSpecError) as e:
        flowtact.sweep(toy, allow_modules=TEST_BLOCKS, grid=GRID, **kwargs)
    assert str(e.value) == says


@pytest.mark.parametrize("flag", [["--workers", "0"], ["--row-timeout", "-1"], ["--row-timeout", "nan"],
                                  ["--duration", "inf"]])  # fmt: skip
def test_bad_numeric_flags_exit_2(toy: Path, flag: list[str], capsys) -> None:
    with pytest.raises(SystemExit) as e:
        main(["sweep", str(toy), *flag])
    assert e.value.code == 2
    assert f"argument {flag[0]}" in capsys.readouterr().err


def test_a_table_over_budget_is_refused_before_its_rows_are_read(
    toy: Path, tmp_path: Path, monkeypatch
) -> None:
    out = tmp_path / "big.parquet"
    flowtact.sweep(toy, allow_modules=TEST_BLOCKS, grid=GRID, workers=1, out=out)
    monkeypatch.setattr(store, "MAX_TABLE_ROWS", 1)
    with pytest.raises(SweepSpecError, match=r"big\.parquet: cannot resume from it, it declares 2 rows"):
        flowtact.sweep(toy, allow_modules=TEST_BLOCKS, grid=GRID, workers=1, out=out)


def hostile_table(path: Path, rows: int, setup_of: str | None) -> None:
    """A table of ``rows`` rows whose every cell is one 1000-character text, dictionary-encoded: a
    few hundred KB on disk, 4 GB if read naively; its setup is ``setup_of`` graph's (forged) or none."""
    import json

    import numpy as np
    import pyarrow as pa
    import pyarrow.parquet as pq

    from flowtact.sweeps.api import setup
    from flowtact.sweeps.metrics import parse_metrics

    one = pa.DictionaryArray.from_arrays(pa.array(np.zeros(rows, dtype=np.int32)), pa.array(["x" * 1000]))
    table = pa.table({"key": one, "status": one, "setup": one, "error": one})
    if setup_of is not None:
        made = setup(Path(setup_of).read_text(), [], 0.1, parse_metrics(None))
        table = table.replace_schema_metadata({store.SETUP_KEY: json.dumps(made, sort_keys=True).encode()})
    pq.write_table(table, path)


@pytest.mark.parametrize(
    ("rows", "forged", "says"),
    [
        (1_000_000, False, "made by another setup (it records none"),
        (1_000_000, True, "cannot resume from it, its rows hold 4,032,000,000 bytes (at most 268,435,456)"),
        (1_000_001, True, "cannot resume from it, it declares 1,000,001 rows"),
    ],
)
def test_a_hostile_table_is_refused_in_bounded_time_and_memory(tmp_path: Path, rows: int, forged: bool,
                                                               says: str) -> None:  # fmt: skip
    from hostile import TOUCH, run_measured

    out = tmp_path / "hostile.parquet"
    hostile_table(out, rows, TOUCH if forged else None)
    m = run_measured(["sweep", TOUCH, "--set-grid", "sa1.tau_s=0.01", "--duration", "0.1", "--out", str(out),
                      "--quiet"], timeout_s=120)  # fmt: skip
    assert m.returncode == 2, m.stderr
    first = m.stderr.splitlines()[0]
    assert first.startswith("flowtact sweep: error: ") and str(out) in first and says in first, first
    assert m.peak_mib < 500, f"peak RSS {m.peak_mib:.0f} MiB"
