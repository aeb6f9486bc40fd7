"""A test block for the worker's hot path (graphs name it ``hotpathblocks:SlowRamp``)."""

from __future__ import annotations

import time
from dataclasses import dataclass

from toyblocks import Ramp, RampConfig, Scale, ScaleConfig

from flowtact import param


@dataclass(frozen=True)
class SlowRampConfig(RampConfig):
    step_delay_s: float = param(0.0, doc="wall time each step takes (a source with costly steps)", ge=0)


class SlowRamp(Ramp):
    """The toy ramp, taking ``step_delay_s`` of wall time per step (a test stand-in for a costly source)."""

    config_cls = SlowRampConfig

    def step(self, now):
        time.sleep(self.config.step_delay_s)
        return super().step(now)


@dataclass(frozen=True)
class SlowScaleConfig(ScaleConfig):
    step_delay_s: float = param(
        0.0, doc="wall time each step takes (a consumer slower than its producer)", ge=0
    )


class SlowScale(Scale):
    """The toy gain, taking ``step_delay_s`` of wall time per step that brings data."""

    config_cls = SlowScaleConfig
    chunking_invariant = True  # so --fast may step it once over several ticks (ticks_mergeable)

    def step(self, x):
        if len(x):
            time.sleep(self.config.step_delay_s)
        return super().step(x)
