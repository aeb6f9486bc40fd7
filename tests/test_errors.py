"""Every public error of the framework lives in flowtact.errors, derives from FlowtactError and is
exported by ``flowtact`` (issue 32, point 5): one place to read them, one base to catch them."""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import pytest

import flowtact
import flowtact.errors
from flowtact.errors import FlowtactError


def _framework_modules() -> list[str]:
    """Every module of the framework (the block library and the bench suites excluded)."""
    return [
        info.name
        for info in pkgutil.walk_packages(flowtact.__path__, "flowtact.")
        if not info.name.startswith(("flowtact.blocks.", "flowtact.bench."))
        and info.name not in ("flowtact.blocks", "flowtact.bench")
    ]


def _public_exceptions() -> dict[str, type[BaseException]]:
    found: dict[str, type[BaseException]] = {}
    for name in _framework_modules():
        try:
            module = importlib.import_module(name)
        except ImportError as e:  # an optional extra that is not installed
            if "flowtact" in str(e):
                raise
            continue
        for attr, cls in inspect.getmembers(module, inspect.isclass):
            if issubclass(cls, BaseException) and cls.__module__ == name and not attr.startswith("_"):
                found[f"{name}.{attr}"] = cls
    return found


def test_the_walk_sees_the_whole_framework():
    modules = _framework_modules()
    assert len(modules) > 60
    for room in ("flowtact.runtime.worker", "flowtact.benchmark.suite", "flowtact.sweeps.grid"):
        assert room in modules


def test_every_public_exception_is_defined_in_flowtact_errors():
    elsewhere = sorted(k for k in _public_exceptions() if not k.startswith("flowtact.errors."))
    assert not elsewhere, f"move these to flowtact/errors.py (or make them private): {elsewhere}"


def test_every_public_exception_derives_from_the_one_base_and_is_exported():
    found = _public_exceptions()
    assert len(found) >= 24
    not_based = sorted(k for k, c in found.items() if not issubclass(c, FlowtactError))
    assert not not_based, f"not a FlowtactError: {not_based}"
    unexported = sorted(k for k, c in found.items() if getattr(flowtact, c.__name__, None) is not c)
    assert not unexported, f"add to flowtact/__init__.py and its __all__: {unexported}"
    assert set(flowtact.errors.__all__) <= set(flowtact.__all__)
    assert set(flowtact.errors.__all__) == {c.__name__ for c in found.values()}


@pytest.mark.parametrize(
    ("name", "builtin"),
    [
        ("SafeYamlError", ValueError),
        ("WireError", ValueError),
        ("ConformanceError", AssertionError),
        ("UnknownBlockError", LookupError),
        ("RecordingCorrupted", OSError),
        ("NodeError", RuntimeError),
    ],
)
def test_each_error_keeps_the_builtin_base_callers_catch(name: str, builtin: type[BaseException]):
    cls = getattr(flowtact, name)
    assert issubclass(cls, FlowtactError)
    assert issubclass(cls, builtin)


def test_the_exception_and_the_record_say_what_they_are():
    from flowtact.graphfile.located import GraphProblem, Loc

    problem = GraphProblem(Loc("g.yaml", 3, 5), "unknown block 'x'", hint="did you mean 'y'?")
    err = flowtact.GraphFileError([problem, GraphProblem(Loc("g.yaml", 4, 1), "second")])
    assert not issubclass(GraphProblem, BaseException)
    assert err.errors[0] is problem
    assert str(err) == "g.yaml:3:5: unknown block 'x'\n    hint: did you mean 'y'?\ng.yaml:4:1: second"
    assert not hasattr(flowtact.errors, "GraphErrors")
