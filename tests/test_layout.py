"""The layout shows the architecture, and these rules keep it so (docs/architecture.md).

* ``flowtact/`` (the framework) never imports ``flowtact.blocks``;
* a generic family (signal, spiking, devices) never imports a domain;
* a domain (touch, teleop, ...) never imports another domain;
* every Block subclass defined in blocks/ is registered under its name (pyproject.toml entry
  points), so the conformance suite runs on it.

Imports are read from the source (every ``import`` statement, including those inside functions).
"""

from __future__ import annotations

import ast
import inspect
import pkgutil
from importlib import import_module
from pathlib import Path

import pytest

import flowtact.blocks
from flowtact.block import Block
from flowtact.catalog.blocks import block_names, load_block

ROOT = Path(__file__).resolve().parent.parent
FAMILIES = ("signal", "spiking", "devices")
DOMAINS = ("touch", "teleop", "braille")


def _imports(path: Path, package: str) -> set[str]:
    """Absolute names of the modules a file imports (relative imports resolved against ``package``)."""
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                mod = f"{base}.{node.module}" if node.module else base
            else:
                mod = node.module or ""
            out.add(mod)
            out |= {f"{mod}.{a.name}" for a in node.names}
    return out


def _room(module: str) -> str | None:
    """The generic family or domain a ``flowtact.blocks.<room>...`` module belongs to."""
    parts = module.split(".")
    return parts[2] if len(parts) > 2 and parts[:2] == ["flowtact", "blocks"] else None


def _sources(folder: str, package: str) -> list[tuple[Path, str]]:
    """(file, its package name) for every .py file below ``folder``."""
    out = []
    for path in sorted((ROOT / folder).rglob("*.py")):
        rel = path.relative_to(ROOT / folder).with_suffix("")
        parts = [package, *rel.parts]
        pkg = ".".join(parts if parts[-1] == "__init__" else parts[:-1]).removesuffix(".__init__")
        out.append((path, pkg))
    return out


def test_the_rooms_are_the_documented_ones():
    rooms = {p.name for p in (ROOT / "blocks").iterdir() if (p / "__init__.py").exists()}
    assert rooms <= set(FAMILIES + DOMAINS)
    assert not [p.name for p in (ROOT / "blocks").glob("*.py") if p.name != "__init__.py"]


def test_the_framework_never_imports_the_block_library():
    bad = [
        f"{path.relative_to(ROOT)} imports {m}"
        for path, pkg in _sources("flowtact", "flowtact")
        for m in _imports(path, pkg)
        if m == "flowtact.blocks" or m.startswith("flowtact.blocks.")
    ]
    assert not bad, bad


def test_families_never_import_domains_and_domains_never_import_each_other():
    bad = []
    for path, pkg in _sources("blocks", "flowtact.blocks"):
        here = _room(f"{pkg}.x")
        for m in _imports(path, pkg):
            there = _room(m)
            if there is None or there == here:
                continue
            if here in FAMILIES and there in DOMAINS:
                bad.append(f"{path.relative_to(ROOT)}: family '{here}' imports domain module {m}")
            if here in DOMAINS and there in DOMAINS:
                bad.append(f"{path.relative_to(ROOT)}: domain '{here}' imports domain module {m}")
    assert not bad, bad


def _block_classes() -> list[type[Block]]:
    found = []
    for info in pkgutil.walk_packages(flowtact.blocks.__path__, "flowtact.blocks."):
        try:
            module = import_module(info.name)
        except ImportError as e:  # an optional extra (torch, OpenCV) that is not installed
            pytest.skip(f"{info.name}: {e}")
        for _, cls in inspect.getmembers(module, inspect.isclass):
            if issubclass(cls, Block) and cls.__module__ == module.__name__ and cls.__dict__.get("step"):
                found.append(cls)
    return found


def test_every_block_class_is_registered_under_its_name():
    classes = _block_classes()
    assert len(classes) >= 27
    unregistered = [
        f"{c.__module__}.{c.__name__} (name '{c.name}')"
        for c in classes
        if c.name not in block_names() or load_block(c.name) is not c
    ]
    assert not unregistered, f"add these to [project.entry-points.'flowtact.blocks']: {unregistered}"


def test_the_framework_never_imports_the_benchmark_suites():
    bad = [
        f"{path.relative_to(ROOT)} imports {m}"
        for path, pkg in _sources("flowtact", "flowtact")
        for m in _imports(path, pkg)
        if m == "flowtact.bench" or m.startswith("flowtact.bench.")
    ]
    assert not bad, bad


def test_every_benchmark_suite_in_bench_is_registered_under_its_name():
    from flowtact.benchmark import Suite, suites

    registered = suites()
    defined = []
    for path, pkg in _sources("bench", "flowtact.bench"):
        if "SUITE = Suite(" not in path.read_text():
            continue
        module = import_module(pkg + "." + path.stem if path.stem != "__init__" else pkg)
        defined.append(module.SUITE)
    assert len(defined) >= 9
    missing = [f"{s.name} ({s.run.__module__})" for s in defined if registered.get(s.name) is not s]
    assert not missing, f"add these to [project.entry-points.'flowtact.bench']: {missing}"
    assert all(isinstance(s, Suite) for s in registered.values())
