"""Files a graph names are found wherever flowtact is installed and wherever the graph file is:
``pkg:PACKAGE/FILE`` finds a file shipped in flowtact's packages; a relative name is read from the
graph file's real folder (symlinks resolved)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from flowtact.errors import GraphFileError
from flowtact.graphfile.graph import load_graph
from flowtact.graphfile.param_paths import package_file

ROOT = Path(__file__).resolve().parents[2]
BRAILLE = ROOT / "graphs" / "braille.yaml"
MODEL = "braille_first.npz"


def _model(graph) -> Path:
    return Path(graph.nodes["decoder"].params["model"])


def test_a_copy_of_the_braille_graph_in_another_folder_finds_its_model(tmp_path):
    shutil.copy(BRAILLE, tmp_path / "braille.yaml")
    model = _model(load_graph(tmp_path / "braille.yaml"))
    assert model.is_file() and model.name == MODEL


def test_the_braille_graph_names_its_model_as_a_package_resource():
    assert f"pkg:flowtact.blocks.braille.models/{MODEL}" in BRAILLE.read_text()
    assert "../" not in BRAILLE.read_text().split("nodes:", 1)[1]


def test_through_a_symlinked_folder_relative_names_are_read_beside_the_real_file(tmp_path):
    real = tmp_path / "real"
    real.mkdir()
    shutil.copy(ROOT / "blocks" / "braille" / "models" / MODEL, real / "mine.npz")
    text = BRAILLE.read_text().replace(f"pkg:flowtact.blocks.braille.models/{MODEL}", "mine.npz")
    (real / "braille.yaml").write_text(text)
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "elsewhere" / "graphs").symlink_to(real)
    model = _model(load_graph(tmp_path / "elsewhere" / "graphs" / "braille.yaml"))
    assert model == (real / "mine.npz").resolve()


def test_a_symlinked_graph_file_reads_beside_its_target(tmp_path):
    real = tmp_path / "real"
    real.mkdir()
    shutil.copy(ROOT / "blocks" / "braille" / "models" / MODEL, real / "mine.npz")
    text = BRAILLE.read_text().replace(f"pkg:flowtact.blocks.braille.models/{MODEL}", "mine.npz")
    (real / "braille.yaml").write_text(text)
    (tmp_path / "link.yaml").symlink_to(real / "braille.yaml")
    assert _model(load_graph(tmp_path / "link.yaml")) == (real / "mine.npz").resolve()


@pytest.mark.parametrize(
    ("name", "why"),
    [
        ("pkg:os/x.npz", "a package of flowtact's own"),
        ("pkg:flowtact.blocks.braille.models/../presets.py", "FILE inside the package"),
        ("pkg:flowtact.blocks.braille.models", "expected pkg:PACKAGE/FILE"),
        ("pkg:flowtact.no_such_pkg/x.npz", "no installed package 'flowtact.no_such_pkg'"),
    ],
)
def test_a_bad_package_name_is_refused_at_its_place(tmp_path, name, why):
    text = BRAILLE.read_text().replace(f"pkg:flowtact.blocks.braille.models/{MODEL}", name)
    (tmp_path / "g.yaml").write_text(text)
    with pytest.raises(GraphFileError) as info:
        load_graph(tmp_path / "g.yaml")
    (err,) = info.value.errors
    line = 1 + next(i for i, ln in enumerate(text.splitlines()) if ln.strip().startswith("decoder:"))
    assert why in str(err) and f"g.yaml:{line}:" in str(err) and "'model'" in str(err)


def test_package_file_points_into_the_installed_package():
    import flowtact.blocks.braille.models as models  # noqa: F401 (a namespace package or not)

    found = Path(package_file(f"pkg:flowtact.blocks.braille.models/{MODEL}"))
    assert found.is_file() and found.parent.name == "models"
