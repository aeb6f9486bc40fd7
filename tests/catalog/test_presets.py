"""Presets: a domain's numbers for generic blocks, named DOMAIN.NAME, resolved before validation."""

from __future__ import annotations

import pytest

from flowtact import ConfigError
from flowtact.blocks.signal.weighted_sum import WeightedSum
from flowtact.blocks.spiking.nlif import Nlif
from flowtact.blocks.touch.presets import NEURON_PRESETS, TABLE_I
from flowtact.catalog.presets import presets_for
from flowtact.errors import GraphFileError
from flowtact.graphfile.graph import load_graph


def test_the_touch_domain_publishes_its_presets_for_generic_blocks():
    touchsim = {f"touch.{c}.{i}" for c, k in (("SA1", 4), ("RA", 9), ("PC", 4)) for i in range(k)}
    assert {p for p in presets_for("nlif") if p.startswith("touch.")} == {
        "touch.SA1",
        "touch.FA1",
        "touch.hand",
    } | touchsim
    assert set(presets_for("weighted_sum")) == {"touch.SA1", "touch.FA1"}
    assert set(presets_for("savgol")) == {"touch.rager"}
    assert set(presets_for("rectified_gain")) == {
        "touch.SA1.rectified",
        "touch.FA1.rectified",
        "touch.hand",
    }
    assert presets_for("lowpass") == {}


def test_a_preset_fills_in_parameters_and_given_ones_override_it():
    cfg = Nlif(n=3, preset="touch.FA1", sigma=0.0).config
    assert cfg.tau_s == NEURON_PRESETS["FA1"]["tau_s"] and cfg.sigma == 0.0 and cfg.n == 3
    ws = WeightedSum(preset="touch.SA1").config
    assert ws.w1 + ws.w2 + ws.w3 == TABLE_I["SA1"]
    assert ws.expect_units == ("N", "N/s", "N/s^2")


SA1_FAMILY = (
    "(did you mean one of the SA1 presets: touch.SA1, touch.SA1.0, touch.SA1.1, touch.SA1.2, touch.SA1.3?)"
)


@pytest.mark.parametrize(
    ("given", "hint"),
    [
        ("SA1", "(did you mean 'touch.SA1'?)"),  # spelt before presets had domains
        ("SA2", SA1_FAMILY),  # a family misspelt: the family's presets, not 'touch.SA1.2' by likeness
        ("touch.SA2", SA1_FAMILY),
        ("touch.SA1.9", SA1_FAMILY),  # no such model: its family
        ("touch.RA", ", ".join(f"touch.RA.{i}" for i in range(9)) + "?)"),  # a family without a model
        ("PC.7", "(did you mean one of the PC presets: touch.PC.0, touch.PC.1, touch.PC.2, touch.PC.3?)"),
        ("FA2", "(did you mean 'touch.FA1'?)"),  # a family of one
        ("touch.hnad", "(did you mean 'touch.hand'?)"),
        (3, "(valid: braille.afferent, "),
    ],
)
def test_an_unknown_or_old_preset_spelling_is_refused_with_a_hint(given, hint):
    with pytest.raises(ConfigError, match=r"'preset' must name a preset of nlif as DOMAIN\.NAME") as e:
        Nlif(preset=given)
    assert hint in str(e.value)


def test_a_block_without_presets_says_so():
    with pytest.raises(ConfigError, match="block lowpass has no presets"):
        from flowtact.blocks.signal.lowpass import Lowpass

        Lowpass(preset="touch.SA1")


def test_a_graph_with_an_old_preset_spelling_points_at_the_value(tmp_path):
    path = tmp_path / "g.yaml"
    path.write_text(
        "name: g\nnodes:\n  s: {block: aunp_sensor}\n  f: {block: gauge_force}\n"
        "  w: {block: weighted_sum, params: {preset: SA1}}\n"
        "edges: [s.r -> f.r, s.ref -> f.ref, f.f -> w.x1]\n"
    )
    with pytest.raises(GraphFileError) as e:
        load_graph(path)
    text = str(e.value)
    assert text.startswith(f"{path}:5:") and "did you mean 'touch.SA1'?" in text
