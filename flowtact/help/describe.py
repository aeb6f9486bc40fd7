"""``flowtact blocks NAME``: a block's docs as readable terminal text, with the presets that apply to it.

The docstring's reStructuredText is rendered by :mod:`flowtact.help.rst_text`; ports (from their
declarations: dtype, shape, units, rate, labels, doc — no docstring repeats them), parameters (type,
default, rules, doc) and counters come from the class; every preset published for the block
(``flowtact.presets`` entry points) is listed with each value and the units its field name carries.
"""

from __future__ import annotations

import inspect
import re
import shutil
from collections.abc import Mapping, Sequence
from typing import Any

from flowtact.block import Block
from flowtact.catalog.presets import presets_for
from flowtact.help.rst_text import inline_text, rst_to_text

__all__ = ["describe_block", "units_of"]

_UNIT_WORDS = {
    "s": "s",
    "ms": "ms",
    "us": "µs",
    "hz": "Hz",
    "n": "N",
    "mm": "mm",
    "um": "µm",
    "m": "m",
    "deg": "°",
    "rad": "rad",
    "c": "°C",
    "dn": "DN",
    "px": "px",
    "px2": "px²",
    "ua": "µA",
    "nc": "nC",
    "adc": "ADC counts",
    "ppm": "ppm",
}


def units_of(field: str) -> str:
    """The units a parameter's name carries (``tau_s`` → ``s``, ``gain_us_per_n`` → ``µs/N``), or ""."""
    num, _, den = field.partition("_per_")
    tokens = num.split("_")[1:]  # the first word names the quantity, never a unit
    units = []
    for tok in reversed(tokens):
        if tok not in _UNIT_WORDS:
            break
        units.insert(0, _UNIT_WORDS[tok])
        if len(units) == 2:
            break
    top = "·".join(units)
    if not den:
        return top
    bottom = _UNIT_WORDS.get(den.split("_")[-1], "")
    if not bottom:
        return top
    return f"{top or '1'}/{bottom}"


def _value(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:g}"
    if isinstance(v, str):
        return repr(v)
    if isinstance(v, Sequence) and len(v) > 12:  # a per-unit list of a large population: its ends
        return f"[{_value(v[0])}, {_value(v[1])}, … {_value(v[-1])}] ({len(v)} values)"
    if isinstance(v, Sequence):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    return repr(v)


def _names_text(what: str, v: Any) -> str:
    """``, labels a, b, c`` (a long list shortened: its first and last names, and how many)."""
    if isinstance(v, str):
        return f", {what} from {v}"
    if not v:
        return ""
    text = ", ".join(v) if len(v) <= 8 else f"{', '.join(v[:3])} … {v[-1]} ({len(v)})"
    return f", {what} {text}"


def _port_text(port: Any, output: bool, derived: bool, inputs: Any = ()) -> str:
    """One line from a port's declaration: what flows (dtype, shape, units), at what rate, named how."""
    shape = (
        "any shape"
        if port.shape is None
        else "shape (" + ", ".join(map(str, port.shape)) + ("," if len(port.shape) == 1 else "") + ")"
    )
    if port.shape is None and port.ndim is not None:
        dims = (port.ndim,) if isinstance(port.ndim, int) else port.ndim  # one rank, or the ranks allowed
        shape = "shape " + " or ".join({0: "()", 1: "(C,)"}.get(n, f"{n}-d") for n in dims)
    parts = [f"{port.dtype or 'any dtype'} {shape}"]
    if port.units:
        parts.append(f"units {port.units}")
    if port.events:
        parts[0] = f"events, {parts[0]}"
        if port.n_units is not None:
            parts.append(f"n_units {port.n_units}")
    elif port.rate in inputs:
        parts.append(f"at the rate of {port.rate}")
    elif port.rate is not None:
        parts.append(f"at {port.rate} (a parameter)")
    elif output and derived:
        parts.append("at its input's rate")
    elif port.require_rate:
        parts.append("with a nominal rate")
    if port.same_rate:
        parts.append(f"same rate as {port.same_rate}")
    text = ", ".join(parts)
    if port.labels is not None:
        text += _names_text("labels", port.labels)
    if port.categories is not None:
        text += _names_text("categories", port.categories)
    text += ", optional" if port.optional else ""
    text += ", delayed" if port.delay else ""
    return text


def _wrapped(text: str, indent: int, width: int) -> list[str]:
    return rst_to_text(inline_text(text), width - indent).splitlines()


def describe_block(cls: Any, width: int | None = None) -> str:
    """The block's docstring, ports, parameters, presets and counters as plain text of ``width`` columns
    (default: the terminal's, at most 100)."""
    width = width or min(shutil.get_terminal_size((100, 24)).columns, 100)
    lines = [f"{cls.name}  ({cls.__module__}.{cls.__name__})", ""]
    lines.append(rst_to_text(inspect.cleandoc(cls.__doc__ or ""), width))
    derived = cls.specs is Block.specs or not cls.inputs  # the declarations alone give the outputs
    for title, ports in (("Inputs", cls.inputs), ("Outputs", cls.outputs)):
        lines += ["", f"{title}:"]
        for name, port in ports.items():
            lines.append(f"  {name:<12} {_port_text(port, title == 'Outputs', derived, cls.inputs)}")
            lines += ["      " + s for s in _wrapped(port.doc, 6, width)]
        if not ports:
            lines.append("  (none: a source)" if title == "Inputs" else "  (none)")
    lines += ["", "Parameters:"]
    for f in cls.config_cls.fields_info():
        rules = f"  [{f.rules}]" if f.rules else ""
        units = units_of(f.name)
        lines.append(
            f"  {f.name:<16} {f.type:<22} default {f.default!r}{rules}" + (f"  ({units})" if units else "")
        )
        lines += ["      " + s for s in _wrapped(f.doc, 6, width)]
    lines += _presets(cls)
    counters = cls.documented_counters()
    if counters:
        lines += ["", "Counters:"]
        for name, doc in counters.items():
            lines.append(f"  {name}")
            lines += ["      " + s for s in _wrapped(doc, 6, width)]
    return "\n".join(re.sub(r"\s+$", "", line) for line in "\n".join(lines).splitlines())


def _presets(cls: Any) -> list[str]:
    presets: Mapping[str, Mapping[str, Any]] = presets_for(cls.name)
    if not presets:
        return []
    lines = ["", "Presets (in a graph: preset: NAME; parameters given beside it override the preset's):"]
    for name, params in sorted(presets.items()):
        lines.append(f"  {name}")
        for key, v in params.items():
            units = units_of(key)
            lines.append(f"    {key:<16} {_value(v)}" + (f" {units}" if units else ""))
    return lines
