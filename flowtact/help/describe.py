"""``flowtact blocks NAME``: a block's docs as readable terminal text, with the presets that apply to it.

The docstring's reStructuredText is rendered by :mod:`flowtact.help.rst_text`; ports, parameters (type,
default, rules, doc) and counters come from the class; every preset published for the block
(``flowtact.presets`` entry points) is listed with each value and the units its field name carries.
"""

from __future__ import annotations

import inspect
import re
import shutil
from collections.abc import Mapping, Sequence
from typing import Any

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
    if isinstance(v, Sequence):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    return repr(v)


def _port_text(port: Any) -> str:
    if port.events:
        return "events"
    shape = "any shape" if port.shape is None else f"shape {tuple(port.shape)}"
    units = f", {port.units}" if port.units else ""
    extra = ", optional" if port.optional else ""
    extra += ", delayed" if port.delay else ""
    return f"{port.dtype or 'any'} {shape}{units}{extra}"


def _wrapped(text: str, indent: int, width: int) -> list[str]:
    return rst_to_text(inline_text(text), width - indent).splitlines()


def describe_block(cls: Any, width: int | None = None) -> str:
    """The block's docstring, ports, parameters, presets and counters as plain text of ``width`` columns
    (default: the terminal's, at most 100)."""
    width = width or min(shutil.get_terminal_size((100, 24)).columns, 100)
    lines = [f"{cls.name}  ({cls.__module__}.{cls.__name__})", ""]
    lines.append(rst_to_text(inspect.cleandoc(cls.__doc__ or ""), width))
    for title, ports in (("Inputs", cls.inputs), ("Outputs", cls.outputs)):
        lines += ["", f"{title}:"]
        for name, port in ports.items():
            lines.append(f"  {name:<12} {_port_text(port)}")
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
