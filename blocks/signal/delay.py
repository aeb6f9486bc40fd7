"""A one-tick delay: the port through which a feedback loop closes."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from flowtact import (
    Block,
    Chunk,
    Config,
    Example,
    Port,
    StreamSpec,
    param,
)
from flowtact.inputs.limits import MAX_TICK_S

__all__ = ["Delay", "DelayConfig"]


@dataclass(frozen=True)
class DelayConfig(Config):
    """What the fed-back stream carries: in a loop the compiler needs it before the loop is resolved."""

    dtype: str = param("float64", doc="dtype of the fed-back stream")
    shape: tuple[int, ...] = param((), doc="sample shape of the fed-back stream", ge=1)
    units: str = param("1", doc="units of the fed-back stream")
    rate_hz: float | None = param(None, doc="rate of the fed-back stream (None: an event stream)", gt=0)

    def state_bytes(self) -> dict[str, float]:
        """One tick of the fed-back stream: its sample size × the samples of a longest tick."""
        try:
            itemsize = np.dtype(self.dtype).itemsize
        except TypeError:
            itemsize = 8  # not a dtype: the block's own check says so
        samples = (self.rate_hz or 1.0) * MAX_TICK_S
        return {"shape": float(np.prod(self.shape, dtype=float)) * itemsize * samples}


class Delay(Block):
    """One-tick delay: passes its input through unchanged so a graph can close a feedback loop.

    Ports
    -----
    x : any dtype and shape (declared ``delay=True``: it receives data one executor tick late)
    y : the same samples with the same timestamps, dtype, shape, units and rate as ``x``

    Config
    ------
    dtype, shape, units, rate_hz: what the fed-back stream carries. Inside a loop the compiler
    resolves this block before the stream that feeds it, so it takes the output spec from these
    parameters, then checks that the stream that arrives matches them. Outside a loop they are
    not needed (the input's spec is passed on).

    Notes
    -----
    The compiler accepts a cycle only if it passes through a delay port; this block is the
    standard way to put one in a loop (e.g. a controller's command fed back to a planner). The
    delay is the executor's: the block itself adds no latency, holds no state and never alters
    data (no bad-data policy: it computes nothing; the consumer's policy applies).

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.signal.delay import Delay
    >>> from flowtact.testing import run_offline
    >>> run_offline(Delay(), x=np.arange(3.0))["y"].data.tolist()
    [0.0, 1.0, 2.0]
    """

    config_cls = DelayConfig
    inputs = {"x": Port(dtype=None, delay=True, doc="samples to pass on (one tick late)")}
    outputs = {"y": Port(dtype=None, doc="the same samples, unchanged")}

    def specs(self, inputs: Mapping[str, StreamSpec]) -> dict[str, StreamSpec]:
        if "x" in inputs:
            return {"y": inputs["x"]}
        c = self.config  # inside a loop: the fed-back stream is not resolved yet
        return {
            "y": StreamSpec(
                dtype=c.dtype,
                shape=tuple(c.shape),
                units=c.units,
                rate_hz=c.rate_hz,
                events=c.rate_hz is None,
            )
        }

    def step(self, x: Chunk) -> dict[str, Chunk]:
        return {"y": x}

    @classmethod
    def example(cls) -> Example:
        rng = np.random.default_rng(3)
        return Example(inputs={"x": rng.normal(size=(200, 2))}, units={"x": "N"})
