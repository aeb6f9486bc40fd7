"""docs/writing-a-block.md works as written: its block passes every check, its snippets and commands run."""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
import tomllib
import types
from pathlib import Path

import pytest
from doc_pages import clean_env

from flowtact import ConfigError
from flowtact.testing import CHECKS, check_chunking_invariance

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "writing-a-block.md"
FENCE = re.compile(r"^```(\w+)\n(.*?)^```", re.S | re.M)


def blocks() -> list[tuple[str, str]]:
    """Every fenced code block as (language, text)."""
    return [(m.group(1), m.group(2)) for m in FENCE.finditer(DOC.read_text())]


def named(name: str) -> str:
    """The code block whose first line is the comment ``# NAME``."""
    (text,) = [t for _, t in blocks() if re.match(rf"# {re.escape(name)}[\s(]", t)]
    return text


def module(name: str, code: str) -> types.ModuleType:
    """``code`` imported as module ``name`` (dataclasses look their module up)."""
    if name not in sys.modules:
        mod = sys.modules[name] = types.ModuleType(name)
        exec(compile(code, f"{DOC}#{name}", "exec"), mod.__dict__)  # the doc's own code
    return sys.modules[name]


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    """A user's folder holding the doc's files, as the page tells them to save them."""
    out = tmp_path_factory.mktemp("user")
    for name in (
        "envelope.py",
        "try_envelope.py",
        "test_envelope.py",
        "envelope.yaml",
        "run_envelope_graph.py",
    ):
        (out / name).write_text(named(name))
    return out


def run(cmd: list[str], cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, cwd=cwd, env=clean_env(cwd), capture_output=True, text=True, timeout=300)


@pytest.mark.parametrize("check", CHECKS, ids=lambda c: c.__name__.removeprefix("check_"))
def test_the_doc_block_passes_every_conformance_check(check):
    check(module("doc_envelope", named("envelope.py")).Envelope)


def test_the_config_rules_say_what_the_page_says():
    env = module("doc_envelope", named("envelope.py")).Envelope
    with pytest.raises(ConfigError) as info:
        env(attack_s=0)
    assert str(info.value) == "envelope: 'attack_s' must be > 0; got 0"
    assert "`Envelope(attack_s=0)` raises `envelope: 'attack_s' must be > 0; got 0`" in " ".join(
        DOC.read_text().split()
    )
    with pytest.raises(ConfigError, match="'release_s' must be >= attack_s"):
        env(attack_s=0.1, release_s=0.01)


def test_the_quoted_failure_is_what_the_suite_says_for_the_quoted_bug():
    good = named("envelope.py")
    anchor = "        for i, row in enumerate(np.abs(x.data)):"
    assert anchor in good
    bug = good.replace(anchor, '        self.env = np.zeros(self.input_specs["x"].shape)\n' + anchor)
    broken = module("doc_envelope_bug", bug).Envelope
    with pytest.raises(AssertionError) as info:
        check_chunking_invariance(broken)
    (quoted,) = [t for lang, t in blocks() if lang == "text" and "chunking invariance" in t]
    assert str(info.value) == quoted.strip()


def test_trying_it_offline_runs(folder):
    done = run([sys.executable, "try_envelope.py"], folder)
    assert done.returncode == 0, done.stderr
    assert re.fullmatch(r"envelope at t=1 s: 0\.\d\d N; clipped \d+ samples\n", done.stdout), done.stdout


def test_every_command_on_the_page_runs(folder):
    commands = [line for lang, t in blocks() if lang == "bash" for line in t.splitlines() if line.strip()]
    assert commands == [
        "pytest test_envelope.py",
        "flowtact validate envelope.yaml --allow-module envelope",
        "flowtact run envelope.yaml --fast --record envelope.h5 --allow-module envelope",
    ]
    bindir = Path(sys.executable).parent
    for line in commands:
        argv = shlex.split(line)
        if argv[0] == "pytest":
            argv += ["-q", "-p", "no:cacheprovider"]
        done = run([str(bindir / argv[0]), *argv[1:]], folder)
        assert done.returncode == 0, f"{line}\n{done.stdout}\n{done.stderr}"
        if argv[0] == "pytest":
            assert f"{len(CHECKS)} passed" in done.stdout
    assert (folder / "envelope.h5").exists()


def test_the_graph_runs_from_python(folder):
    done = run([sys.executable, "run_envelope_graph.py"], folder)
    assert done.returncode == 0, done.stderr


def test_the_entry_point_snippet_is_valid_toml():
    table = tomllib.loads(named("pyproject.toml"))
    (value,) = table["project"]["entry-points"]["flowtact.blocks"].values()
    assert re.fullmatch(r"[\w.]+\.envelope:Envelope", value)
