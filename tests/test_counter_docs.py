"""Every counter a block reports is explained: the code of each registered block is read (ast) for
what it counts, and each name must be in the block's ``counter_docs``; the CLI and the run summary
print the explanations."""

from __future__ import annotations

import ast
import builtins
import inspect
import textwrap
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import ModuleType
from typing import Any

import numpy as np
import pytest

from flowtact.block import Block, Port, Source, nonfinite_counter_docs, screen_nonfinite
from flowtact.catalog.blocks import block_names, load_block
from flowtact.chunk import Chunk
from flowtact.graphfile.graph import load_graph
from flowtact.help.describe import describe_block
from flowtact.running.compile import compile_graph
from flowtact.runtime.inproc import InprocExecutor, RunSummary, explain_counters
from flowtact.testing import run_offline, run_source

# -- reading a block's code for the counters it keeps -------------------------------------------------


@dataclass
class Counted:
    """Counter names found in the code, and the places where a name could not be read off it."""

    names: set[str] = field(default_factory=set)
    unreadable: list[str] = field(default_factory=list)
    followed: set[tuple[Any, str]] = field(default_factory=set)


def counted_names(cls: type[Block]) -> Counted:
    """Every counter name ``cls`` (with its bases up to Block) can report, read from its source.

    Counting is ``<block>.count(name, ...)`` and any write to ``<block>.counters``, where ``<block>``
    is ``self`` in a method or the parameter a function receives the block in: a call that passes
    the block to a function (``screen_nonfinite(self, ...)``, a module helper) is followed into
    it. A name is a string literal, either branch of a conditional expression, or a loop variable
    over a module-level collection (``for bit, name in FLAGS.items()``); anything else, or a block
    passed somewhere the scan cannot follow, is reported as unreadable.
    """
    out = Counted()
    for klass in cls.__mro__:
        if not issubclass(klass, Block) or klass in (Block, Source):
            continue
        node, module, where = _parse(klass)
        assert isinstance(node, ast.ClassDef)
        for fn in node.body:
            if not isinstance(fn, ast.FunctionDef | ast.AsyncFunctionDef) or not fn.args.args:
                continue
            if any(isinstance(d, ast.Name) and d.id == "staticmethod" for d in fn.decorator_list):
                continue
            _scan(fn, fn.args.args[0].arg, module, where, out)
    return out


def _parse(obj: Any) -> tuple[ast.stmt, ModuleType, str]:
    lines, start = inspect.getsourcelines(obj)
    tree = ast.parse(textwrap.dedent("".join(lines)))
    ast.increment_lineno(tree, start - 1)
    module = inspect.getmodule(obj)
    assert module is not None
    return tree.body[0], module, inspect.getsourcefile(obj) or module.__name__


def _is(node: ast.AST, name: str) -> bool:
    return isinstance(node, ast.Name) and node.id == name


def _is_counters(node: ast.AST, me: str) -> bool:
    return isinstance(node, ast.Attribute) and node.attr == "counters" and _is(node.value, me)


@dataclass(frozen=True)
class _Scope:
    """What a scan of one function knows: the block's name there, the module, the source place and
    each AST node's parent."""

    me: str
    module: ModuleType
    where: str
    parents: Mapping[ast.AST, ast.AST]


def _scan(fn: ast.AST, me: str, module: ModuleType, where: str, out: Counted) -> None:
    """Counters kept on the block named ``me`` inside function ``fn``."""
    parents = {child: node for node in ast.walk(fn) for child in ast.iter_child_nodes(node)}
    scope = _Scope(me, module, where, parents)
    for node in ast.walk(fn):
        if isinstance(node, ast.Call):
            _scan_call(node, scope, out)
        elif isinstance(node, ast.Assign | ast.AugAssign | ast.AnnAssign):
            _scan_assign(node, scope, out)


def _counter_name(expr: ast.AST | None, scope: _Scope, out: Counted) -> None:
    """The counter name(s) ``expr`` stands for, or an unreadable place."""
    if isinstance(expr, ast.Constant) and isinstance(expr.value, str):
        out.names.add(expr.value)
    elif isinstance(expr, ast.IfExp):
        _counter_name(expr.body, scope, out)
        _counter_name(expr.orelse, scope, out)
    elif (
        isinstance(expr, ast.Name) and (found := _loop_values(expr, scope.parents, scope.module)) is not None
    ):
        out.names.update(found)
    else:
        text = ast.unparse(expr) if expr is not None else "?"
        out.unreadable.append(f"{scope.where}:{getattr(expr, 'lineno', '?')}: counter name `{text}`")


