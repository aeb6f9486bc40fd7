"""Every shell command on every page (README.md, docs/*.md) runs as written in a clean shell.

One mechanism (tests/doc_pages.py): a page's ```bash blocks are extracted as written and run with
``bash -e`` in a fresh folder holding ``graphs/`` and ``scripts/`` (symlinked, as a user's clone
or a symlinked graphs folder would be), with only PATH and HOME set (:func:`doc_pages.clean_env`):
a command that needs a variable the page does not set fails. Pages whose quoted outputs are checked
too have their own test (``RUN_ELSEWHERE``), which must run them through the same clean shell;
the other pages run here. Commands too long for the suite are checked by a cheaper command on the
same entry point (``doc_pages.CHECKED_ONLY``, which the README's test applies too); each such
substitution is listed there and nowhere else.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from doc_pages import CHECKED_ONLY, ROOT, bash_blocks, commands, pages, run_in_clean_shell

#: Pages run, block by block in a clean shell, by their own test (which also checks quoted outputs).
RUN_ELSEWHERE = {
    "README.md": "tests/docs/test_readme_commands.py",
    "docs/writing-a-block.md": "tests/docs/test_writing_a_block_doc.py",
    "docs/your-own-data.md": "tests/docs/test_docs_your_own_data.py",
    "docs/sweeps.md": "tests/sweeps/test_sweeps_doc.py",
}
#: Pages whose commands this test runs, in page order.
RUN_HERE = (
    "docs/braille.md",
    "docs/lsl.md",
    "docs/recordings.md",
    "docs/schema.md",
    "docs/touch-encoding.md",
    "docs/touchsim.md",
    "docs/view.md",
)


def _rel(page: Path) -> str:
    return page.relative_to(ROOT).as_posix()


def _stripped(cmd: str) -> str:
    """A command without its trailing ``  # comment``."""
    return cmd.split("  #", 1)[0].rstrip() if "\n" not in cmd else cmd


def test_every_page_with_commands_is_run_by_a_test():
    with_commands = {_rel(p) for p in pages() if bash_blocks(p)}
    assert with_commands == set(RUN_ELSEWHERE) | set(RUN_HERE), "a page gained or lost commands: list it"


@pytest.mark.parametrize("page", sorted(RUN_ELSEWHERE))
def test_the_pages_own_test_runs_it_in_the_clean_shell(page):
    """Their tests use doc_pages' clean environment and never pass this process's on."""
    text = (ROOT / RUN_ELSEWHERE[page]).read_text()
    assert "from doc_pages import" in text and ("clean_env" in text or "run_in_clean_shell" in text)
    assert "os.environ" not in text and "PYTHONPATH" not in text, RUN_ELSEWHERE[page]


def test_every_checked_only_command_is_on_a_page():
    shown = (*RUN_HERE, "README.md")
    written = {_stripped(c) for p in shown for b in bash_blocks(ROOT / p) for c in commands(b)}
    assert set(CHECKED_ONLY) <= written


def test_every_script_the_readme_names_in_its_text_is_in_one_of_its_command_blocks():
    """A command named only in the prose (`python scripts/x.py`) is run by no test: show it in a
    ```bash block, which tests/docs/test_readme_commands.py runs (or checks, CHECKED_ONLY)."""
    text = (ROOT / "README.md").read_text()
    written = [_stripped(c) for b in bash_blocks(ROOT / "README.md") for c in commands(b)]
    prose = re.sub(r"```.*?```", "", text, flags=re.S).replace("\n", " ")
    named = re.findall(r"`(python3? scripts/[^`]+)`", prose)
    assert named, "the README names scripts/startup_table.py"
    assert [c for c in named if not any(w.startswith(c) for w in written)] == []


@pytest.fixture
def user_folder(tmp_path) -> Path:
    """A fresh folder with the clone's graphs/ and scripts/ reached through symlinks."""
    for name in ("graphs", "scripts"):
        (tmp_path / name).symlink_to(ROOT / name)
    return tmp_path


@pytest.mark.slow
@pytest.mark.cli
@pytest.mark.timeout(1800)
@pytest.mark.parametrize("page", RUN_HERE)
def test_every_command_of_the_page_runs_as_written(page, user_folder):
    failures = []
    ran = 0
    for block in bash_blocks(ROOT / page):
        for cmd in commands(block):
            todo = CHECKED_ONLY.get(_stripped(cmd), cmd)
            done = run_in_clean_shell(todo, user_folder)
            ran += 1
            if done.returncode != 0 or "Traceback" in done.stderr:
                failures.append(f"$ {todo}\n(exit {done.returncode})\n{done.stderr[-2000:]}")
    assert ran >= 2 and not failures, "\n\n".join(failures)


def test_the_readme_layout_names_every_graph_page_and_block_family():
    layout = (ROOT / "README.md").read_text().split("## Layout", 1)[1].split("\n## ", 1)[0]
    graphs = [p.name for p in (ROOT / "graphs").glob("*.yaml")]
    pages_ = [p.name for p in (ROOT / "docs").glob("*.md")]
    families = [p.name for p in (ROOT / "blocks").iterdir() if (p / "__init__.py").is_file()]
    missing = [n for n in graphs + pages_ if n not in layout]
    missing += [f for f in families if f"{f}/" not in layout]
    assert {"braille.yaml", "braille_open.yaml"} <= set(graphs) and "braille" in families
    assert not missing, f"README's layout omits {missing}"
