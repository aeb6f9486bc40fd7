"""The layout shows the architecture, and these rules keep it so (docs/architecture.md).

* ``flowtact/`` (the framework) never imports ``flowtact.blocks``;
* a generic family (signal, spiking, devices) never imports a domain;
* a domain (touch, teleop, ...) never imports another domain;
* every Block subclass defined in blocks/ is registered under its name (pyproject.toml entry
  points), so the conformance suite runs on it;
* no module imports another module's private (``_name``) name (framework, blocks, bench, scripts);
* no two modules import each other, directly or round a circle;
* the framework's modules sit in rooms named for their job (``CORE`` at the top level, the rest in
  ``ROOMS``), and the framework's tests mirror them (tests/ROOM/);
* the framework names no library block (no literal ``load_block("...")``): it asks for a role
  (``flowtact.catalog.blocks.ROLES``), which a registered block fills.

Imports are read from the source (every ``import`` statement, including those inside functions and
under ``if TYPE_CHECKING``): a function-level or type-only import is how a circle is usually hidden,
and it still ties the two modules to each other.
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
CORE = ("__init__", "api", "block", "chunk", "params", "finite", "errors", "version", "testing", "cli")
"""The framework's top level: what a block author imports (and the command line)."""
ROOMS = {
    "streams": "helpers that pair and join a block's input streams",
    "inputs": "untrusted input read within bounds and shown as data",
    "graphfile": "the graph file and its checks",
    "running": "a graph compiled, launched and ended, above the runtime",
    "runtime": "the engine: executors, workers, supervisor, links",
    "recording": "HDF5 recordings, their checksums, `flowtact info`",
    "help": "docs and help rendering",
    "console": "what every command shares on the terminal",
    "catalog": "entry-point registries",
    "verify": "the conformance suite's messages, numerical stress cases",
    "pictures": "`flowtact graph` and `flowtact plot`",
    "benchmark": "`flowtact bench`",
    "sweeps": "`flowtact sweep`",
    "commands": "the command line's commands, one module each, found through one entry-point group",
    "view": "`flowtact run --view`: live streams in a browser",
}
TEST_ONLY_ROOMS = ("blocks", "docs")
"""Test folders with no framework room: the block library's tests, the docs' own tests."""
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


def _private_imports(path: Path) -> list[str]:
    """``from M import _name`` / ``import M._part`` in a file: a private name taken from another module."""
    bad = []
    for node in ast.walk(ast.parse(path.read_text())):
        names = []
        if isinstance(node, ast.ImportFrom):
            names = [f"from {'.' * node.level}{node.module or ''} import {a.name}" for a in node.names
                     if a.name.startswith("_") and not a.name.startswith("__")]  # fmt: skip
        elif isinstance(node, ast.Import):
            names = [f"import {a.name}" for a in node.names
                     if any(p.startswith("_") and not p.startswith("__") for p in a.name.split("."))]  # fmt: skip
        bad += [f"{path.relative_to(ROOT)}:{node.lineno}: {n}" for n in names]
    return bad


def test_no_module_imports_another_modules_private_name():
    """What a module keeps private (a leading underscore) is not another module's to import: share
    it under a public name instead (issue 32). Attribute access (``mod._name``) is ruff's SLF001."""
    folders = (
        ("flowtact", "flowtact"),
        ("blocks", "flowtact.blocks"),
        ("bench", "flowtact.bench"),
        ("scripts", "scripts"),
    )
    bad = [b for folder, pkg in folders for path, _ in _sources(folder, pkg) for b in _private_imports(path)]
    assert not bad, bad


def test_the_private_import_rule_sees_one(tmp_path, monkeypatch):
    (tmp_path / "m.py").write_text(
        "from flowtact.recording.hdf5 import _attr\nimport os._x\nfrom a import __all__\n"
    )
    monkeypatch.setattr(f"{__name__}.ROOT", tmp_path)
    assert _private_imports(tmp_path / "m.py") == [
        "m.py:1: from flowtact.recording.hdf5 import _attr",
        "m.py:2: import os._x",
    ]


def _literal_block_lookups(path: Path) -> list[str]:
    """``load_block("NAME")`` calls with a literal name: a library block named by the framework."""
    bad = []
    for node in ast.walk(ast.parse(path.read_text())):
        if not (isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant)):
            continue
        func = node.func.attr if isinstance(node.func, ast.Attribute) else getattr(node.func, "id", "")
        if func == "load_block":
            bad.append(f"{path.relative_to(ROOT)}:{node.lineno}: load_block({node.args[0].value!r})")
    return bad


def test_the_framework_asks_for_library_blocks_by_role_only():
    """The framework never names a library block (``load_block("replay")`` hides a dependency on
    the library from rule 1); it asks for a role, and every role is filled by a registered block."""
    from importlib.metadata import entry_points

    from flowtact.catalog.blocks import ROLES, ROLES_GROUP, role_block

    bad = [b for path, _ in _sources("flowtact", "flowtact") for b in _literal_block_lookups(path)]
    assert not bad, bad
    registered = {load_block(n) for n in block_names()}
    assert {ep.name for ep in entry_points(group=ROLES_GROUP)} == set(ROLES)
    for role in ROLES:
        assert role_block(role) in registered, role
    assert callable(role_block("replay").stand_in)  # type: ignore[attr-defined]


