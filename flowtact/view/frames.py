"""One frame of the page: the data each stream gathered since the last frame, cut to what a plot
can show (at most :data:`MAX_POINTS` points per channel, :data:`MAX_EVENTS` spikes, one image of
at most :data:`MAX_SIDE` pixels a side), as JSON-ready values (non-finite values become null).
"""

from __future__ import annotations

import base64
import math
from collections import deque
from collections.abc import Mapping
from typing import Any

import numpy as np

from flowtact.chunk import StreamSpec
from flowtact.view.buffers import Pending
from flowtact.view.kinds import describe, is_pulses, view_kind

__all__ = ["MAX_CHANNELS", "MAX_EVENTS", "MAX_POINTS", "MAX_RATE_BARS", "MAX_SIDE", "FrameMaker"]

MAX_POINTS = 50
"""Points per channel in one frame: at 20 frames a second a 1 kHz stream is drawn whole, a faster one
decimated to 1000 points a second (10 000 over the page's 10 s window: more than a plot's width)."""
MAX_CHANNELS = 16
"""Channels of one stream drawn as lines; the rest are left out (the page says how many)."""
MAX_EVENTS = 2000
"""Spikes of one stream in one frame (the newest); rates count all of them."""
MAX_SIDE = 128
"""Pixels on the longer side of one image tile (taken every k-th pixel)."""
MAX_RATE_BARS = 64
"""Rate bars of a raster: one per unit, or per group of neighbouring units beyond this many."""
RATE_WINDOW_S = 1.0
"""Graph seconds the rates of a raster are counted over."""


def _decimate(n: int, most: int) -> np.ndarray | slice:
    """Indices of at most ``most`` of ``n`` samples, evenly spaced, the newest kept."""
    if n <= most:
        return slice(None)
    return np.unique(np.linspace(n - 1, 0, most).round().astype(np.int64))


def _values(a: np.ndarray) -> list[Any]:
    """A float array as a JSON-ready list: NaN and infinities become None (JSON has neither)."""
    a = np.asarray(a, np.float64)
    finite = np.isfinite(a)
    if finite.all():
        return a.tolist()
    return [v if ok else None for v, ok in zip(a.tolist(), finite.tolist(), strict=True)]


class _Rates:
    """Spike counts per unit over the last :data:`RATE_WINDOW_S` of graph time, as rates (Hz)."""

    def __init__(self, n_units: int) -> None:
        self.n_units = max(1, n_units)
        self.group = max(1, math.ceil(self.n_units / MAX_RATE_BARS))
        self.frames: deque[tuple[float, np.ndarray]] = deque()
        self.total = np.zeros(self.n_units, np.int64)
        self.start = 0.0  # graph time 0: where counting begins

    def add(self, units: np.ndarray, end: float) -> list[float]:
        """Count this frame's spikes (of units, up to graph time ``end``); the rate per bar (Hz)."""
        ok = (units >= 0) & (units < self.n_units)
        counts = np.bincount(units[ok], minlength=self.n_units)
        self.frames.append((end, counts))
        self.total += counts
        while len(self.frames) > 1 and end - self.frames[0][0] >= RATE_WINDOW_S - 1e-9:
            t0, old = self.frames.popleft()
            self.total -= old
            self.start = t0
        span = max(end - self.start, 1e-9)
        pad = (-self.n_units) % self.group
        grouped = np.concatenate([self.total, np.zeros(pad, np.int64)]).reshape(-1, self.group)
        sizes = np.full(len(grouped), self.group, np.float64)
        sizes[-1] -= pad  # the last group may hold fewer units
        per_unit = grouped.sum(axis=1) / sizes
        return _values(per_unit / span)


