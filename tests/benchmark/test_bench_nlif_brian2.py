"""The nlif suite's Brian2 comparison (--peers): where Brian2 comes from, its run of the suite's population
through bench/peers/brian2_lif.py, and the spike-train agreement it reports. No timing is asserted."""

from __future__ import annotations

import importlib.util
import stat
import sys
from pathlib import Path

import numpy as np
import pytest

from flowtact.bench.blocks.spiking import nlif as suite
from flowtact.bench.peers import venv

pytestmark = pytest.mark.oracle


def test_agreement_counts_common_and_lone_step_neuron_pairs():
    ours = (np.array([3, 3, 7, 9]), np.array([0, 1, 0, 2]))
    theirs = (np.array([3, 7, 8, 9]), np.array([1, 0, 0, 1]))
    a = suite.spike_agreement(ours, theirs)
    assert a == {
        "flowtact": 4,
        "brian2": 4,
        "common": 2,
        "only_flowtact": 2,
        "only_brian2": 2,
        "identical": False,
    }
    assert suite.spike_agreement(ours, ours)["identical"]
    # the same steps with the neurons swapped is a disagreement, not a match
    assert not suite.spike_agreement(
        (np.array([1, 2]), np.array([0, 1])), (np.array([1, 2]), np.array([1, 0]))
    )["identical"]


def test_brian2_script_spikes_like_the_block_for_the_suites_population():
    b = suite.brian2_run(Path(sys.executable), 5, 0.3, 1, target="numpy")
    assert len(b["secs"]) == 1 and b["target"] == "numpy" and b["version"]
    ours = suite.block_spikes(5, 0.3)
    assert len(ours[0]) > 20  # the population does fire
    assert suite.spike_agreement(ours, (b["steps"], b["idx"]))["identical"]


def test_brian2_comes_from_this_environment_or_a_venv_pinned_like_constraints(monkeypatch):
    assert suite.brian2_python() == (Path(sys.executable), "this environment")
    asked = {}

    def fake_venv(name, packages, module):
        asked.update(name=name, packages=list(packages), module=module)
        return Path("/venv/bin/python")

    monkeypatch.setattr(importlib.util, "find_spec", lambda _name: None)
    monkeypatch.setattr(suite, "venv_python", fake_venv)
    py, where = suite.brian2_python()
    assert py == Path("/venv/bin/python") and "throw-away venv" in where
    assert asked == {
        "name": "brian2",
        "packages": ["brian2==2.9.0", f"numpy=={np.__version__}"],
        "module": "brian2",
    }
    constraints = Path(suite.__file__).resolve().parents[3] / "constraints.txt"
    if constraints.exists():  # a source checkout: the pin is constraints.txt's
        assert "brian2==2.9.0" in constraints.read_text().split()


def test_a_venv_whose_python_imports_the_module_is_reused_without_pip(tmp_path):
    py = tmp_path / "ref" / "bin" / "python"
    py.parent.mkdir(parents=True)
    py.write_text("#!/bin/sh\nexit 0\n")  # "imports" anything
    py.chmod(py.stat().st_mode | stat.S_IXUSR)
    assert venv.venv_python("ref", ["nothing-to-install"], "anything", root=tmp_path) == py