def test_the_role_rule_sees_a_literal_block_name(tmp_path, monkeypatch):
    (tmp_path / "m.py").write_text(
        "from flowtact.catalog.blocks import load_block\nx = load_block('replay')\n"
    )
    monkeypatch.setattr(f"{__name__}.ROOT", tmp_path)
    assert _literal_block_lookups(tmp_path / "m.py") == ["m.py:2: load_block('replay')"]


def test_every_package_folder_is_in_the_wheel():
    """A folder with an ``__init__.py`` that pyproject's package list leaves out is missing from an
    installed flowtact (the editable install hides it; .ci/run's wheel check finds it late)."""
    import tomllib

    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    dirs = {"flowtact": "flowtact", "blocks": "flowtact.blocks", "bench": "flowtact.bench"}
    found = {
        ".".join([dirs[top], *init.parent.relative_to(ROOT / top).parts])
        for top in dirs
        for init in (ROOT / top).rglob("__init__.py")
    }
    assert not found - listed, sorted(found - listed)


def test_the_framework_sits_in_its_documented_rooms():
    top = sorted(p.stem for p in (ROOT / "flowtact").glob("*.py"))
    assert top == sorted(CORE), f"a top-level module outside CORE: put it in a room ({sorted(ROOMS)})"
    rooms = sorted(p.name for p in (ROOT / "flowtact").iterdir() if (p / "__init__.py").exists())
    assert rooms == sorted(ROOMS)
    for room in (r for r in rooms if r != "runtime"):  # runtime/ is being rebuilt (issue 32, Deliver 1)
        doc = (ROOT / "flowtact" / room / "__init__.py").read_text()
        assert doc.startswith('"""'), f"flowtact/{room}/__init__.py: say what the room holds"


def test_the_framework_tests_mirror_its_rooms():
    folders = {p.name for p in (ROOT / "tests").iterdir() if p.is_dir() and any(p.rglob("test_*.py"))}
    assert folders <= set(ROOMS) | set(TEST_ONLY_ROOMS), folders - set(ROOMS) - set(TEST_ONLY_ROOMS)
    assert len(folders) >= 10
    names = [p.name for p in (ROOT / "tests").rglob("test_*.py")]
    assert len(names) == len(set(names)), "test file names must stay unique (the folders have no __init__.py)"


def _module_graph() -> dict[str, set[str]]:
    """Module -> the modules of flowtact/, blocks/ and bench/ it imports (packages by their __init__)."""
    files: dict[str, tuple[Path, str]] = {}
    for folder, package in (
        ("flowtact", "flowtact"),
        ("blocks", "flowtact.blocks"),
        ("bench", "flowtact.bench"),
    ):
        for path, pkg in _sources(folder, package):
            rel = path.relative_to(ROOT / folder).with_suffix("")
            files[".".join([package, *rel.parts]).removesuffix(".__init__")] = (path, pkg)
    return {
        name: {m for m in _imports(path, pkg) if m in files and m != name}
        for name, (path, pkg) in files.items()
    }


def _circles(graph: dict[str, set[str]]) -> list[set[str]]:
    """The strongly connected groups of more than one module (Tarjan's algorithm, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[set[str]] = []
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            v, edges = work[-1]
            w = next(edges, None)
            if w is None:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    group = set()
                    while True:
                        x = stack.pop()
                        on_stack.discard(x)
                        group.add(x)
                        if x == v:
                            break
                    if len(group) > 1:
                        out.append(group)
            elif w not in index:
                index[w] = low[w] = len(index)
                stack.append(w)
                on_stack.add(w)
                work.append((w, iter(sorted(graph[w]))))
            elif w in on_stack:
                low[v] = min(low[v], index[w])
    return out


def test_the_circle_finder_finds_circles_and_only_them():
    assert _circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [{"a", "b", "c"}]
    assert _circles({"a": {"b"}, "b": set(), "c": {"b"}}) == []
    assert sorted(map(sorted, _circles({"a": {"b"}, "b": {"a"}, "c": {"d"}, "d": {"c", "a"}}))) == [
        ["a", "b"],
        ["c", "d"],
    ]


def test_the_import_graph_is_read_with_function_level_and_type_only_imports():
    graph = _module_graph()
    assert "flowtact.running.compile" in graph["flowtact.running.launch"]  # module level
    assert "flowtact.sweeps.api" in graph["flowtact"]  # inside a function (flowtact.sweep)
    assert len(graph) > 150


def test_no_two_modules_import_each_other():
    circles = _circles(_module_graph())
    assert not circles, (
        f"import circles (move what both need to a third module): {[sorted(c) for c in circles]}"
    )
