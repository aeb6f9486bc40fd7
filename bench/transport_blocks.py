"""Bench-only blocks for bench/transport.py: the source -> stage -> sink pipeline of the transport bench.

Graphs name them ``flowtact.bench.transport_blocks:BenchSource`` (and ``BenchStage``,
``BenchSink``), importable wherever flowtact is installed. They carry the same payloads and do the same
work as the raw pyzmq baseline and the peer pipelines (bench/peers/), so that the bench compares
transports, not blocks: 4 float64 per sample (``small``) or one 240x320 uint8 frame (``image``),
``y = 2 x`` or ``y = 255 - x``. They are not run by this file: it only defines them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from flowtact import Block, Chunk, Config, Example, Port, Source, StreamSpec, param

__all__ = ["PAYLOADS", "BenchSink", "BenchSource", "BenchStage"]

PAYLOADS: dict[str, tuple[str, tuple[int, ...]]] = {
    "small": ("float64", (4,)),
    "image": ("uint8", (240, 320)),
}
"""dtype and sample shape of each payload: 32 bytes or a 76.8 kB frame per sample."""


@dataclass(frozen=True)
class BenchSourceConfig(Config):
    payload: Literal["small", "image"] = param(
        "small", doc="small: 4 float64 per sample; image: 240x320 uint8"
    )
    rate_hz: float = param(
        1000.0, doc="samples per second (run with --tick 1/rate_hz for one sample per message)", gt=0
    )


class BenchSource(Source):
    """Emits the bench payload at ``rate_hz``: sample i holds i (small) or one fixed random frame (image).

    Ports
    -----
    y : float64 (4,) or uint8 (240, 320), units "1", at ``rate_hz``

    Notes
    -----
    The frame is drawn once from the block's seed at reset; every image sample is a read-only
    view of it (no per-sample allocation beyond the time stamps), like the baseline's source.
    """

    config_cls = BenchSourceConfig
    outputs = {"y": Port(dtype=None, doc="the payload: 4 float64 (small) or a 240x320 uint8 frame (image)")}

    def specs(self, inputs):  # noqa: ARG002 — a source: its outputs come from its config
        dtype, shape = PAYLOADS[self.config.payload]
        return {"y": StreamSpec(dtype=dtype, shape=shape, rate_hz=self.config.rate_hz)}

    def reset(self) -> None:
        self.i = 0
        dtype, shape = PAYLOADS[self.config.payload]
        self.frame = self.rng.integers(0, 256, shape, dtype=np.uint8) if dtype == "uint8" else None

    def step(self, now: float) -> dict[str, Chunk]:
        rate = self.config.rate_hz
        end = self.due(now, rate)
        k = np.arange(self.i, end, dtype=np.float64)  # sample indices, exact in float64
        self.i = max(self.i, end)
        if self.frame is None:
            data = np.repeat(k[:, None], 4, axis=1)
        else:
            data = np.broadcast_to(self.frame, (len(k), *self.frame.shape))
        return {"y": Chunk(k / rate, data)}

    @classmethod
    def example(cls) -> Example:
        return Example(params={"payload": "small", "rate_hz": 500.0}, duration_s=0.5)


class BenchStage(Block):
    """The stage's work: ``y = 2 x`` for float samples, ``y = 255 - x`` for uint8 frames (a new array).

    Ports
    -----
    x : float64 or uint8, any shape
    y : same dtype, shape, units and rate as ``x``
    """

    config_cls = Config
    chunking_invariant = True  # the --fast runtime may step it once over several ticks
    inputs = {"x": Port(dtype=None, doc="float samples or uint8 frames")}
    outputs = {"y": Port(dtype=None, doc="2 x (float) or 255 - x (uint8)")}

    def specs(self, inputs):
        return {"y": inputs["x"]}

    def step(self, x: Chunk) -> dict[str, Chunk]:  # type: ignore[override]
        y = 255 - x.data if x.data.dtype == np.uint8 else 2.0 * x.data
        return {"y": Chunk(x.t, y, x.end)}

    @classmethod
    def example(cls) -> Example:
        return Example(inputs={"x": np.arange(40.0).reshape(10, 4)})


class BenchSink(Block):
    """Consumes its input and counts samples (``samples`` counter); no outputs, so it is a sink.

    Ports
    -----
    x : any dtype and shape
    """

    config_cls = Config
    chunking_invariant = True  # the --fast runtime may step it once over several ticks
    sink = True
    inputs = {"x": Port(dtype=None, doc="anything")}
    outputs = {}

    def step(self, x: Chunk) -> dict[str, Chunk]:  # type: ignore[override]
        self.count("samples", len(x))
        return {}

    @classmethod
    def example(cls) -> Example:
        return Example(inputs={"x": np.ones((10, 4))})