def _scan_call(node: ast.Call, scope: _Scope, out: Counted) -> None:
    """``block.count(name)``, a method of ``block.counters``, or the block passed to a function."""
    f = node.func
    if isinstance(f, ast.Attribute) and f.attr == "count" and _is(f.value, scope.me):
        kw = [k.value for k in node.keywords if k.arg == "what"]
        _counter_name(node.args[0] if node.args else kw[0] if kw else None, scope, out)
        return
    if isinstance(f, ast.Attribute) and _is_counters(f.value, scope.me):
        _scan_counters_method(node, f.attr, scope, out)
        return
    passed = [(i, None) for i, a in enumerate(node.args) if _is(a, scope.me)]
    passed += [(None, k.arg) for k in node.keywords if _is(k.value, scope.me)]
    for pos, kw in passed:
        _follow(node, pos, kw, scope.me, scope.module, scope.where, out)


def _scan_counters_method(node: ast.Call, method: str, scope: _Scope, out: Counted) -> None:
    """``block.counters.<method>(...)``: the names it writes; reading methods write none."""
    if method in ("setdefault", "__setitem__") and node.args:
        _counter_name(node.args[0], scope, out)
    elif method == "update" and node.args and isinstance(node.args[0], ast.Dict):
        for key in node.args[0].keys:
            _counter_name(key, scope, out)
    elif method not in ("get", "items", "keys", "values", "copy", "__getitem__", "__contains__"):
        out.unreadable.append(f"{scope.where}:{node.lineno}: `{ast.unparse(node)}`")


def _scan_assign(node: ast.Assign | ast.AugAssign | ast.AnnAssign, scope: _Scope, out: Counted) -> None:
    """Writes to ``block.counters[name]`` and ``block.counters = {...}`` (also inside tuple targets)."""
    targets = list(node.targets) if isinstance(node, ast.Assign) else [node.target]
    while targets:
        t = targets.pop()
        if isinstance(t, ast.Tuple | ast.List):
            targets += t.elts
        elif isinstance(t, ast.Subscript) and _is_counters(t.value, scope.me):
            _counter_name(t.slice, scope, out)
        elif _is_counters(t, scope.me):
            value = node.value
            if isinstance(value, ast.Dict) and all(k is not None for k in value.keys):
                for key in value.keys:
                    _counter_name(key, scope, out)
            else:
                out.unreadable.append(f"{scope.where}:{node.lineno}: `{ast.unparse(node)}`")


_POSITIONAL, _POSITIONAL_OR_KEYWORD = (
    inspect.Parameter.POSITIONAL_ONLY,
    inspect.Parameter.POSITIONAL_OR_KEYWORD,
)


def _follow(
    call: ast.Call, pos: int | None, kw: str | None, me: str, module: ModuleType, where: str, out: Counted
) -> None:
    """The block is passed to a function: scan that function with the parameter that receives it."""
    f = call.func
    if isinstance(f, ast.Attribute) and _is(f.value, me):
        return  # a method of the block itself: scanned with the class
    target = _resolve(f, module)
    if target is not None and getattr(target, "__module__", None) == "builtins":
        return  # isinstance(self, ...), getattr(self, ...), ...
    if not inspect.isfunction(target):
        out.unreadable.append(f"{where}:{call.lineno}: the block is passed to `{ast.unparse(f)}`")
        return
    params = inspect.signature(target).parameters
    positional = [p.name for p in params.values() if p.kind in (_POSITIONAL, _POSITIONAL_OR_KEYWORD)]
    if kw is not None:
        param = kw if kw in params else None
    else:
        param = positional[pos] if pos is not None and pos < len(positional) else None
    if param is None:
        out.unreadable.append(f"{where}:{call.lineno}: the block goes into `{ast.unparse(f)}` via *args/**kw")
        return
    if (target, param) in out.followed:
        return
    out.followed.add((target, param))
    node, target_module, target_where = _parse(target)
    _scan(node, param, target_module, target_where, out)


