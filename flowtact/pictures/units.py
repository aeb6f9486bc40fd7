"""Unit strings as a reader expects them on a plot (``us`` -> ``µs``), and units carried by labels.

Ports spell units in ASCII (``us``, ``uA``) so that they compare exactly; figures print them with
their proper symbols. A channel label may end in a unit suffix (``deviation_us``,
``amplitude_ua``, ``engage_1``) when that channel's unit is not the stream's own.
"""

from __future__ import annotations

import re

__all__ = ["DIMENSIONLESS", "label_unit", "pretty_units"]

#: Axis text for a dimensionless quantity (units "1" or "").
DIMENSIONLESS = "dimensionless"

_SUFFIX_UNITS = {
    "us": "us",
    "ms": "ms",
    "s": "s",
    "ua": "uA",
    "ma": "mA",
    "n": "N",
    "mn": "mN",
    "mm": "mm",
    "um": "um",
    "rad": "rad",
    "deg": "deg",
    "hz": "Hz",
    "v": "V",
    "mv": "mV",
    "1": "1",
}
_SUFFIX = re.compile(r"^(?P<name>.+?)_(?P<unit>" + "|".join(_SUFFIX_UNITS) + r")$", re.IGNORECASE)


def pretty_units(units: str | None) -> str:
    """``us`` -> ``µs``, ``uA`` -> ``µA``, ``um`` -> ``µm``, ``deg`` -> ``°``; ``1``/empty -> dimensionless."""
    if units is None or units.strip() in ("", "1"):
        return DIMENSIONLESS
    out = []
    for part in re.split(r"([/*· ^()])", units):
        if len(part) >= 2 and part[0] == "u" and part[1:] in ("s", "A", "m", "V", "N", "W"):
            part = "µ" + part[1:]
        elif part == "deg":
            part = "°"
        elif part == "ohm":
            part = "Ω"
        out.append(part)
    return "".join(out)


def label_unit(label: str) -> tuple[str, str | None]:
    """A channel label without its unit suffix, and that unit (None: the stream's own units)."""
    m = _SUFFIX.match(label)
    if m is None:
        return label, None
    return m.group("name"), _SUFFIX_UNITS[m.group("unit").lower()]
