"""The hostile cases of tests/inputs/test_hostile_input.py: they live in bench/hostile_cases.py (installed as
flowtact.bench.hostile_cases) so that ``flowtact bench hostile_input`` runs from a wheel too."""

from pathlib import Path

from flowtact.bench.hostile_cases import CASES, TOUCH, Measured, run_measured

ROOT = Path(__file__).resolve().parent.parent

__all__ = ["CASES", "ROOT", "TOUCH", "Measured", "run_measured"]