def _resolve(expr: ast.AST, module: ModuleType) -> Any:
    """The object a dotted name refers to in ``module`` (or builtins), else None."""
    if isinstance(expr, ast.Name):
        if expr.id in vars(module):
            return vars(module)[expr.id]
        return getattr(builtins, expr.id, None)
    if isinstance(expr, ast.Attribute):
        base = _resolve(expr.value, module)
        return getattr(base, expr.attr, None) if base is not None else None
    return None


def _loop_values(name: ast.Name, parents: Mapping[ast.AST, ast.AST], module: ModuleType) -> set[str] | None:
    """The strings a loop variable takes, when it loops over a module-level collection."""
    node: ast.AST = name
    while node in parents:
        node = parents[node]
        if not isinstance(node, ast.For):
            continue
        target, it = node.target, node.iter
        if _is(target, name.id):
            index = None
        elif isinstance(target, ast.Tuple) and any(_is(e, name.id) for e in target.elts):
            index = next(i for i, e in enumerate(target.elts) if _is(e, name.id))
        else:
            continue
        method = None
        if isinstance(it, ast.Call) and isinstance(it.func, ast.Attribute) and not it.args:
            method, it = it.func.attr, it.func.value
        coll = _resolve(it, module)
        if method in ("items", "keys", "values") and isinstance(coll, Mapping):
            items = list(getattr(coll, method)())
        elif method is None and isinstance(coll, list | tuple | set | frozenset | Mapping):
            items = list(coll)
        else:
            return None
        values = [v if index is None else v[index] for v in items]
        return set(values) if all(isinstance(v, str) for v in values) else None
    return None


# -- the blocks ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", block_names())
def test_every_counter_a_block_keeps_is_explained(name):
    cls = load_block(name)
    found = counted_names(cls)
    assert not found.unreadable, (
        f"{name}: cannot tell which counters these keep (name them with a literal string):\n  "
        + "\n  ".join(found.unreadable)
    )
    docs = cls.documented_counters()
    missing = sorted(found.names - set(docs))
    assert not missing, f"{name}: counts {missing} without explaining them in {cls.__name__}.counter_docs"
    stale = sorted(set(docs) - found.names)
    assert not stale, f"{name}: counter_docs explains {stale}, which its code never counts"
    for counter, text in docs.items():
        assert counter.isidentifier(), f"{name}: counter {counter!r} is not an identifier"
        assert isinstance(text, str) and text.strip() and "\n" not in text, f"{name}: {counter}: {text!r}"


@pytest.mark.parametrize("name", block_names())
def test_what_a_block_counts_on_its_example_is_explained(name):
    """The same promise at run time (the examples feed NaN, dropouts and bursts to many blocks)."""
    cls = load_block(name)
    ex = cls.example()
    block = cls(**ex.params)
    if isinstance(block, Source):
        run_source(block, ex.duration_s, inputs=ex.inputs, rate_hz=ex.rate_hz, units=ex.units)
    else:
        run_offline(block, rate_hz=ex.rate_hz, units=ex.units, **ex.inputs)
    assert set(block.counters) <= set(cls.documented_counters()), block.counters


def test_the_counters_the_issue_named_are_explained():
    """The counters a teleop run printed without a word: now each has one."""
    for block, counters in {
        "serial_io": ("late", "resyncs", "stamp_nudged", "cmd_clamped"),
        "force_feedback": ("late", "stalled"),
        "weighted_sum": ("unpaired_at_end",),
    }.items():
        docs = load_block(block).documented_counters()
        for c in counters:
            assert len(docs[c]) > 20, (block, c)


# -- the scan itself: it must see what a careless block counts ------------------------------------------

NAMES = {1: "looped_a", 2: "looped_b"}


def _helper(block: Block, n: int) -> None:
    block.count("via_helper", n)


class _Careless(Block):
    counter_docs = {"documented": "a documented counter"}
    inputs = {"x": Port(doc="x")}
    outputs = {"y": Port(doc="y")}

    def step(self, x: Chunk | None = None, **_: Chunk) -> dict[str, Chunk]:
        self.count("documented")
        self.count("forgotten", 2)
        self.counters["assigned"] = 1
        self.counters.setdefault("set_by_default", 0)
        _helper(self, 3)
        screen_nonfinite(self, x, "drop", "x", None)  # type: ignore[arg-type]
        for _, name in NAMES.items():
            self.count(name)
        self.count("then" if x else "otherwise")
        return {}


