"""The command line's help says what the pages say, in plain text: no reST markup, examples that
parse, every format listed, and a misspelt graph name gets a did-you-mean and the shipped graphs."""

from __future__ import annotations

import re
import shlex

import pytest

from flowtact.cli import build_parser, main, one_line_summary
from flowtact.commands.run import RUN_EXAMPLES
from flowtact.graphfile.graph import shipped_graphs
from flowtact.pictures.graph_figure import FORMATS


def _help(capsys, *argv: str) -> str:
    with pytest.raises(SystemExit) as info:
        main([*argv, "--help"])
    assert info.value.code == 0
    return capsys.readouterr().out


def test_top_level_help_has_no_rest_markup(capsys):
    out = _help(capsys)
    assert "``" not in out and ":class:" not in out and ":func:" not in out
    for plugin in ("fit-force", "sim", "train-braille", "train-force"):
        (line,) = [ln for ln in out.splitlines() if ln.strip().startswith(plugin)]
        assert "flowtact " not in line, line  # the name is beside it: not repeated
    assert "register-python-argcomplete flowtact" in out


@pytest.mark.parametrize(
    ("doc", "line"),
    [
        (
            "``flowtact fit-force REC.h5``: fit ``linear_force``'s per-sensor lines on a recording.\n\nMore.",
            "fit linear_force's per-sensor lines on a recording",
        ),
        ("Train the Braille decoder: ``flowtact train-braille``.", "train the Braille decoder"),
        ("Emulate the exoskeleton. It prints 'PORT'.", "emulate the exoskeleton"),
    ],
)
def test_one_line_summary(doc, line):
    from flowtact.help.rst_text import inline_text

    assert one_line_summary(inline_text(doc)) == line


def test_run_help_has_examples_that_parse(capsys):
    out = _help(capsys, "run")
    assert "examples:" in out and "flowtact run touch.h5 --fast" in out
    examples = [
        ln.split("  #", 1)[0].strip() for ln in RUN_EXAMPLES.splitlines() if ln.startswith("  flowtact")
    ]
    assert len(examples) >= 5
    parser = build_parser()
    for ex in examples:
        args = parser.parse_args(shlex.split(ex)[1:])  # exits (and fails the test) on a bad flag
        assert args.command == "run"


def test_graph_help_lists_every_format_it_draws(capsys):
    out = " ".join(_help(capsys, "graph").split())
    for fmt in FORMATS:
        assert fmt in out, fmt


def test_sim_help_describes_devices_and_examples(capsys):
    assert main(["sim", "--help"]) == 0
    out = capsys.readouterr().out
    assert re.search(r"^devices:\n  exo\s+\w", out, re.M), out
    assert "examples:" in out and "flowtact sim exo" in out and "``" not in out
    assert len(out.splitlines()) >= 8


@pytest.mark.parametrize(
    ("given", "guess"), [("touhc", "touch"), ("brail", "braille"), ("graphs/sllip.yaml", "graphs/slip.yaml")]
)
def test_a_misspelt_graph_gets_a_did_you_mean_and_the_shipped_list(given, guess, capsys, monkeypatch):
    from pathlib import Path

    monkeypatch.chdir(Path(__file__).resolve().parent.parent)
    assert main(["run", given, "--fast"]) == 2
    err = capsys.readouterr().err
    assert f"{given}:1:1: no such graph file (did you mean '{guess}'?)" in err
    assert f"shipped graphs, run by name (flowtact run touch): {', '.join(shipped_graphs())}" in err
    assert {"touch", "slip", "braille", "braille_open"} <= set(shipped_graphs())
