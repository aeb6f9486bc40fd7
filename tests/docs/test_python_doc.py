"""docs/python.md works as written: its Python blocks, run in order in a fresh interpreter, build and
run graphs in-process and across processes and draw a plot (Deliver 4 of issue 34)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest
from doc_pages import clean_env

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "python.md"
PYTHON = re.compile(r"^```python\n(.*?)^```", re.S | re.M)


def python_blocks() -> list[str]:
    return PYTHON.findall(DOC.read_text())


def test_the_page_has_its_parts():
    code = "\n".join(python_blocks())
    for part in ("processes=True", "GraphBuilder(", ".frame(", "savefig(", "flowtact.run("):
        assert part in code, part


@pytest.mark.slow
@pytest.mark.cli
@pytest.mark.timeout(900)
def test_the_page_runs_in_a_fresh_interpreter(tmp_path):
    script = tmp_path / "page.py"
    script.write_text("\n\n".join(python_blocks()))
    done = subprocess.run(
        [sys.executable, "-P", str(script)],
        cwd=tmp_path,
        env=clean_env(tmp_path),
        stdin=subprocess.DEVNULL,
        capture_output=True,
        text=True,
        timeout=850,
    )
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr[-3000:]
    out = done.stdout
    assert "['afferents', 'sensing']" in out  # two worker processes ran
    for said in re.findall(r"# (<python graph .*)", DOC.read_text()):  # the quoted error, as printed
        assert said in out, (said, out)
    import matplotlib.image

    picture = matplotlib.image.imread(tmp_path / "press.png")
    assert picture.shape[:2] == (400, 700)
    assert picture[..., :3].std() > 0.05  # something is drawn
