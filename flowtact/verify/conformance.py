"""What lets the conformance suite (``flowtact.testing.CHECKS``) say what it expected and what happened.

:func:`example_of` reads a block's ``example`` in any natural form (classmethod, staticmethod, an
:class:`~flowtact.block.Example` attribute) or says exactly what to write; :func:`first_difference`
names the first sample where two runs' outputs part; :class:`ConformanceError` is the one failure.
"""

from __future__ import annotations

import inspect
from collections.abc import Mapping
from typing import Any

import numpy as np

from flowtact.block import Block, Example, Source
from flowtact.chunk import Chunk
from flowtact.errors import ConformanceError

__all__ = ["differing_rows", "example_of", "first_difference", "value_text"]

EXAMPLE_TEMPLATE = """\
    @classmethod
    def example(cls) -> Example:  # from flowtact import Example
        return Example(params={...}, inputs={"PORT": np.array(...)}, units={"PORT": "UNITS"})"""


def example_of(cls: type[Block]) -> Example:
    """``cls``'s example, whether declared as a classmethod, a staticmethod or an ``Example`` attribute.

    Raises :class:`ConformanceError` saying what to write when there is none, when it is a plain
    method (it would need an instance, which needs the example's params), or when it does not give
    an :class:`~flowtact.block.Example` whose params and inputs fit the block.
    """
    raw = inspect.getattr_static(cls, "example", None)
    owner = next((k for k in cls.__mro__ if "example" in k.__dict__), None)
    fix = f"write it as\n{EXAMPLE_TEMPLATE}"
    if raw is None or owner is Block or owner is Source:
        raise ConformanceError(
            cls.name, "example", f"{cls.__name__} to provide example()", f"it has none; {fix}"
        )
    if isinstance(raw, Example):
        ex = raw
    elif isinstance(raw, (classmethod, staticmethod)):
        ex = cls.example()
    elif inspect.isfunction(raw):
        raise ConformanceError(
            cls.name,
            "example",
            "example to be a classmethod (the suite builds the block from the example's params)",
            f"{cls.__name__}.example is a plain method taking self; {fix}",
        )
    else:
        raise ConformanceError(
            cls.name,
            "example",
            "example to be a classmethod returning flowtact.Example",
            f"{cls.__name__}.example is a {type(raw).__name__}; {fix}",
        )
    if not isinstance(ex, Example):
        raise ConformanceError(
            cls.name,
            "example",
            "example() to return a flowtact.Example",
            f"it returned {type(ex).__name__}: {ex!r:.120}; {fix}",
        )
    _check_example(cls, ex)
    return ex


def _check_example(cls: type[Block], ex: Example) -> None:
    known = {f.name for f in cls.config_cls.fields_info()} | {"preset"}
    unknown = sorted(set(ex.params) - known)
    if unknown:
        raise ConformanceError(
            cls.name,
            "example",
            f"example params among the config's fields ({', '.join(sorted(known - {'preset'}))})",
            f"it sets {', '.join(repr(k) for k in unknown)}",
        )
    try:
        cls.configure(ex.params)
    except Exception as e:  # the example's own params must build the block
        raise ConformanceError(
            cls.name, "example", "example params the block accepts", f"{type(e).__name__}: {e}"
        ) from e
    stray = sorted(set(ex.inputs) - set(cls.inputs))
    if stray:
        raise ConformanceError(
            cls.name,
            "example",
            f"example inputs named after input ports ({', '.join(cls.inputs) or 'none'})",
            f"it feeds {', '.join(repr(k) for k in stray)}",
        )
    missing = [p for p, port in cls.inputs.items() if not port.optional and p not in ex.inputs]
    if missing and not issubclass(cls, Source):
        raise ConformanceError(
            cls.name,
            "example",
            "example inputs for every required input port",
            f"it gives none for {', '.join(repr(p) for p in missing)}",
        )


def value_text(v: Any) -> str:
    """A sample value as a reader wants to see it: ``0.25``, ``3``, ``[0.1, 0.2]`` (shortened)."""
    a = np.asarray(v)
    if a.ndim == 0:
        return repr(a.item())
    text = np.array2string(a, threshold=8, max_line_width=10_000, separator=", ")
    return text if len(text) <= 80 else text[:77] + "..."


def first_difference(
    expected: Mapping[str, Chunk], got: Mapping[str, Chunk], when: str, ref: str
) -> str | None:
    """Where ``got`` (a run ``when`` …) first differs from ``expected`` (the ``ref`` run), or None.

    E.g. ``"output 'y' differs at sample 812 when fed in chunks of 7: expected 0.25 (whole), got 0.0"``.
    Outputs compare bit for bit, NaN equal to NaN.
    """
    if expected.keys() != got.keys():
        return f"outputs {sorted(got)} {when}, expected {sorted(expected)} ({ref})"
    for port in expected:
        e, g = expected[port], got[port]
        for field, what in (("data", "differs"), ("t", "has a different time stamp")):
            x, y = getattr(e, field), getattr(g, field)
            if x.dtype != y.dtype:
                return f"output '{port}'.{field} is {y.dtype} {when}, expected {x.dtype} ({ref})"
            if x.shape[1:] != y.shape[1:]:
                return (
                    f"output '{port}' samples have shape {y.shape[1:]} {when}, expected {x.shape[1:]} ({ref})"
                )
            n = min(len(x), len(y))
            rows = differing_rows(x[:n], y[:n])
            if rows.size:
                i = int(rows[0])
                at = f" (t={float(e.t[i]):.6g} s)" if field == "data" and i < len(e.t) else ""
                return (
                    f"output '{port}' {what} at sample {i}{at} {when}: expected {value_text(x[i])} ({ref}), "
                    f"got {value_text(y[i])}"
                )
            if len(x) != len(y):
                return f"output '{port}' has {len(y)} samples {when}, expected {len(x)} ({ref}); the first {n} agree"
    return None


def differing_rows(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Indices of the samples (rows) where two equally long arrays differ, NaN equal to NaN."""
    same = ((x == y) | (np.isnan(x) & np.isnan(y))) if x.dtype.kind in "fc" else (x == y)
    return np.flatnonzero(~same.reshape(len(x), -1).all(axis=1)) if len(x) else np.empty(0, np.intp)
