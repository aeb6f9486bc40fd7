"""Optional packages a graph's active blocks need, checked before anything starts.

A block names the modules it imports beyond flowtact's core in ``requires`` (import name -> the
pip extra that installs it, e.g. ``{"serial": "serial"}``); a config may narrow that down
(``Block.required_modules``). Availability is looked up with ``importlib.util.find_spec``, which
imports nothing, so validating a graph that needs torch stays fast and never loads torch.
"""

from __future__ import annotations

import importlib.metadata
import importlib.util
import re
from collections.abc import Iterable
from typing import TYPE_CHECKING

from flowtact.graphfile.located import GraphProblem

if TYPE_CHECKING:
    from flowtact.graphfile.graph import Graph

__all__ = ["install_hint", "missing_extras", "module_available"]


def module_available(name: str) -> bool:
    """Whether ``import name`` would find the module (without importing it)."""
    try:
        return importlib.util.find_spec(name) is not None
    except ValueError:  # already imported, without a spec (``__spec__`` is None): it is there
        return True
    except ImportError:  # a parent package of a dotted name is missing
        return False


def _distribution(module: str) -> str | None:
    """The installed distribution that ships the top-level package of ``module`` (``flowtact``)."""
    top = module.partition(".")[0]
    try:
        dists = importlib.metadata.packages_distributions().get(top, [])
    except Exception:  # noqa: BLE001 - broken metadata of another package must not hide the real problem
        dists = []
    return dists[0] if dists else None


def _extra_packages(dist: str, extra: str) -> list[str]:
    """The packages a distribution's extra installs (``flowtact``, ``serial`` -> ``[pyserial]``)."""
    try:
        reqs = importlib.metadata.requires(dist) or []
    except importlib.metadata.PackageNotFoundError:
        return []
    marker = re.compile(rf"""extra\s*==\s*['"]{re.escape(extra)}['"]""")
    names = []
    for req in reqs:
        spec, _, env = req.partition(";")
        name = re.match(r"\s*([A-Za-z0-9][A-Za-z0-9._-]*)", spec)
        if name and marker.search(env):
            names.append(name.group(1))
    return names


def install_hint(block_module: str, module: str, extra: str) -> tuple[str, str]:
    """(what is missing, how to install it) for ``module`` of a block defined in ``block_module``:
    ``("pyserial", 'pip install "flowtact[serial]"')``; without an extra, the module's own name."""
    dist = _distribution(block_module) if extra else None
    if dist is None:
        return f"module '{module}'", f"pip install {module} (or the package that provides it)"
    packages = [p for p in _extra_packages(dist, extra) if p.lower() != dist.lower()]
    return (", ".join(packages) or f"module '{module}'"), f'pip install "{dist}[{extra}]"'


def missing_extras(graph: Graph, active: Iterable[str]) -> list[GraphProblem]:
    """An error at each active node whose block needs a module that is not installed."""
    errors = []
    for name in active:
        node = graph.nodes[name]
        for module, extra in node.cls.required_modules(node.config).items():
            if module_available(module):
                continue
            what, how = install_hint(node.cls.__module__, module, extra)
            errors.append(GraphProblem(node.loc, f"node '{name}': block {node.cls.name} needs {what}: {how}"))
    return errors
