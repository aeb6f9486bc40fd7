"""Throw-away venvs for the benches' external references (ezmsg, Timeflux, Brian2), made on first use.

Each lives under ``~/.cache/flowtact-bench/NAME``, holds only what ``pip install`` brings for the
reference, and is reused while its module imports; delete the folder to start afresh.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

__all__ = ["VENVS", "venv_python"]

VENVS = Path.home() / ".cache" / "flowtact-bench"


def venv_python(name: str, packages: Sequence[str], module: str, root: Path = VENVS) -> Path | None:
    """The Python of venv ``root/name`` that can import ``module``, creating it with ``pip install
    packages`` on first use; None (with a message on stderr) if venv or pip fails."""
    venv = root / name
    py = venv / "bin" / "python"
    if py.exists() and subprocess.run([py, "-c", f"import {module}"], capture_output=True).returncode == 0:
        return py
    print(f"   creating {venv} (pip install {' '.join(packages)}) ...", file=sys.stderr, flush=True)
    shutil.rmtree(venv, ignore_errors=True)
    venv.parent.mkdir(parents=True, exist_ok=True)
    steps = [
        [sys.executable, "-m", "venv", str(venv)],
        [str(py), "-m", "pip", "install", "--disable-pip-version-check", "-q", *packages],
    ]
    for cmd in steps:
        r = subprocess.run(cmd, capture_output=True, text=True)
        if r.returncode != 0:
            tail = "\n".join((r.stderr or r.stdout).strip().splitlines()[-5:])
            print(
                f"   {name}: '{' '.join(cmd[:4])} ...' failed, skipping {name}:\n{tail}",
                file=sys.stderr,
                flush=True,
            )
            return None
    return py
