"""``flowtact blocks NAME``: readable text for every registered block, with its presets' values."""

import inspect
import re

import pytest

from flowtact.catalog.blocks import block_names, load_block
from flowtact.cli import main
from flowtact.help.describe import describe_block, units_of

MARKUP = re.compile(
    r"``|:(?:class|func|meth|mod|attr|data|obj|math|ref|doc|py:\w+):`|^\s*\.\. [\w-]+::", re.M
)


@pytest.mark.parametrize("name", block_names())
def test_no_rst_markup_and_prose_fits_the_width(name):
    cls = load_block(name)
    text = describe_block(cls, width=90)
    assert not MARKUP.search(text), MARKUP.search(text)
    raw = inspect.cleandoc(cls.__doc__ or "")
    for line in text.splitlines():  # only literal blocks and doctests (kept verbatim) may run longer
        if len(line) > 90:
            assert line.strip() in raw or line.startswith("  "), line


def test_nlif_shows_the_sa1_and_fa1_presets_with_their_values_and_units(capsys):
    assert main(["blocks", "nlif"]) == 0
    text = capsys.readouterr().out
    presets = text.split("Presets (", 1)[1].split("\nCounters:", 1)[0]
    sa1 = presets.split("  touch.SA1\n", 1)[1]
    fa1 = presets.split("  touch.FA1\n", 1)[1].split("  touch.SA1", 1)[0]
    assert re.search(r"^    tau_s +0\.01 s$", sa1, re.M)
    assert re.search(r"^    tau_s +0\.005 s$", fa1, re.M)
    assert re.search(r"^    gain +30$", sa1, re.M) and re.search(r"^    refractory_s +0\.0035 s$", sa1, re.M)
    assert re.search(r"^    h_weights +\[0, 0, -0\.5, -0\.5\]$", sa1, re.M)


def test_weighted_sum_and_savgol_show_their_presets():
    ws = describe_block(load_block("weighted_sum"))
    assert re.search(r"touch\.SA1\n    w1 +\[0\.405, 8\.908, 0\.382\]", ws)
    assert "expect_units     ['N', 'N/s', 'N/s^2']" in ws
    sg = describe_block(load_block("savgol"))
    assert re.search(r"touch\.rager\n    window +5\n    order +4", sg)


def test_a_block_without_presets_has_no_section():
    assert "Presets" not in describe_block(load_block("delay"))


@pytest.mark.parametrize(
    ("field", "units"),
    [
        ("tau_s", "s"),
        ("rate_hz", "Hz"),
        ("gain_us_per_n", "µs/N"),
        ("sensitivity_per_n", "1/N"),
        ("damping_n_s", "N·s"),
        ("min_area_px2", "px²"),
        ("stiffness_n_per_mm", "N/mm"),
        ("n", ""),
        ("v_leak", ""),
        ("max_units", ""),
    ],
)
def test_units_from_field_names(field, units):
    assert units_of(field) == units
