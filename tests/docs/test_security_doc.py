"""docs/security.md names the tests that guard each rule: every named test and file exists."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DOC = (ROOT / "docs" / "security.md").read_text()


def _defined_tests() -> set[str]:
    names: set[str] = set()
    for path in (ROOT / "tests").rglob("test_*.py"):
        names.update(re.findall(r"^def (test_\w+)", path.read_text(), flags=re.M))
    return names


def test_every_test_the_page_names_exists():
    named = {m.split("[")[0] for m in re.findall(r"`(test_\w+(?:\[[^\]]*\])?)`", DOC)}
    assert len(named) >= 20  # the page names the guard of each rule
    missing = sorted(named - _defined_tests())
    assert not missing, f"docs/security.md names tests that do not exist: {missing}"


def test_every_file_the_page_names_exists():
    files = set(re.findall(r"\b((?:tests|flowtact|blocks|bench)/[\w/]+\.py)\b", DOC))
    assert len(files) >= 10
    missing = sorted(f for f in files if not (ROOT / f).is_file())
    assert not missing, f"docs/security.md names files that do not exist: {missing}"


def test_the_readme_links_the_page():
    assert "(docs/security.md)" in (ROOT / "README.md").read_text()