class FrameMaker:
    """Turns the buffers' pending data into one JSON-ready frame a time (kept state: rates)."""

    def __init__(self, specs: Mapping[str, StreamSpec]) -> None:
        self.specs = dict(specs)
        self.rates = {
            n: _Rates(s.n_units if s.n_units is not None else 1)
            for n, s in self.specs.items()
            if view_kind(s) == "raster"
        }
        self.seq = 0
        self.now = -math.inf

    def meta(self, graph: str) -> dict[str, Any]:
        """What the page needs once: the graph's name and how to draw each stream."""
        streams = [describe(n, s, MAX_CHANNELS) for n, s in self.specs.items()]
        for d in streams:
            if d["kind"] == "raster":
                d["rate_group"] = self.rates[d["name"]].group
        return {"type": "meta", "graph": graph, "streams": streams}

    def frame(self, pending: Mapping[str, Pending]) -> dict[str, Any] | None:
        """The next frame, or None when no stream brought anything new."""
        if not pending:
            return None
        out: dict[str, Any] = {}
        for name, p in pending.items():
            if len(p.t):
                self.now = max(self.now, float(p.t[-1]))
            if p.end is not None:
                self.now = max(self.now, p.end)
            out[name] = self._stream(name, p)
        self.seq += 1
        return {"type": "frame", "seq": self.seq, "now": self.now, "streams": out}

    def _stream(self, name: str, p: Pending) -> dict[str, Any]:
        spec = self.specs[name]
        kind = view_kind(spec)
        if kind == "raster":
            return self._raster(name, spec, p)
        if kind == "image":
            return self._image(p)
        n = len(p.t)
        pick = _decimate(n, MAX_POINTS)
        t = p.t[pick]
        flat = p.data.reshape(n, spec.size)[pick]
        out: dict[str, Any] = {"t": _values(t), "dropped": p.dropped}
        if kind == "categorical":
            cats = spec.categories or ()
            out["y"] = [_values(flat[:, 0])]
            if n:
                last = p.data.reshape(n, spec.size)[-1, 0]
                i = int(last) if np.isfinite(last) else -1
                out["current"] = cats[i] if 0 <= i < len(cats) else f"{last:g}"
        else:
            out["y"] = [_values(flat[:, c]) for c in range(min(flat.shape[1], MAX_CHANNELS))]
        return out

    def _raster(self, name: str, spec: StreamSpec, p: Pending) -> dict[str, Any]:
        units = p.data[:, 0] if is_pulses(spec) else p.data.reshape(len(p.t), spec.size)[:, 0]
        units = np.asarray(units).astype(np.int64, copy=False)
        end = p.end if p.end is not None else (float(p.t[-1]) if len(p.t) else self.now)
        rates = self.rates[name].add(units, end)
        keep = slice(-MAX_EVENTS, None)
        return {
            "t": _values(p.t[keep]),
            "u": units[keep].tolist(),
            "count": len(p.t),
            "rates": rates,
            "end": end,
            "dropped": p.dropped,
        }

    def _image(self, p: Pending) -> dict[str, Any]:
        if not len(p.t):
            return {"empty": True}
        img = np.asarray(p.data[-1])
        if img.ndim == 2:
            tiles, rgb = img[None], False
        elif img.ndim == 3 and img.shape[-1] in (3, 4) and img.shape[0] > 4:
            tiles, rgb = img[None, ..., :3], True
        else:
            tiles, rgb = img.reshape(-1, *img.shape[-2:]), False
        step = max(1, math.ceil(max(tiles.shape[1], tiles.shape[2]) / MAX_SIDE))
        tiles = tiles[:, ::step, ::step]
        finite = np.isfinite(tiles) if tiles.dtype.kind == "f" else None
        lo = float(tiles[finite].min()) if finite is not None and finite.any() else float(tiles.min())
        hi = float(tiles[finite].max()) if finite is not None and finite.any() else float(tiles.max())
        if tiles.dtype == np.uint8:
            pixels = tiles
        else:
            scaled = (np.nan_to_num(tiles.astype(np.float64), nan=lo) - lo) / ((hi - lo) or 1.0)
            pixels = np.clip(scaled * 255.0, 0, 255).astype(np.uint8)
        return {
            "t": float(p.t[-1]),
            "tiles": int(pixels.shape[0]),
            "h": int(pixels.shape[1]),
            "w": int(pixels.shape[2]),
            "rgb": rgb,
            "min": lo if math.isfinite(lo) else None,
            "max": hi if math.isfinite(hi) else None,
            "pixels": base64.b64encode(np.ascontiguousarray(pixels).tobytes()).decode("ascii"),
        }
