"""Shell completion (argcomplete): the installed ``flowtact`` script answers a completion request
with its subcommands, flags and shipped graph names, through argcomplete's own protocol."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from flowtact.graphfile.graph import shipped_graphs

FLOWTACT = Path(sys.executable).parent / "flowtact"


def complete(line: str, tmp_path: Path) -> list[str]:
    """What the shell would offer for ``line`` (the cursor at its end), via argcomplete's hooks:
    _ARGCOMPLETE set, COMP_LINE/COMP_POINT the line, answers written to _ARGCOMPLETE_STDOUT_FILENAME."""
    out = tmp_path / "completions"
    env = {
        "PATH": f"{FLOWTACT.parent}:/usr/bin:/bin",
        "HOME": str(tmp_path),
        "_ARGCOMPLETE": "1",
        "_ARGCOMPLETE_SHELL": "bash",
        "COMP_LINE": line,
        "COMP_POINT": str(len(line)),
        "_ARGCOMPLETE_IFS": "\n",
        "_ARGCOMPLETE_STDOUT_FILENAME": str(out),
    }
    done = subprocess.run([str(FLOWTACT)], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return [w.strip() for w in out.read_text().split("\n") if w.strip()]


@pytest.fixture(autouse=True)
def _installed():
    if not FLOWTACT.exists():
        pytest.skip("no installed flowtact script beside this interpreter")


def test_the_completer_yields_the_subcommands(tmp_path):
    words = complete("flowtact ", tmp_path)
    assert {"run", "validate", "plot", "info", "bench", "sweep", "sim", "train-braille"} <= set(words)
    assert set(complete("flowtact va", tmp_path)) == {"validate"}


def test_the_completer_yields_flags_and_shipped_graphs(tmp_path):
    assert {"--fast", "--record", "--duration"} <= set(complete("flowtact run --", tmp_path))
    (tmp_path / "mine.yaml").write_text("nodes: {}\n")
    words = set(complete("flowtact run ", tmp_path))
    assert set(shipped_graphs()) <= words and "mine.yaml" in words


def test_the_script_carries_the_argcomplete_marker():
    """register-python-argcomplete completes only scripts whose module says PYTHON_ARGCOMPLETE_OK
    in its first 1024 bytes."""
    head = (Path(__file__).resolve().parents[1] / "flowtact" / "cli.py").read_text()[:1024]
    assert "PYTHON_ARGCOMPLETE_OK" in head
