"""Every shell command on every page (README.md, docs/*.md) runs as written in a clean shell.

One mechanism (tests/doc_pages.py): a page's ```bash blocks are extracted as written and run with
``bash -e`` in a fresh folder holding ``graphs/`` and ``scripts/`` (symlinked, as a user's clone
or a symlinked graphs folder would be), with only PATH and HOME set (:func:`doc_pages.clean_env`):
a command that needs a variable the page does not set fails. Pages whose quoted outputs are checked
too have their own test (``RUN_ELSEWHERE``), which must run them through the same clean shell;
the other pages run here. Commands too long for the suite are checked by a cheaper command on the
same entry point (``CHECKED_ONLY``); each such substitution is listed here and nowhere else.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from doc_pages import ROOT, bash_blocks, commands, pages, run_in_clean_shell

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
    "docs/recordings.md",
    "docs/touch-encoding.md",
    "docs/touchsim.md",
    "docs/view.md",
)
#: Commands too long for the test suite (minutes on a busy 2-core machine): replaced by a check
#: that the same program starts and parses its arguments. Everything else runs in full.
CHECKED_ONLY = {
    # 2 x 520 letters through the open-loop graph: minutes
    "python scripts/braille_discrimination.py --letters 520 --speed 30": (
        "python scripts/braille_discrimination.py --help"
    ),
    # 3 x 260 letters of training runs (README runs a small train-braille in full)
    "flowtact train-braille --out model.npz": "flowtact train-braille --help",
    # the Braille benchmark: ~30 s idle, minutes loaded (flowtact bench has its own tests)
    "flowtact bench braille --quick --out bench-braille": "flowtact bench --list",
    # a dozen closed-loop readings of 104 letters: no arguments to parse; compiled only
    "python scripts/braille_controller_validation.py": "python -m py_compile scripts/braille_controller_validation.py",
    # three fresh numba compiles of the normal generator under different CPU tunings: minutes under load
    "python scripts/normal_draws_tuning.py": "python -m py_compile scripts/normal_draws_tuning.py",
    # installs TouchSim from GitHub into a throw-away venv, then 400 noisy runs: minutes, and a network
    "python scripts/touchsim_noise_reference.py --repeats 400": "python scripts/touchsim_noise_reference.py --help",
    # 3 x 3 real-time runs of 10 s with a headless Chromium: minutes (tests/view has the browser tests)
    "python scripts/view_overhead.py --graph touch --duration 10 --repeats 3": "python scripts/view_overhead.py --help",
    # the TouchSim benchmark with its peer (a throw-away venv from GitHub): a minute and more
    "flowtact bench touchsim --quick --peers --out bench-touchsim": "flowtact bench --list",
}


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
    written = {_stripped(c) for p in RUN_HERE for b in bash_blocks(ROOT / p) for c in commands(b)}
    assert set(CHECKED_ONLY) <= written


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
