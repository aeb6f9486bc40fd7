"""One error path for every command (issue 30): a bad flag of any plugin command is ONE line on
stderr and exit status 2, never a traceback; every number from a flag is range-checked (NaN,
infinities, negatives, absurd sizes) before anything is allocated; whatever a command raises, the
built-ins' and the plugins' alike, prints one line with control characters escaped, exit 1 for a
failed run, the traceback only with --debug.
"""

from __future__ import annotations

import json

import pytest
from hostile import TOUCH, run_measured

from flowtact import cli
from flowtact.cli import main
from flowtact.commands import Command
from flowtact.console.debug import ENV, HINT

PEAK_MIB = 500  # the bound on a refusal's peak memory

SEED_RANGE = "must be an integer in [0, 9223372036854775807]"
PLUGIN_MISUSE = [
    # flowtact sim / sim exo
    (["sim", "nope"], "unknown device 'nope'; devices: exo"),
    (["sim", "exo", "--seed", "-1"], f"argument --seed: {SEED_RANGE}, got '-1'"),
    (["sim", "exo", "--rate-hz", "0"], "argument --rate-hz: must be a finite number in (0, 10000] Hz"),
    (["sim", "exo", "--rate-hz", "nan"], "argument --rate-hz: must be a finite number in (0, 10000] Hz"),
    (["sim", "exo", "--rate-hz", "1e308"], "argument --rate-hz: must be a finite number in (0, 10000] Hz"),
    (["sim", "exo", "--rate-hz", "fast"], "argument --rate-hz: expected a number, got 'fast'"),
    (["sim", "exo", "--period-s", "-1"], "argument --period-s: must be a finite number in [4, 3600] s"),
    (["sim", "exo", "--replug-s", "nan"], "argument --replug-s: must be a finite number in [0, 60] s"),
    (
        ["sim", "exo", "--drift-ppm", "inf"],
        "argument --drift-ppm: must be a finite number in [-10000, 10000]",
    ),
    (["sim", "exo", "--offset-s", "-1"], "argument --offset-s: must be a finite number in [0, 4294.97] s"),
    (
        ["sim", "exo", "--latency-ms", "nan"],
        "argument --latency-ms: must be a finite number in [0, 10000] ms",
    ),
    (["sim", "exo", "--jitter-ms", "-1"], "argument --jitter-ms: must be a finite number in [0, 10000] ms"),
    (["sim", "exo", "--max-push-n", "0"], "argument --max-push-n: must be a finite number in (0, 100] N"),
    (["sim", "exo", "--object-stiffness", "nan"], "argument --object-stiffness: must be a finite number"),
    (["sim", "exo", "--object-closure", "2"], "argument --object-closure: must be a finite number in [0, 1]"),
    (["sim", "exo", "--user", "grasp", "idle"], "argument --user: takes 1 or 3 values"),
    (
        ["sim", "exo", "--log", "{tmp}"],
        "--log {tmp}: is a folder; the log is only ever written to a new file",
    ),
    # flowtact fit-force
    (["fit-force", "{tmp}/r.h5", "--json", "{tmp}"], "--json {tmp}: is a folder; give the file to write"),
    (["fit-force", "{tmp}/r.h5", "--tol-s", "nan"], "argument --tol-s: must be a finite number in [0, 1] s"),
    (["fit-force", "{tmp}/missing.h5"], "recording not found: {tmp}/missing.h5"),
    # flowtact train-force (flags are checked before torch is imported)
    (["train-force", "r.h5", "--threads", "-1"], "argument --threads: must be an integer in [0, 1024]"),
    (
        ["train-force", "r.h5", "--time-limit", "nan"],
        "argument --time-limit: must be a finite number in (0, 1e+07] s",
    ),
    (["train-force", "r.h5", "--epochs", "0"], "argument --epochs: must be an integer in [1, 100000]"),
    (["train-force", "r.h5", "--patience", "1e9"], "argument --patience: must be an integer in [1, 100000]"),
    (["train-force", "r.h5", "--batch-size", "1"], "argument --batch-size: must be an integer in [2, 65536]"),
    (["train-force", "r.h5", "--lr", "inf"], "argument --lr: must be a finite number in (0, 10]"),
    (["train-force", "r.h5", "--l2", "nan"], "argument --l2: must be a finite number in [0, 1e+06]"),
    (["train-force", "r.h5", "--downsample", "0"], "argument --downsample: must be an integer in [1, 64]"),
    (["train-force", "r.h5", "--seed", "-1"], f"argument --seed: {SEED_RANGE}"),
    (["train-force", "r.h5", "--lr-plateau", "2.5"], "argument --lr-plateau: expected an integer, got '2.5'"),
    (["train-force", "r.h5", "--crop", "0,0,0,0"], "argument --crop: x0, y0 must be in [0, 100000] and w, h"),
    (["train-force", "r.h5", "--sensors", "7"], "argument --sensors: sensor '7': use thumb, index, middle"),
    # flowtact train-braille
    (["train-braille", "--bins", "1e9"], "argument --bins: must be an integer in [1, 100], got '1e9'"),
    (["train-braille", "--alpha", "nan"], "argument --alpha: must be a finite number in (0, 1e+06]"),
    (["train-braille", "--var-smoothing", "inf"], "argument --var-smoothing: must be a finite number"),
    (["train-braille", "--repeats", "1e9"], "argument --repeats: must be an integer in [1, 100000]"),
    (["train-braille", "--letters", "1e12"], "argument --letters: must be an integer in [1, 10000]"),
    (["train-braille", "--seed", "-1"], f"argument --seed: {SEED_RANGE}"),
    (["train-braille", "--speeds", "nan"], "argument --speeds: speeds must be in (0, 1000] mm/s"),
    (
        ["train-braille", "--letters", "10000", "--repeats", "3"],
        "--letters 10000 × 9 runs (--speeds × --repeats) is 90000 letters; at most 30000 in all",
    ),
    (
        ["train-braille", "--letters", "10000", "--bins", "100"],
        "30000 windows × 24 units × --bins 100 need 549.3 MiB of features; at most 256.0 MiB",
    ),
]


