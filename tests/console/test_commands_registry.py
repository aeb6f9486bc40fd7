"""Every ``flowtact`` command registers one way (issue 32, Deliver 4): a Command named in the
``flowtact.commands`` entry-point group, the built-in ones included; a toy command added through a
(fake) entry point parses, runs, fails and documents itself exactly as the built-ins do."""

from __future__ import annotations

import argparse
from importlib.metadata import EntryPoint, entry_points

import pytest

from flowtact import cli
from flowtact.cli import main
from flowtact.commands import GROUP, Command

BUILT_INS = {"run", "validate", "graph", "blocks", "plot", "info", "bench", "sweep", "worker", "keys"}
SEEN: list[argparse.Namespace] = []


def _add(sp: argparse.ArgumentParser) -> None:
    sp.add_argument("word")
    sp.add_argument("--times", type=int, default=1)


def _run(args: argparse.Namespace) -> int:
    SEEN.append(args)
    if args.word == "fail":
        raise RuntimeError("the toy failed")
    print(" ".join([args.word] * args.times))
    return 0


TOY = Command(
    run=_run, add_arguments=_add, check=lambda a: "--times must be positive" if a.times < 1 else None
)
"""The toy command ``flowtact toy WORD [--times N]``."""


@pytest.fixture
def toy(monkeypatch):
    """The installed commands plus ``toy``, named by a fake entry point of this module."""
    real = cli.find_commands()
    fake = EntryPoint(name="toy", value=f"{__name__}:TOY", group=GROUP)
    monkeypatch.setattr(cli, "find_commands", lambda: {**real, "toy": fake})
    SEEN.clear()


def test_every_built_in_command_is_an_entry_point_of_the_one_group():
    eps = {ep.name: ep for ep in entry_points(group=GROUP)}
    assert set(eps) >= BUILT_INS
    for name in BUILT_INS | {"sim", "train-force", "fit-force", "train-braille"}:
        assert isinstance(eps[name].load(), Command), name


@pytest.mark.usefixtures("toy")
def test_a_toy_command_runs_through_main(capsys):
    assert main(["toy", "hey", "--times", "2"]) == 0
    assert capsys.readouterr().out == "hey hey\n"
    assert SEEN[0].command == "toy" and SEEN[0].times == 2


@pytest.mark.usefixtures("toy")
def test_a_toy_command_fails_and_misuses_as_the_built_ins(capsys):
    assert main(["toy", "fail"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("flowtact: error: RuntimeError: the toy failed") and "Traceback" not in err
    with pytest.raises(SystemExit) as bad:
        main(["toy", "hey", "--times", "many"])
    assert bad.value.code == 2
    assert "argument --times: invalid int value: 'many'" in capsys.readouterr().err
    with pytest.raises(SystemExit) as checked:
        main(["toy", "hey", "--times", "0"])
    assert checked.value.code == 2 and "--times must be positive" in capsys.readouterr().err
    assert [SEEN[0]] == SEEN  # only the failing run reached the body


@pytest.mark.usefixtures("toy")
def test_a_toy_command_is_listed_with_its_modules_summary_and_has_help(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    listed = capsys.readouterr().out
    assert "toy" in listed and "every flowtact command registers one way" in listed
    with pytest.raises(SystemExit) as info:
        main(["toy", "--help"])
    assert info.value.code == 0 and "--times" in capsys.readouterr().out


def test_only_the_command_run_is_imported(monkeypatch, capsys):
    """A broken command elsewhere in the group does not stop another from running."""
    real = cli.find_commands()
    broken = EntryPoint(name="broken", value="no_such_module_anywhere:COMMAND", group=GROUP)
    monkeypatch.setattr(cli, "find_commands", lambda: {**real, "broken": broken})
    assert main(["blocks"]) == 0
    assert "nlif" in capsys.readouterr().out
    assert main(["broken"]) == 1
    assert "flowtact broken: error: No module named 'no_such_module_anywhere'" in capsys.readouterr().err


def test_an_entry_point_that_is_not_a_command_is_one_line(monkeypatch, capsys):
    not_cmd = EntryPoint(name="odd", value="os.path:join", group=GROUP)
    monkeypatch.setattr(cli, "find_commands", lambda: {"odd": not_cmd})
    assert main(["odd"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "is not a flowtact.commands.Command" in err[0]
