"""Every malformed graph of the corpus yields its `path:line:col: message`, exit 2, no traceback.

Each file in tests/graphfile/graphs/bad/ starts with `# expect: LINE:COL: text`; the text must appear in
the error printed for that location.
"""

import re
import subprocess
import sys
from pathlib import Path

import pytest

from flowtact.cli import main

CORPUS = sorted((Path(__file__).parent / "graphs" / "bad").glob("*.yaml"))


def expectation(path: Path) -> tuple[int, int, str]:
    first = path.read_bytes().split(b"\n", 1)[0].decode()  # the rest may be hostile bytes (not UTF-8)
    m = re.match(r"# expect: (\d+):(\d+): (.+)", first)
    assert m, f"{path.name} has no '# expect: LINE:COL: text' first line"
    return int(m.group(1)), int(m.group(2)), m.group(3)


def test_the_corpus_is_large_enough():
    assert len(CORPUS) >= 60


@pytest.mark.parametrize("path", CORPUS, ids=lambda p: p.stem)
def test_malformed_graph_is_reported_at_its_place(path, capsys):
    line, col, text = expectation(path)
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"{path}:{line}:{col}: " in err, err
    located = [e for e in err.splitlines() if e.startswith(f"{path}:{line}:{col}: ")]
    assert any(text in e for e in located), f"expected {text!r} at {line}:{col}, got:\n{err}"
    assert "Traceback" not in err


def test_the_command_line_prints_no_traceback():
    path = next(p for p in CORPUS if p.stem == "unknown_block")
    proc = subprocess.run(
        [sys.executable, "-m", "flowtact.cli", "validate", str(path)], capture_output=True, text=True
    )
    assert proc.returncode == 2
    assert "did you mean 'savgol'?" in proc.stderr
    assert "Traceback" not in proc.stderr


def test_a_bad_override_is_located_and_rejected(capsys):
    graph = Path(__file__).parents[2] / "graphs" / "touch.yaml"
    assert main(["validate", str(graph), "--set", "sa1.tau_s=-1"]) == 2
    err = capsys.readouterr().err
    assert "--set:1:1: sa1 (nlif): 'tau_s' must be > 0; got -1" in err
