"""How a stream is drawn, from its :class:`~flowtact.chunk.StreamSpec` alone.

lines (samples, a channel per value, labelled, with units), raster (events: spikes or pulses, by
unit), image (2-D or 3-D samples without a name per value), categorical (samples naming a category).
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np

from flowtact.chunk import StreamSpec

__all__ = ["Kind", "describe", "view_kind"]

Kind = Literal["lines", "raster", "image", "categorical"]


def view_kind(spec: StreamSpec) -> Kind:
    """What the page draws for a stream of ``spec``."""
    if spec.events:
        return "raster"
    if spec.categories is not None:
        return "categorical"
    named = spec.labels is not None and len(spec.labels) == spec.size
    if len(spec.shape) >= 2 and not named:
        return "image"
    return "lines"


def is_pulses(spec: StreamSpec) -> bool:
    """Events whose rows start with the unit (stimulation pulses), as recordings call them."""
    return spec.events and len(spec.shape) == 1 and bool(spec.labels) and spec.labels[0] == "unit"  # type: ignore[index]


def describe(name: str, spec: StreamSpec, max_channels: int) -> dict[str, Any]:
    """The page's description of one stream (sent once, when a browser connects)."""
    kind = view_kind(spec)
    out: dict[str, Any] = {
        "name": name,
        "kind": kind,
        "units": spec.units,
        "rate_hz": spec.rate_hz,
        "shape": list(spec.shape),
        "dtype": np.dtype(spec.dtype).name,
    }
    if kind == "lines":
        n = spec.size
        labels = list(spec.labels) if spec.labels is not None and len(spec.labels) == n else None
        out["labels"] = (labels or [f"ch{i}" if n > 1 else name for i in range(n)])[:max_channels]
        out["channels"] = n
    elif kind == "raster":
        out["n_units"] = spec.n_units if spec.n_units is not None else 1
    elif kind == "categorical":
        out["categories"] = list(spec.categories or ())
    return out
