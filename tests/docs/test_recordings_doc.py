"""docs/recordings.md is true: its Python snippets run against a fresh recording, and every path
and attribute its MATLAB snippets read exists with a type MATLAB reads without jsondecode."""

import re
from pathlib import Path

import h5py
import numpy as np
import pytest

from flowtact.cli import main

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "recordings.md"
#: Attributes the MATLAB snippets may read as JSON text, through jsondecode.
JSON_ATTRS = {"summary", "params", "seeds", "versions", "overrides", "pruned"}


def blocks(lang: str) -> list[str]:
    return re.findall(rf"^```{lang}\n(.*?)^```", DOC.read_text(), flags=re.S | re.M)


@pytest.fixture(scope="module")
def run_h5(tmp_path_factory):
    folder = tmp_path_factory.mktemp("doc")
    argv = ["run", str(ROOT / "graphs" / "touch.yaml"), "--fast", "--duration", "2", "--inproc", "--quiet"]
    assert main([*argv, "--record", str(folder / "run.h5")]) == 0
    return folder / "run.h5"


def test_python_snippets_run_against_a_fresh_recording(run_h5, monkeypatch, capsys):
    code = blocks("python")
    assert len(code) >= 3
    monkeypatch.chdir(run_h5.parent)
    namespace: dict = {}
    for i, block in enumerate(code):
        exec(compile(block, f"{DOC.name}[python block {i + 1}]", "exec"), namespace)
    out = capsys.readouterr().out
    assert "N 1000.0 ('Fx', 'Fy', 'Fz') (2000, 3)" in out
    assert "touch 7" in out and "no error" in out


def _matlab_reads() -> tuple[set[str], set[tuple[str, str]], set[str], set[str]]:
    """Datasets read, (object, attribute) pairs read, attributes read via jsondecode, h5info paths."""
    text = "\n".join(blocks("matlab"))
    files = set(re.findall(r"h5\w+\('([^']+)'", text))
    assert files == {"run.h5"}, files
    read_calls = re.findall(r"h5read\('run\.h5',\s*'([^']+)'\)", text)
    att_calls = re.findall(r"h5readatt\('run\.h5',\s*'([^']+)',\s*'([^']+)'\)", text)
    info_calls = re.findall(r"h5info\('run\.h5'(?:,\s*'([^']+)')?\)", text)
    # every call is parsed (none written in a form these patterns would miss)
    assert len(read_calls) == text.count("h5read("), text
    assert len(att_calls) == text.count("h5readatt("), text
    assert len(info_calls) == text.count("h5info("), text
    via_json = set(re.findall(r"jsondecode\(h5readatt\('run\.h5',\s*'/',\s*'([^']+)'\)\)", text))
    datasets, attrs, infos = set(read_calls), set(att_calls), set(info_calls)
    return datasets, attrs, via_json, infos


def _matlab_readable(value) -> bool:
    """A number (scalar or array), a string, or an array of strings: h5readatt returns them as is."""
    if isinstance(value, str):
        return True
    a = np.asarray(value)
    if a.dtype.kind in "iuf":
        return True
    return a.dtype.kind == "O" and all(isinstance(x, str) for x in a.ravel())


def test_matlab_snippets_by_their_layout(run_h5):
    datasets, attrs, via_json, infos = _matlab_reads()
    assert len(datasets) >= 5 and len(attrs) >= 12 and infos == {"/streams"}
    with h5py.File(run_h5, "r") as f:
        for path in datasets:
            assert path in f and isinstance(f[path], h5py.Dataset), path
            assert f[path].dtype.kind in "iuf", (path, f[path].dtype)  # numeric: h5read returns a matrix
        for obj, name in attrs:
            assert obj in f, obj
            assert name in f[obj].attrs, (obj, name)
            value = f[obj].attrs[name]
            assert _matlab_readable(value), (obj, name, type(value))
            if name in JSON_ATTRS:  # JSON text only where the snippet decodes it
                assert name in via_json, f"{obj} {name} is JSON: the snippet must jsondecode it"
        for path in infos:
            assert isinstance(f[path], h5py.Group)
    read = {name for _, name in attrs}
    assert {"units", "rate_hz", "channel_labels", "kind", "n_units", "end_s", "graph_yaml", "error"} <= read


def test_every_stream_attribute_but_the_json_twins_is_matlab_readable(run_h5):
    with h5py.File(run_h5, "r") as f:
        for name, g in f["streams"].items():
            for key, value in g.attrs.items():
                if key in (
                    "labels",
                    "shape",
                ):  # JSON twins of channel_labels and sample_shape, for format 1 readers
                    continue
                assert _matlab_readable(value), (name, key, value)
            assert list(g.attrs["sample_shape"]) == list(g["data"].shape[1:])


def test_readme_links_the_layout_and_mentions_info():
    readme = (ROOT / "README.md").read_text()
    section = readme.split("## Recordings", 1)[1].split("\n## ", 1)[0]
    assert "docs/recordings.md" in section and "flowtact info" in section
