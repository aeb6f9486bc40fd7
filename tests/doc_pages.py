"""The pages' shell commands and the clean shell they run in, shared by every doc test.

A page works as written when its ```bash blocks run in a shell holding only what any shell has:
``PATH`` (the venv's ``bin`` first, as after ``. .venv/bin/activate``) and ``HOME``. No
``PYTHONPATH`` or other variable the page does not set itself; tests/docs/test_doc_commands.py checks
that every page with commands is run this way by some test.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
FENCE = re.compile(r"^```bash\n(.*?)^```", re.S | re.M)


#: Commands too long for the test suite (minutes on a busy 2-core machine), on any page or the
#: README: replaced by a check that the same program starts and parses its arguments (or a cheap
#: run of it). Everything else runs in full.
CHECKED_ONLY = {
    # 2 x 520 letters through the open-loop graph: minutes
    "python scripts/braille_discrimination.py --letters 520 --speed 30": (
        "python scripts/braille_discrimination.py --help"
    ),
    # 3 x 260 training and 8 x 520 validation letters, then some 25 second-order layers: minutes
    "python scripts/braille_cuneate.py --json cuneate.json --figure braille-cuneate.png": (
        "python scripts/braille_cuneate.py --help"
    ),
    # 3 x 260 training letters and 6 x 260 held-out ones on the varying fingertip: about a minute idle
    "python scripts/braille_fingertip_curve.py --reps 10 --plot braille-fingertip-curve.png": (
        "python scripts/braille_fingertip_curve.py --help"
    ),
    # 3 x 260 letters of training runs (README runs a small train-braille in full)
    "flowtact train-braille --out model.npz": "flowtact train-braille --help",
    # the Braille benchmark: ~30 s idle, minutes loaded (flowtact bench has its own tests)
    "flowtact bench braille --quick --out bench-braille": "flowtact bench --list",
    # 6 constant-speed and 18 closed-loop readings of 208 letters: about 6 min; compiled only
    "python scripts/braille_controller_validation.py": "python -m py_compile scripts/braille_controller_validation.py",
    # three fresh numba compiles of the normal generator under different CPU tunings: minutes under load
    "python scripts/normal_draws_tuning.py": "python -m py_compile scripts/normal_draws_tuning.py",
    # installs TouchSim from GitHub into a throw-away venv, then 400 noisy runs: minutes, and a network
    "python scripts/touchsim_noise_reference.py --repeats 400": "python scripts/touchsim_noise_reference.py --help",
    # 3 x 3 real-time runs of 10 s with a headless Chromium: minutes (tests/view has the browser tests)
    "python scripts/view_overhead.py --graph touch --duration 10 --repeats 3": "python scripts/view_overhead.py --help",
    # the TouchSim benchmark with its peer (a throw-away venv from GitHub): a minute and more
    "flowtact bench touchsim --quick --peers --out bench-touchsim": "flowtact bench --list",
    # the start-up table: 4 graphs x 2 caches x idle and loaded (CPU-bound loops) x 3 rounds, a quarter
    # of an hour; the README's cheap row (one graph, idle, one round) runs in full
    "python scripts/startup_table.py": "python scripts/startup_table.py --help",
    # 10 s of 16 900 afferents in real time: with the start-up, tens of seconds on a loaded machine;
    # a short --fast run of the same graph (bench/touchsim_hand.py runs it in real time)
    "flowtact run graphs/hand.yaml --duration 10": "flowtact run graphs/hand.yaml --fast --duration 0.05",
}


def pages() -> list[Path]:
    """README.md and every docs/*.md page."""
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def bash_blocks(page: Path) -> list[str]:
    """The page's ```bash blocks, in order, as written."""
    return FENCE.findall(page.read_text())


def commands(block: str) -> list[str]:
    """One block's commands: continued lines (``\\``) joined, a heredoc kept whole, blank and
    comment-only lines dropped."""
    out: list[str] = []
    lines = block.splitlines()
    i = 0
    while i < len(lines):
        cmd = lines[i]
        i += 1
        if not cmd.strip() or cmd.lstrip().startswith("#"):
            continue
        while cmd.endswith("\\") and i < len(lines):
            cmd = cmd[:-1].rstrip() + " " + lines[i].strip()
            i += 1
        heredoc = re.search(r"<<\s*'?(\w+)'?", cmd)
        if heredoc:
            end = lines.index(heredoc.group(1), i)
            cmd, i = "\n".join([cmd, *lines[i : end + 1]]), end + 1
        out.append(cmd)
    return out


def clean_env(home: Path) -> dict[str, str]:
    """The environment a page's commands get: PATH (this venv's bin first) and HOME, nothing else."""
    return {"PATH": f"{Path(sys.executable).parent}:/usr/bin:/bin", "HOME": str(home)}


def run_in_clean_shell(cmd: str, cwd: Path, timeout: float = 600) -> subprocess.CompletedProcess:
    """``cmd`` as ``bash -e -c`` in ``cwd`` with :func:`clean_env` (HOME is ``cwd``)."""
    return subprocess.run(
        ["bash", "-e", "-c", cmd],
        cwd=cwd,
        env=clean_env(cwd),
        stdin=subprocess.DEVNULL,
        capture_output=True,
        text=True,
        timeout=timeout,
    )
