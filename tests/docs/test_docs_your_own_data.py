"""docs/your-own-data.md: every command of the walkthrough runs (exit 0) in a fresh folder, and
the outputs it quotes are the ones the commands give."""

import re
import subprocess
import sys
from pathlib import Path

import pytest
from doc_pages import bash_blocks, run_in_clean_shell

ROOT = Path(__file__).parents[2]
DOC = ROOT / "docs" / "your-own-data.md"


def blocks(lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", DOC.read_text(), re.S)


def quoted(after: str) -> str:
    """The ```text block that follows the first line containing ``after``."""
    text = DOC.read_text()
    return re.search(r"```text\n(.*?)```", text[text.index(after) :], re.S).group(1)


@pytest.fixture(scope="module")
def walked(tmp_path_factory):
    here = tmp_path_factory.mktemp("walk")
    (here / "graphs").symlink_to(ROOT / "graphs")
    results = []
    for cmd in bash_blocks(DOC):
        results.append((cmd, run_in_clean_shell(cmd, here, timeout=300)))
    return here, results


def test_every_command_runs(walked):
    _, results = walked
    assert len(results) >= 5
    for cmd, proc in results:
        assert proc.returncode == 0, f"{cmd}\n{proc.stderr}"
        assert "Traceback" not in proc.stderr, cmd


def test_the_quoted_outputs_are_what_the_commands_print(walked):
    here, results = walked
    head = next(p for c, p in results if "head -3 log.csv" in c)
    assert head.stdout == quoted("head -3 log.csv")
    past = next(p for c, p in results if "--duration 5" in c)
    said = [
        ln for ln in past.stderr.splitlines() if "compil" not in ln
    ]  # a cold numba cache announces compiling
    assert "\n".join(said).strip() == quoted("Asked to run longer").strip()
    assert (here / "out.png").stat().st_size > 10_000
    # the bad-file example: the log with one cell spoiled, refused as the page says
    good = (here / "log.csv").read_text()
    lines = good.split("\n")
    cells = lines[1741].split(",")
    lines[1741] = ",".join([*cells[:-1], "abc"])
    (here / "log.csv").write_text("\n".join(lines))
    want = quoted("## Bad files").splitlines()
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "flowtact.cli",
            *want[0].split()[2:3],
            "graphs/touch.yaml",
            "--replay",
            "sensor=log.csv:r=g1,g2,g3,g4",
        ],
        cwd=here,
        capture_output=True,
        text=True,
        timeout=300,
    )
    (here / "log.csv").write_text(good)
    assert proc.returncode == 2 and proc.stderr.splitlines() == want[1:]


def test_the_python_example_runs(walked):
    here, _ = walked
    (python,) = blocks("python")
    proc = subprocess.run(
        [sys.executable, "-c", python], cwd=here, capture_output=True, text=True, timeout=300
    )
    assert proc.returncode == 0, proc.stderr
    assert re.fullmatch(r"[1-9]\d* SA1 spikes\n", proc.stdout)


def test_the_plot_text_says_what_the_fa1_afferents_did(walked):
    """The page says: FA1 spikes at the press's onset only, one per afferent, during its 10 ms rise
    from 0.5 s; none at the release (2 s). The walkthrough's own out.h5 must show exactly that."""
    import h5py
    import numpy as np

    here, _ = walked
    said = " ".join(DOC.read_text().split())
    assert (
        "FA1 spikes at its onset only (20: one per FA1 afferent, all during the 10 ms rise from 0.5 s)"
        in said
    )
    assert "The release at 2 s gives no FA1 spike" in said
    with h5py.File(here / "out.h5", "r") as f:
        fa1 = f["streams/fa1.spikes"]
        t, unit, n = fa1["t"][:], fa1["data"][:], int(fa1.attrs["n_units"])
    assert n == 20 and len(t) == 20 and sorted(unit) == list(range(20))
    assert np.all((t >= 0.5) & (t <= 0.51 + 1e-9))  # the press rises from 0.5 s to 0.51 s
    assert not np.any(t > 1.5)  # nothing at the release
