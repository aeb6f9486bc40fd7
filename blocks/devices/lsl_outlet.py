"""``lsl_outlet``: any graph stream published on the Lab Streaming Layer, stamped in LSL time."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

import flowtact.api as ft
from flowtact.blocks.devices.lsl_clock import anchor

__all__ = ["LslOutlet", "LslOutletConfig"]

#: dtype of the graph stream -> LSL channel format (anything else is sent as double64).
CHANNEL_FORMATS = {
    "float32": "float32",
    "float64": "double64",
    "int8": "int8",
    "int16": "int16",
    "int32": "int32",
    "int64": "int64",
}


@dataclass(frozen=True)
class LslOutletConfig(ft.BadDataConfig):
    name: str = ft.param("", doc="the stream's LSL name ('': the node's name)")
    type: str = ft.param(
        "", doc="the stream's content type ('': Markers for categorical, Spikes for events, else Signal)"
    )
    source_id: str = ft.param("", doc="the stream's source id ('': flowtact/<node>)")
    wait_for_consumers_s: float = ft.param(
        0.0,
        ge=0,
        le=600,
        doc="at start, wait this long for an inlet to connect (samples sent before one connects are "
        "not delivered: LSL keeps no history for later subscribers); 0: do not wait",
    )
    buffer_s: int = ft.param(360, gt=0, le=3600, doc="seconds of samples liblsl keeps for a slow consumer")


class LslOutlet(ft.Block):
    """Publish the stream it is fed as an LSL stream: samples, events (spikes) or categories.

    Config
    ------
    See the field docs (``flowtact blocks lsl_outlet``). Docs: ``docs/lsl.md``.

    Notes
    -----
    What is sent. A sampled stream: one LSL channel per value of a sample (C order), its nominal
    rate, format from the dtype (float32, double64, int8..int64; others as double64), channel
    labels and units in ``desc/channels``. An event stream (spikes): an irregular-rate stream of one
    int32 channel, the unit index, one LSL sample per event at the event's time (rows carrying
    more than the unit: their first column). A categorical stream: an irregular-rate string stream
    (``Markers``), one LSL sample per graph sample: the category's name. The stream's
    ``desc/flowtact`` names the kind, the unit count and the categories.

    Time. Each sample leaves stamped with its graph time plus the run's anchor (graph time 0 on the
    LSL clock, shared by this process's LSL blocks; :mod:`flowtact.blocks.devices.lsl_clock`): a
    sample an ``lsl_inlet`` of the same process read keeps its LSL stamp exactly once the anchor has
    settled (it comes down to the least lateness seen over the steps). An outlet in a process
    without an inlet measures the anchor at each chunk's first sample (it is not told ``now``), so
    its stamps are late by the least such sample's way through the graph.

    I/O. ``open`` creates the outlet (and optionally waits for a consumer), ``step`` pushes without
    blocking, ``close`` withdraws the stream. NaN/inf samples follow ``on_bad_data`` (float streams).

    Example
    -------
    >>> from flowtact.blocks.devices.lsl_outlet import LslOutlet
    >>> LslOutlet(name="spikes").config.name
    'spikes'
    """

    config_cls = LslOutletConfig
    requires = {"pylsl": "lsl"}
    sink = True  # it publishes: it runs even when nothing in the graph consumes it
    inputs = {
        "x": ft.Port(
            dtype=None,
            units=None,
            optional=True,
            doc="a sampled stream (any shape and numeric dtype) or a categorical one; connect x or events",
        ),
        "events": ft.Port(
            dtype=None,
            units=None,
            events=True,
            optional=True,
            doc="an event stream (spikes: the unit index per event); connect x or events",
        ),
    }
    outputs = {}
    counter_docs = {
        **ft.nonfinite_counter_docs("samples"),
        "sent": "samples (or events) pushed to LSL",
    }

    def __init__(self, *args: Any, **kw: Any) -> None:
        super().__init__(*args, **kw)
        self._outlet: Any = None
        self._holding = False

    @classmethod
    def example(cls) -> ft.Example:
        t = np.arange(100) / 100.0
        return ft.Example(
            params={"name": "flowtact_example"}, inputs={"x": np.sin(t)[:, None]}, rate_hz=100.0
        )

    def specs(self, inputs: dict[str, ft.StreamSpec]) -> dict[str, ft.StreamSpec]:
        if len(inputs) != 1:
            raise ft.SpecError(None, "connect exactly one of x (samples, categories) or events (spikes)")
        return {}

    def reset(self) -> None:
        self._port = next(iter(self.input_specs))
        self._last_good: np.ndarray | None = None

    # -- lifecycle ------------------------------------------------------------------------------
    def _info(self) -> Any:
        """The pylsl StreamInfo describing the input stream."""
        import pylsl

        c, spec = self.config, self.input_specs[self._port]
        if spec.categories is not None:
            kind, n, fmt, rate, default = "categorical", 1, "string", 0.0, "Markers"
        elif spec.events:
            kind, n, fmt, rate, default = "events", 1, "int32", 0.0, "Spikes"
        else:
            fmt = CHANNEL_FORMATS.get(spec.dtype, "double64")
            kind, n, rate, default = "samples", spec.size, spec.rate_hz or 0.0, "Signal"
        info = pylsl.StreamInfo(
            c.name or self.node, c.type or default, n, rate, fmt, c.source_id or f"flowtact/{self.node}"
        )
        desc = info.desc()
        meta = desc.append_child("flowtact")
        meta.append_child_value("kind", kind)
        if spec.events and spec.n_units is not None:
            meta.append_child_value("n_units", str(spec.n_units))
        if spec.categories is not None:
            cats = meta.append_child("categories")
            for name in spec.categories:
                cats.append_child_value("category", name)
        channels = desc.append_child("channels")
        labels = spec.labels if spec.labels and len(spec.labels) == n else None
        for i in range(n):
            ch = channels.append_child("channel")
            ch.append_child_value(
                "label", labels[i] if labels else ("unit" if kind == "events" else f"ch{i + 1}")
            )
            ch.append_child_value("unit", spec.units if kind == "samples" else "")
        return info

    def open(self) -> None:
        import pylsl

        self._outlet = pylsl.StreamOutlet(self._info(), 0, self.config.buffer_s)
        anchor.acquire()
        self._holding = True
        wait = self.config.wait_for_consumers_s
        if wait and not self._outlet.wait_for_consumers(wait):
            raise RuntimeError(
                f"{self.node} (lsl_outlet): no LSL inlet connected to stream "
                f"'{self.config.name or self.node}' within {wait:g} s (wait_for_consumers_s)"
            )

    def close(self) -> None:
        self._outlet = None  # pylsl withdraws the stream when the outlet is freed
        if self._holding:
            anchor.release()
            self._holding = False

    # -- the step -------------------------------------------------------------------------------
    def step(self, **inputs: ft.Chunk) -> dict[str, ft.Chunk]:
        spec = self.input_specs[self._port]
        x = inputs[self._port]
        if not spec.events and spec.categories is None:
            x, self._last_good = ft.screen_nonfinite(self, x, self.config.on_bad_data, "x", self._last_good)
        if not len(x) or self._outlet is None:  # offline (no open): a check of the input only
            return {}
        a = anchor.at(float(x.t[0]))
        stamps = x.t + a
        if spec.categories is not None:
            names = spec.categories
            rows: Any = [[names[int(v)] if 0 <= int(v) < len(names) else str(int(v))] for v in x.data.ravel()]
        elif spec.events:
            d = x.data.reshape(len(x), -1)[:, 0] if x.data.ndim > 1 else x.data
            rows = d.astype(np.int32).reshape(-1, 1)
        else:
            fmt = CHANNEL_FORMATS.get(spec.dtype)
            rows = x.data.reshape(len(x), -1)
            rows = np.ascontiguousarray(rows if fmt else rows.astype(np.float64))
        for i in range(len(x)):  # one push per sample: each keeps its own stamp
            self._outlet.push_sample(rows[i], float(stamps[i]), i == len(x) - 1)
        self.count("sent", len(x))
        return {}

    def summary(self) -> str | None:
        if self._outlet is None and not self.counters.get("sent"):
            return None
        return f"LSL '{self.config.name or self.node}': {self.counters.get('sent', 0)} sent"