def _ids(case: object) -> str:
    return " ".join(case) if isinstance(case, list) else ""


@pytest.mark.parametrize(("argv", "text"), PLUGIN_MISUSE, ids=_ids)
def test_every_plugin_commands_bad_flag_is_one_line_and_status_2(argv, text, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)  # nothing a refused command might write lands in the checkout
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    (tmp_path / "r.h5").write_bytes(b"")  # an existing file, for the commands that check before reading
    assert main(argv) == 2
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"flowtact {argv[0]}") and ": error: " in lines[0], err
    assert text.replace("{tmp}", str(tmp_path)) in lines[0], err
    assert "Traceback" not in err and HINT not in err  # a usage error has no traceback to offer
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.h5"]  # nothing written


RUN_MISUSE = [
    (["run", TOUCH, "--duration", "1e308"], "argument --duration: must be at most 1e+10 s, got '1e308'"),
    (["run", TOUCH, "--tick", "1e-12"], "argument --tick: must be at least 1e-06 s, got '1e-12'"),
    (
        ["run", TOUCH, "--startup-s", "0"],
        "argument --startup-s: must be a finite number in (0, 86400] s, got '0'",
    ),
    (
        ["run", TOUCH, "--startup-s", "nan"],
        "argument --startup-s: must be a finite number in (0, 86400] s, got 'nan'",
    ),
]


@pytest.mark.parametrize(("argv", "text"), RUN_MISUSE, ids=_ids)
def test_an_absurd_duration_or_tick_is_a_usage_error(argv, text, capsys):
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert err.strip().splitlines() == [f"flowtact run: error: {text} (see flowtact run --help)"]


@pytest.mark.parametrize(
    ("flags", "said"),
    [
        (["--duration", "1e7", "--tick", "0.001"], "--duration and --tick: 1e+07 s at a 0.001 s tick"),
        (["--duration", "2e9"], "--duration and the default tick (--fast): 2e+09 s at a 1 s tick"),
    ],
)
def test_a_run_of_more_than_a_billion_ticks_is_refused_naming_its_flags(flags, said, tmp_path, capsys):
    out = tmp_path / "r.h5"
    assert main(["run", TOUCH, "--fast", "--quiet", "--record", str(out), *flags]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"flowtact: error: {said}"), err
    assert err[0].endswith("a run takes at most 1e+09")
    assert not out.exists()  # refused before anything started


MEASURED = [
    ["train-braille", "--repeats", "1000000000"],  # was 9.6 GB
    ["train-braille", "--letters", "1000000000000"],  # hung
    ["train-braille", "--bins", "1000000000"],  # MemoryError: 45 TiB
    ["train-braille", "--letters", "10000", "--bins", "100"],  # over the feature budget
    ["run", TOUCH, "--fast", "--duration", "1e7", "--tick", "0.001"],  # hung
]


@pytest.mark.parametrize("argv", MEASURED, ids=_ids)
def test_a_size_from_a_flag_is_refused_before_it_is_allocated(argv, tmp_path):
    m = run_measured([*argv, *(["--out", str(tmp_path / "m.npz")] if argv[0] == "train-braille" else [])])
    assert m.returncode == 2, m.stderr
    lines = [x for x in m.stderr.splitlines() if not x.startswith("peak_rss_kib=")]
    assert len(lines) == 1 and ": error: " in lines[0], m.stderr
    assert m.peak_mib < PEAK_MIB, f"peak RSS {m.peak_mib:.0f} MiB"
    assert not (tmp_path / "m.npz").exists()


# -- whatever a command raises: the same one line, built-in or plugin -------------------------------


class _EntryPoint:
    """A stand-in for an installed plugin command whose ``main`` does ``body``."""

    def __init__(self, body):
        self.body = body

    name, value = "x", "tests:x"

    def load(self):
        return Command(main=lambda argv: self.body(argv))


