"""Block configuration: frozen dataclasses whose fields carry their rules and a one-line doc.

A config is built once from plain values (YAML, ``--set``, keyword arguments), checked field by
field against declared rules, then by the class's ``check()`` for cross-field rules. Every failure
is a :class:`ConfigError` naming the owner, the field and the rule, in one template.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import types
import typing
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, Literal, Self, get_args, get_origin

from flowtact.errors import ConfigError
from flowtact.inputs.limits import budget_problem

__all__ = ["Config", "ConfigError", "FieldInfo", "Rules", "did_you_mean", "param"]


def did_you_mean(name: str, options: typing.Iterable[str]) -> str:
    """`` (did you mean 'x'?)`` for the closest option, or a list of valid ones."""
    options = sorted(options)
    close = difflib.get_close_matches(name, options, n=1, cutoff=0.6)
    if close:
        return f" (did you mean '{close[0]}'?)"
    return f" (valid: {', '.join(options)})" if options else ""


@dataclass(frozen=True)
class Rules:
    """Declarative value rules for one field; numeric rules apply element-wise to sequences."""

    ge: float | None = None
    gt: float | None = None
    le: float | None = None
    lt: float | None = None
    odd: bool = False
    min_len: int | None = None
    max_len: int | None = None

    def violation(self, v: Any) -> str | None:
        """The rule ``v`` breaks, as text, or None."""
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            if self.ge is not None and not v >= self.ge:
                return f">= {self.ge:g}"
            if self.gt is not None and not v > self.gt:
                return f"> {self.gt:g}"
            if self.le is not None and not v <= self.le:
                return f"<= {self.le:g}"
            if self.lt is not None and not v < self.lt:
                return f"< {self.lt:g}"
            if self.odd and isinstance(v, int) and v % 2 == 0:
                return "odd"
        return None

    def text(self) -> str:
        """All rules as one phrase, for documentation."""
        parts = [
            f"{op} {b:g}"
            for op, b in ((">=", self.ge), (">", self.gt), ("<=", self.le), ("<", self.lt))
            if b is not None
        ]
        if self.odd:
            parts.append("odd")
        if self.min_len is not None:
            parts.append(f"at least {self.min_len} items")
        if self.max_len is not None:
            parts.append(f"at most {self.max_len} items")
        return ", ".join(parts)


def param(
    default: Any = dataclasses.MISSING,
    *,
    doc: str,
    ge: float | None = None,
    gt: float | None = None,
    le: float | None = None,
    lt: float | None = None,
    odd: bool = False,
    min_len: int | None = None,
    max_len: int | None = None,
    kw_only: bool = False,
    path: bool = False,
) -> Any:
    """Declare a config field with its one-line doc and rules (units belong in the field name).

    ``kw_only`` lets a base config's field (with a default) precede a subclass's required fields.
    ``path`` marks a file or folder name (a string, or strings in a list): a relative one written in
    a graph file is resolved against the graph file's folder (:mod:`flowtact.graphfile.param_paths`).
    """
    if isinstance(default, list):
        default = _freeze(default)
    rules = Rules(ge, gt, le, lt, odd, min_len, max_len)
    metadata = {"doc": doc, "rules": rules, "path": path}
    return dataclasses.field(default=default, metadata=metadata, kw_only=kw_only)


@dataclass(frozen=True)
class FieldInfo:
    """One documented config field, as ``flowtact blocks NAME`` prints it."""

    name: str
    type: str
    default: Any
    doc: str
    rules: str


@dataclass(frozen=True)
class Config:
    """Base of every block config (itself the config of a block without parameters). Subclasses are ``@dataclass(frozen=True)`` with ``param`` fields.

    Override ``check()`` for rules across fields and raise ``self.error(field, message)``.
    """

    owner: ClassVar[str] = "config"

    def check(self) -> None:
        """Cross-field rules; raise ``self.error(...)`` when one is broken."""

    def state_bytes(self) -> Mapping[str, float]:
        """Bytes of state (and of one tick's output, for a source) each size parameter implies:
        field -> estimate, computed from the field values alone (never by allocating).

        ``build`` refuses a value whose estimate exceeds
        :data:`flowtact.inputs.limits.STATE_BUDGET_BYTES`, before ``check()`` or anything else runs.
        Override it in every config whose state grows with a parameter (a population size, a
        window length, a sample shape).
        """
        return {}

    def error(self, field: str | None, message: str) -> ConfigError:
        """A ConfigError for this config's owner."""
        return ConfigError(self.owner, field, message)

    @classmethod
    def build(cls, params: Mapping[str, Any] | None = None, owner: str | None = None) -> Self:
        """Validate plain values (YAML or keyword arguments) into a frozen config."""
        owner = owner or cls.__name__
        params = dict(params or {})
        hints = typing.get_type_hints(cls)
        fields = {f.name: f for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
        for key in params:
            if key not in fields:
                raise ConfigError(
                    owner, None, f"unknown parameter '{key}'{did_you_mean(key, fields)}", unknown=key
                )
        values = {}
        for name, f in fields.items():
            if name in params:
                rules = f.metadata.get("rules", Rules())
                values[name] = _coerce(params[name], hints[name], rules, owner, name)
            elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
                raise ConfigError(owner, name, "is required but was not given")
        obj = cls(**values)
        object.__setattr__(obj, "owner", owner)
        object.__setattr__(obj, "given", frozenset(params))  # what was given, as against defaulted
        over = budget_problem(dict(obj.state_bytes()))
        if over:
            field, rule = over
            raise _must_be(owner, field, rule, getattr(obj, field), type_error=False)
        try:
            obj.check()
        except ConfigError as e:
            raise ConfigError(owner, e.field, e.rule, unknown=e.unknown) from None
        return obj

    def to_dict(self) -> dict[str, Any]:
        """Plain YAML-safe values (tuples become lists) that ``build`` accepts back."""
        return {f.name: _thaw(getattr(self, f.name)) for f in dataclasses.fields(self)}  # type: ignore[arg-type]

    @classmethod
    def fields_info(cls) -> list[FieldInfo]:
        """Name, type, default, doc and rules of each field."""
        hints = typing.get_type_hints(cls)
        out = []
        for f in dataclasses.fields(cls):  # type: ignore[arg-type]
            default = None if f.default is dataclasses.MISSING else _thaw(f.default)
            rules = f.metadata.get("rules", Rules())
            out.append(
                FieldInfo(f.name, _type_name(hints[f.name]), default, f.metadata.get("doc", ""), rules.text())
            )
        return out

    @classmethod
    def invalid_values(cls) -> Iterator[tuple[str, Any]]:
        """Values that break each field's declared type or rules (for the conformance suite)."""
        hints = typing.get_type_hints(cls)
        for f in dataclasses.fields(cls):  # type: ignore[arg-type]
            hint, rules = hints[f.name], f.metadata.get("rules", Rules())
            yield f.name, _wrong_type_value(hint)
            base = _strip_optional(hint)
            origin = get_origin(base)
            if origin is Literal:
                yield f.name, "__not_an_option__"
            scalar = base
            if origin is tuple:
                scalar = get_args(base)[0]
                if rules.min_len:
                    yield f.name, []
            for bad in _rule_breakers(rules, scalar):
                yield f.name, ([bad] * max(rules.min_len or 1, 1) if origin is tuple else bad)


def _rule_breakers(rules: Rules, scalar: Any) -> Iterator[Any]:
    step = 1 if scalar is int else 1.0
    if rules.ge is not None:
        yield _type_cast(scalar, rules.ge - step)
    if rules.gt is not None:
        yield _type_cast(scalar, rules.gt)
    if rules.le is not None:
        yield _type_cast(scalar, rules.le + step)
    if rules.lt is not None:
        yield _type_cast(scalar, rules.lt)
    if rules.odd:
        low = rules.ge if rules.ge is not None else (rules.gt or 0) + 1
        yield int(math.ceil(low / 2) * 2) if scalar is int else None


def _type_cast(scalar: Any, v: float) -> Any:
    return int(v) if scalar is int else float(v)


def _wrong_type_value(hint: Any) -> Any:
    base = _strip_optional(hint)
    return {str: 12, bool: "yes"}.get(base, "not-a-number" if base in (int, float) else {"x": 1})


def _strip_optional(hint: Any) -> Any:
    if get_origin(hint) in (typing.Union, types.UnionType):
        args = [a for a in get_args(hint) if a is not type(None)]
        if len(args) == 1:
            return args[0]
    return hint


def _type_name(hint: Any) -> str:
    origin = get_origin(hint)
    if origin is Literal:
        return " | ".join(repr(a) for a in get_args(hint))
    if origin in (typing.Union, types.UnionType):
        return " | ".join(_type_name(a) for a in get_args(hint))
    if origin is tuple:
        return f"list[{_type_name(get_args(hint)[0])}]"
    return "null" if hint is type(None) else getattr(hint, "__name__", str(hint))


def _describe(v: Any) -> str:
    text = repr(_thaw(v))
    return text if len(text) < 60 else text[:57] + "..."


def _coerce(v: Any, hint: Any, rules: Rules, owner: str, name: str) -> Any:
    """Check ``v`` against the type ``hint`` and ``rules``; return the frozen value."""
    origin = get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        return _coerce_union(v, hint, rules, owner, name)
    if origin is Literal:
        return _coerce_literal(v, hint, owner, name)
    if origin is tuple:
        return _coerce_list(v, hint, rules, owner, name)
    if hint is Any:
        return _freeze(v)
    return _coerce_scalar(v, hint, rules, owner, name)


def _must_be(owner: str, name: str, expect: str, given: Any, type_error: bool = True) -> ConfigError:
    """The error for a value ``given`` that is not ``expect``."""
    return ConfigError(owner, name, f"must be {expect}; got {_describe(given)}", type_error=type_error)


def _coerce_union(v: Any, hint: Any, rules: Rules, owner: str, name: str) -> Any:
    """``v`` as the first member type of ``hint`` that accepts it (None when the union allows it)."""
    args = get_args(hint)
    if v is None and type(None) in args:
        return None
    errors = []
    for a in (a for a in args if a is not type(None)):
        try:
            return _coerce(v, a, rules, owner, name)
        except ConfigError as e:
            errors.append(e)
    rule_errors = [e for e in errors if not e.type_error]
    if len(errors) == 1 or rule_errors:
        raise (rule_errors or errors)[0]  # the branch whose type matched explains best
    raise _must_be(owner, name, _type_name(hint), v)


def _coerce_literal(v: Any, hint: Any, owner: str, name: str) -> Any:
    """``v`` if it is one of the ``Literal``'s options (``True`` is not ``1`` here)."""
    options = get_args(hint)
    if v not in options or isinstance(v, bool) != any(isinstance(o, bool) for o in options):
        hint_text = did_you_mean(v, map(str, options)) if isinstance(v, str) else ""
        raise ConfigError(
            owner,
            name,
            f"must be one of {', '.join(map(repr, options))}; got {_describe(v)}{hint_text}",
            type_error=not isinstance(v, type(options[0])),
        )
    return v


def _coerce_list(v: Any, hint: Any, rules: Rules, owner: str, name: str) -> tuple[Any, ...]:
    """A list of the item type as a tuple: its length within ``min_len``/``max_len``, the other
    rules applied to every item."""
    item = get_args(hint)[0]
    if isinstance(v, (str, bytes)) or not isinstance(v, (list, tuple)):
        raise _must_be(owner, name, f"a list of {_type_name(item)}", v)
    if rules.min_len is not None and len(v) < rules.min_len:
        raise _must_be(owner, name, f"a list of at least {rules.min_len} items", v, type_error=False)
    if rules.max_len is not None and len(v) > rules.max_len:
        raise _must_be(owner, name, f"a list of at most {rules.max_len} items", v, type_error=False)
    item_rules = dataclasses.replace(rules, min_len=None, max_len=None)
    return tuple(_coerce(x, item, item_rules, owner, name) for x in v)


def _coerce_scalar(v: Any, hint: Any, rules: Rules, owner: str, name: str) -> Any:
    """A bool, an int, a finite float (ints accepted) or a str, within ``rules``."""
    given = v
    if hint is bool:
        if not isinstance(v, bool):
            raise _must_be(owner, name, "true or false", given)
        return v
    if hint is int:
        if isinstance(v, bool) or not isinstance(v, int):
            raise _must_be(owner, name, "an integer", given)
    elif hint is float:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise _must_be(owner, name, "a number", given)
        v = float(v)
        if not math.isfinite(v):
            raise _must_be(owner, name, "a finite number", given, type_error=False)
    elif hint is str:
        if not isinstance(v, str):
            raise _must_be(owner, name, "a string", given)
    else:
        raise TypeError(f"{owner}: field '{name}' has an unsupported type {hint!r}")
    broken = rules.violation(v)
    if broken:
        raise _must_be(owner, name, broken, given, type_error=False)
    return v


def _freeze(v: Any) -> Any:
    if isinstance(v, list):
        return tuple(_freeze(x) for x in v)
    return v


def _thaw(v: Any) -> Any:
    if isinstance(v, tuple):
        return [_thaw(x) for x in v]
    return v
