"""flowtact train-braille: a tiny training run, its model file, and refusals of bad arguments."""

import numpy as np
import pytest
from runs import ROOT

from flowtact.blocks.braille.cells import CATEGORIES
from flowtact.blocks.braille.reading import char_windows, read_line
from flowtact.blocks.braille.train_braille import HELDOUT_SEED, main
from flowtact.blocks.spiking.naive_bayes import NaiveBayes
from flowtact.blocks.spiking.nb_model import load_model
from flowtact.chunk import Chunk, StreamSpec
from flowtact.testing import run_offline


@pytest.mark.slow
def test_a_tiny_training_run_writes_a_model_with_its_provenance(tmp_path, capsys):
    out = tmp_path / "m.npz"
    code = main(
        [
            "--out",
            str(out),
            "--letters",
            "120",
            "--speeds",
            "60",
            "--bins",
            "2",
            "--no-progress",
            "--seed",
            "1",
        ]
    )
    assert code == 0, capsys.readouterr().err
    m = load_model(out)
    assert m.features == "counts" and m.n_bins == 2 and m.n_units == 24 and len(m.classes) == 26
    p = m.provenance
    assert p["seeds"] == [1] and p["speeds_mm_s"] == [60.0] and p["layer"] == "first"
    assert p["windows"] == 120 and p["flowtact_version"] and "--letters 120" in p["command"]
    assert p["training_accuracy"] > 0.5  # far above chance (1/26): it learned something
    assert "training accuracy" in capsys.readouterr().out


def test_char_windows_are_the_decoder_s_windows():
    """The trainer's offline windows are those the decoder block finds online (same spikes, same rule)."""
    r = read_line(seed=3, speed_mm_s=40.0, text="ab cab", layers=("first",))
    char = r.streams["scan.char"]
    w, letters = char_windows(char.t, char.data)
    assert letters == tuple("abcab")
    blk = NaiveBayes(model=str(ROOT / "blocks/braille/models/braille_first.npz"), gap=("gap", "space"))
    t, u = r.spikes["first"]
    window = StreamSpec(dtype="float64", rate_hz=250.0, categories=CATEGORIES)
    specs = {"spikes": StreamSpec(dtype="int64", events=True, n_units=24), "window": window}
    out = run_offline(
        blk, spikes=Chunk(t, u, r.duration_s), window=char.data, t=char.t, rate_hz=250.0, specs=specs
    )
    np.testing.assert_array_equal(out["posterior"].t, w[:, 1])


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--speeds", "0"], "speeds must be in (0, 1000] mm/s"),
        (["--speeds", "fast"], "expected speeds in mm/s"),
        (["--letters", "-3"], "argument --letters: must be an integer in [1, 10000]"),
        (["--layer", "third"], "invalid choice: 'third'"),
        (["--seed", str(HELDOUT_SEED)], "seeds from 100000 are held out"),
        (["--letters", "3", "--speeds", "80"], "never came up in the training text: raise --letters"),
    ],
)
def test_bad_arguments_are_refused_with_one_line_and_status_2(args, message, tmp_path, capsys):
    out = tmp_path / "m.npz"
    assert main(["--out", str(out), "--no-progress", *args]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not out.exists()


def test_a_missing_graph_is_a_usage_error(tmp_path, capsys):
    assert (
        main(["--graph", str(tmp_path / "none.yaml"), "--out", str(tmp_path / "m.npz"), "--no-progress"]) == 2
    )
    assert "none.yaml" in capsys.readouterr().err


@pytest.mark.slow
def test_the_shipped_model_is_what_its_documented_command_makes_today(tmp_path):
    """Retraining with the recorded command gives the shipped arrays bit for bit: the model is
    reproducible and not stale (a change to the sensor, the presets or the graph breaks this)."""
    shipped = load_model(ROOT / "blocks/braille/models/braille_first.npz")
    argv = shipped.provenance["command"].removeprefix("flowtact train-braille ").split()
    out = argv.index("--out") + 1
    argv[out] = str(tmp_path / "again.npz")
    assert main([*argv, "--no-progress"]) == 0
    again = load_model(tmp_path / "again.npz")
    assert again.running_temperature == shipped.running_temperature
    for k in shipped.arrays:
        np.testing.assert_array_equal(again.arrays[k], shipped.arrays[k])