class _Sloppy(_Careless):
    counter_docs = {"forgotten": "documented in the subclass"}

    def flush(self) -> dict[str, Chunk]:
        self.count(f"made_up_{len(self.counters)}")
        _KeepsTheBlock(self)
        return {}


class _KeepsTheBlock:  # the scan cannot see what this does with the block later
    def __init__(self, block: Block) -> None:
        self.block = block


def test_the_scan_finds_every_way_of_counting():
    found = counted_names(_Careless)
    assert found.names == {
        "documented",
        "forgotten",
        "assigned",
        "set_by_default",
        "via_helper",
        "nonfinite_drop",
        "nonfinite_hold",
        "looped_a",
        "looped_b",
        "then",
        "otherwise",
    }
    assert not found.unreadable


def test_the_scan_reports_what_it_cannot_read_and_docs_merge_over_bases():
    found = counted_names(_Sloppy)
    assert "forgotten" in found.names
    assert any("made_up_" in u for u in found.unreadable)
    assert any("_KeepsTheBlock" in u for u in found.unreadable)
    assert _Sloppy.documented_counters() == {
        "documented": "a documented counter",
        "forgotten": "documented in the subclass",
    }


# -- what the user sees: `flowtact blocks NAME` and the run summary ----------------------------------------


def test_describe_block_lists_the_counters():
    text = describe_block(load_block("serial_io"))
    section = text.split("\nCounters:\n", 1)[1]
    for name, doc in load_block("serial_io").documented_counters().items():
        assert f"  {name}\n      " in section  # the name, then its doc below it, wrapped to the width
        assert " ".join(f"{name} {doc}".split()) in " ".join(section.split())
    assert "Counters:" not in describe_block(load_block("aunp_sensor"))  # counts nothing: no section


def test_nonfinite_counter_docs_name_the_samples():
    docs = nonfinite_counter_docs("force samples on 'x'")
    assert set(docs) == {"nonfinite_drop", "nonfinite_hold"}
    assert all(d.startswith("force samples on 'x' with NaN/inf") for d in docs.values())


def test_the_summary_explains_each_counter_and_json_carries_the_explanations():
    summary = RunSummary(
        graph="g",
        duration_s=1.0,
        wall_s=0.5,
        stopped_by="duration",
        counters={"exo": {"resyncs": 3, "late": 2}, "sink": {"received": 7}},
        counter_docs={"exo": {"resyncs": "the clock estimate restarted", "late": "came too late"}},
    )
    lines = summary.format().splitlines()
    assert lines[1:] == [  # one counter per line, explanations in one column
        "  exo: late=2       came too late",
        "  exo: resyncs=3    the clock estimate restarted",
        "  sink: received=7",  # a block that documents nothing still prints its counts
    ]
    d = summary.to_dict()
    assert d["counters"] == summary.counters and d["counter_docs"] == summary.counter_docs


def test_an_inproc_run_explains_its_counters(tmp_path):
    path = tmp_path / "g.yaml"
    path.write_text(
        """
name: bad_samples
seed: 1
nodes:
  src:  {block: replay, params: {path: PATH, units: N, time_offset_s: -0.05}}
  filt: {block: lowpass, params: {cutoff_hz: 5, on_bad_data: drop}}
edges:
  - src.y -> filt.x
record: [filt.y]
""".replace("PATH", str(tmp_path / "x.npz"))
    )
    x = np.ones(100)
    x[[10, 20, 30]] = np.nan
    np.savez(tmp_path / "x.npz", t=np.arange(100) / 100.0, data=x)
    plan = compile_graph(load_graph(path))
    summary = InprocExecutor(plan, fast=True).run(0.9)
    assert summary.counters == {"src": {"skipped_before_zero": 5}, "filt": {"nonfinite_drop": 3}}
    assert summary.counter_docs == explain_counters(plan, summary.counters)
    lines = summary.format().splitlines()
    lowpass_docs = load_block("lowpass").documented_counters()
    assert f"  filt: nonfinite_drop=3      {lowpass_docs['nonfinite_drop']}" in lines
    replay_docs = load_block("replay").documented_counters()
    assert f"  src: skipped_before_zero=5  {replay_docs['skipped_before_zero']}" in lines
