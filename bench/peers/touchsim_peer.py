"""TouchSim's own code as an external reference: its throw-away venv and a run of its per-afferent model.

TouchSim (hsaal/touchsim, the Python implementation of Saal, Delhaye et al., PNAS 2017) has no
licence, so none of its code is copied here: it is pip-installed from its public source into a
venv under ``~/.cache/flowtact-bench/touchsim`` (bench/peers/venv.py) and run there by
bench/peers/touchsim_afferents.py. ``FLOWTACT_TOUCHSIM_SOURCE`` names another source for pip (a
local clone, an archive) where GitHub cannot be reached.
"""

from __future__ import annotations

import os
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from flowtact.bench.peers.venv import VENVS, venv_python

__all__ = ["TOUCHSIM_COMMIT", "TOUCHSIM_SCRIPT", "touchsim_python", "touchsim_run", "touchsim_source"]

TOUCHSIM_COMMIT = "4ec9f5c382e7d48410566de743d7a4f05de75cec"
"""The commit of hsaal/touchsim the figures were made with (2025-04-05, its newest)."""
TOUCHSIM_SCRIPT = Path(__file__).resolve().parent / "touchsim_afferents.py"


def touchsim_source() -> str:
    """What pip installs TouchSim from: ``FLOWTACT_TOUCHSIM_SOURCE``, else its GitHub commit."""
    return (
        os.environ.get("FLOWTACT_TOUCHSIM_SOURCE")
        or f"git+https://github.com/hsaal/touchsim@{TOUCHSIM_COMMIT}#egg=touchsim"
    )


def touchsim_python() -> tuple[Path | None, str]:
    """The throw-away venv's Python that imports touchsim (made on first use), and where it is.

    Installed editable (``pip install -e``): TouchSim loads its hand outline at import from
    ``surfaces/`` beside its package folder, which only a source tree has (its setup.py puts the
    file elsewhere, and ``import touchsim`` then fails)."""
    py = venv_python("touchsim", ["-e", touchsim_source()], "touchsim")
    return py, f"throw-away venv {VENVS / 'touchsim'} (pip install -e {touchsim_source()})"


def touchsim_run(
    py: Path, s: np.ndarray, d: np.ndarray, cls: np.ndarray, idx: np.ndarray, repeats: int, *, noise: bool = True,
    threads: int = 1, timeout: float = 1800.0,
) -> dict:  # fmt: skip
    """TouchSim's ``lif_neuron`` on s, d (samples × afferents) with models (class, index), ``repeats``
    times after a warm-up, in ``py``'s process with ``threads`` numba threads: each repeat's CPU
    seconds, spike counts (repeats × afferents) and spikes (sample indices, repeat by repeat)."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env["NUMBA_NUM_THREADS"] = str(threads)
    with tempfile.TemporaryDirectory(prefix="ftbench-touchsim-") as tmp:
        inp, out = Path(tmp, "in.npz"), Path(tmp, "out.npz")
        np.savez(inp, s=s, d=d, cls=cls, idx=idx)
        cmd = [str(py), str(TOUCHSIM_SCRIPT), str(inp), str(out), "--repeats", str(repeats)]
        if not noise:
            cmd.append("--noise-off")
        r = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=timeout)
        if r.returncode != 0 or not out.exists():
            tail = "\n".join((r.stderr or r.stdout).strip().splitlines()[-5:])
            raise RuntimeError(f"TouchSim run exited with {r.returncode}:\n{tail}")
        with np.load(out) as f:
            return {k: f[k] for k in ("secs", "counts", "spikes")} | {"version": str(f["version"])}