def _raise(e: BaseException):
    def body(_argv):
        raise e

    return body


def _argparse_exit(argv):
    import argparse

    ap = argparse.ArgumentParser(prog="flowtact plain")  # a plugin with argparse's own parser
    ap.add_argument("--n", type=int)
    ap.parse_args(argv)
    return 0


PWNED = "\x1b]0;pwned\x07"


@pytest.fixture
def plugin(monkeypatch):
    """Install a fake plugin command ``flowtact x`` running ``body``; returns the installer."""

    def install(body):
        monkeypatch.setattr(cli, "find_commands", lambda: {"x": _EntryPoint(body)})

    monkeypatch.delenv(ENV, raising=False)
    return install


@pytest.mark.parametrize(
    ("error", "status", "line"),
    [
        (RuntimeError(f"boom {PWNED}"), 1, "flowtact x: error: RuntimeError: boom \\x1b]0;pwned\\x07"),
        (
            MemoryError("Unable to allocate 1.55 TiB for an array with shape (1, 2)"),
            1,
            "flowtact x: error: not enough memory: Unable to allocate 1.55 TiB",
        ),
        (RecursionError("maximum recursion depth exceeded"), 1, "flowtact x: error: input nested too deeply"),
        (
            json.JSONDecodeError("Expecting property name enclosed in double quotes", "{x", 1),
            1,
            "flowtact x: error: not valid JSON: Expecting property name enclosed in double quotes: line 1",
        ),
        (
            IsADirectoryError(21, "Is a directory", f"out{PWNED}"),
            2,
            "flowtact x: error: out\\x1b]0;pwned\\x07: Is a",
        ),
        (KeyError("nope"), 1, "flowtact x: error: KeyError: 'nope'"),
    ],
    ids=["escapes", "memory", "recursion", "json", "folder", "keyerror"],
)
def test_what_a_plugin_raises_is_one_escaped_line(plugin, capsys, error, status, line):
    plugin(_raise(error))
    assert main(["x"]) == status
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1, err
    assert err.startswith(line), err
    assert "\x1b" not in err and "\x07" not in err and "Traceback" not in err
    assert err.rstrip().endswith(HINT) == (status == 1)  # a failed run offers its traceback


def test_debug_adds_the_traceback_escaped_for_plugins_too(plugin, capsys):
    plugin(_raise(RuntimeError(f"boom {PWNED}")))
    assert main(["--debug", "x"]) == 1
    err = capsys.readouterr().err
    first, rest = err.split("\n", 1)
    assert first == "flowtact x: error: RuntimeError: boom \\x1b]0;pwned\\x07"
    assert rest.startswith("Traceback (most recent call last):") and "in body" in rest
    assert "\x1b" not in err


def test_a_plugins_own_argparse_exit_keeps_its_status(plugin, capsys):
    plugin(_argparse_exit)
    assert main(["x", "--n", "many"]) == 2
    assert "argument --n: invalid int value: 'many'" in capsys.readouterr().err
    assert main(["x", "--help"]) == 0


def test_a_plugin_that_cannot_be_loaded_is_one_line(monkeypatch, capsys):
    class Broken:
        def load(self):
            raise ImportError("No module named 'gone'")

    monkeypatch.setattr(cli, "find_commands", lambda: {"x": Broken()})
    assert main(["x"]) == 1
    err = capsys.readouterr().err
    assert err == f"flowtact x: error: No module named 'gone' {HINT}\n"


def test_a_built_in_commands_error_text_is_escaped_too(tmp_path, capsys):
    name = str(tmp_path / f"rec{PWNED}.h5")
    assert main(["info", name]) == 2  # a file the user named that is not there: bad input
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1, err
    assert "rec\\x1b]0;pwned\\x07.h5" in err and "\x1b" not in err and "\x07" not in err


def test_a_damaged_json_file_is_named(tmp_path, capsys):
    """``Expecting property name…`` alone said neither which file nor what it should be."""
    bad = tmp_path / "earlier" / "results" / "executor.json"
    bad.parent.mkdir(parents=True)
    bad.write_text("{'suite': 1}")
    assert (
        main(["bench", "executor", "--out", str(tmp_path / "o"), "--compare", str(tmp_path / "earlier")]) == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        f"flowtact: error: --compare: {bad}: not a results file of flowtact bench "
        "(Expecting property name enclosed in double quotes: line 1 column 2 (char 1))"
    ]
    assert not (tmp_path / "o").exists()  # refused before a suite ran


def test_a_sweeps_duration_is_bounded_like_a_runs(capsys):
    with pytest.raises(SystemExit) as e:
        main(["sweep", TOUCH, "--set-grid", "sa1.n=1,2", "--duration", "1e308"])
    assert e.value.code == 2
    assert "argument --duration: must be at most 1e+10 s, got '1e308'" in capsys.readouterr().err
