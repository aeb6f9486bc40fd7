"""Tiny generic blocks for framework tests (graphs name them as ``toyblocks:Class``)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from flowtact import Block, Chunk, Config, Example, Port, Source, StreamSpec, param
from flowtact.errors import SpecError


@dataclass(frozen=True)
class RampConfig(Config):
    rate_hz: float = param(1000.0, doc="sample rate", gt=0)
    channels: int = param(1, doc="channels", ge=1)
    units: str = param("N", doc="units of the output")
    noise: float = param(0.0, doc="white noise sd", ge=0)


class Ramp(Source):
    """A ramp t·(1 + channel index) plus seeded noise."""

    config_cls = RampConfig
    outputs = {"y": Port(doc="the ramp"), "z": Port(doc="the ramp negated")}

    def specs(self, inputs):  # noqa: ARG002 — a source: its outputs come from its config
        c = self.config
        spec = StreamSpec(shape=(c.channels,), units=c.units, rate_hz=c.rate_hz)
        return {"y": spec, "z": spec}

    def reset(self):
        self.i = 0

    def step(self, now):
        n = self.due(now, self.config.rate_hz) - self.i
        t = (self.i + np.arange(n)) / self.config.rate_hz
        self.i += n
        y = t[:, None] * (1.0 + np.arange(self.config.channels))
        y = y + self.config.noise * self.rng.standard_normal(y.shape)
        out = {}
        if "y" in self.demanded:
            out["y"] = Chunk(t, y)
        if "z" in self.demanded:
            self.count("z_chunks")
            out["z"] = Chunk(t, -y)
        return out

    @classmethod
    def example(cls):
        return Example(params={"noise": 0.1})


@dataclass(frozen=True)
class ScaleConfig(Config):
    gain: float = param(2.0, doc="multiplier")
    rate_hz: float | None = param(None, doc="expected input rate", gt=0)
    mode: Literal["mul", "neg"] = param("mul", doc="what to do")


class Scale(Block):
    """y = gain · x."""

    config_cls = ScaleConfig
    inputs = {"x": Port(doc="in")}
    outputs = {"y": Port(doc="out")}

    def specs(self, inputs):
        x = inputs["x"]
        if self.config.rate_hz is not None and x.rate_hz != self.config.rate_hz:
            raise SpecError(
                "x", f"expects {self.config.rate_hz:g} Hz (rate_hz) but the stream is {x.rate_hz:g} Hz"
            )
        return {"y": x}

    def step(self, x):
        return {"y": Chunk(x.t, x.data * self.config.gain)}

    @classmethod
    def example(cls):
        return Example(inputs={"x": np.ones((10, 2))})


class Closable(Scale):
    """y = gain · x, refusing to step or flush once closed (a model or device released in close)."""

    def reset(self):
        self.closed = False

    def step(self, x):
        if self.closed:
            raise RuntimeError("stepped after close()")
        return super().step(x)

    def flush(self):
        if self.closed:
            raise RuntimeError("flushed after close()")
        return super().flush()

    def close(self):
        self.closed = True


@dataclass(frozen=True)
class AddConfig(Config):
    wb: float = param(1.0, doc="weight of b (0: b is not needed)")


class Add(Block):
    """y = a + wb·b, for sample-aligned inputs."""

    config_cls = AddConfig
    inputs = {
        "a": Port(units="N", doc="first"),
        "b": Port(optional=True, doc="second (optional)"),
        "fb": Port(optional=True, delay=True, doc="fed back one tick late"),
    }
    outputs = {"y": Port(doc="sum")}

    def needs(self, connected):
        return connected - ({"b"} if self.config.wb == 0 else set())

    def reset(self):
        self.held = {p: [] for p in self.inputs}

    def step(self, a, b=None, fb=None):  # noqa: ARG002 — step takes every input port; this toy ignores fb
        if b is None:
            return {"y": a}
        return {"y": Chunk(a.t, a.data + self.config.wb * b.data)}

    @classmethod
    def example(cls):
        return Example(inputs={"a": np.ones((10, 1))})


class Heavy(Block):
    """Imports a (pretend) heavy optional dependency only when opened."""

    config_cls = ScaleConfig
    requires = ("toyheavy",)
    inputs = {"x": Port(doc="in")}
    outputs = {"y": Port(doc="out")}

    def open(self):
        import toyheavy  # noqa: F401  (the import itself is what the test watches)

    def step(self, x):
        return {"y": x}

    @classmethod
    def example(cls):
        return Example(inputs={"x": np.ones((10, 1))})


class Loop(Block):
    """y = x + (what came back through the delayed input fb, shifted one tick)."""

    config_cls = AddConfig
    inputs = {"x": Port(doc="in"), "fb": Port(delay=True, optional=True, doc="feedback, one tick late")}
    outputs = {"y": Port(doc="out")}

    def reset(self):
        self.got_feedback = 0

    def step(self, x, fb=None):
        if fb is not None:
            self.got_feedback += len(fb)
        return {"y": x}

    @classmethod
    def example(cls):
        return Example(inputs={"x": np.ones((10, 1))})


@dataclass(frozen=True)
class FramesConfig(Config):
    rate_hz: float = param(40.0, doc="frames per second", gt=0)
    size: int = param(8, doc="frame side (pixels)", ge=1)


class Frames(Source):
    """A camera stand-in: uint8 frames whose pixels are (frame index + pixel index) mod 256."""

    config_cls = FramesConfig
    outputs = {"y": Port(doc="frames")}

    def specs(self, inputs):  # noqa: ARG002 — a source: its outputs come from its config
        c = self.config
        return {"y": StreamSpec(dtype="uint8", shape=(c.size, c.size), units="1", rate_hz=c.rate_hz)}

    def reset(self):
        self.i = 0

    def step(self, now):
        c = self.config
        n = self.due(now, c.rate_hz) - self.i
        idx = self.i + np.arange(n)
        self.i += n
        pix = np.arange(c.size * c.size).reshape(c.size, c.size)
        frames = ((idx[:, None, None] + pix[None]) % 256).astype(np.uint8)
        return {"y": Chunk(idx / c.rate_hz, frames)}

    @classmethod
    def example(cls):
        return Example()


class FrameMean(Block):
    """Mean pixel value of each frame."""

    inputs = {"x": Port(dtype="uint8", doc="frames")}
    outputs = {"y": Port(dtype="float64", shape=(), doc="mean")}

    def specs(self, inputs):
        return {"y": StreamSpec(units="1", rate_hz=inputs["x"].rate_hz)}

    def step(self, x):
        return {"y": Chunk(x.t, x.data.mean(axis=tuple(range(1, x.data.ndim))))}

    @classmethod
    def example(cls):
        frames = np.arange(5 * 4, dtype=np.uint8).reshape(5, 2, 2)
        return Example(inputs={"x": frames}, rate_hz=40.0)


@dataclass(frozen=True)
class SlowSinkConfig(Config):
    delay_s: float = param(0.01, doc="wall time spent per sample (a deliberately slow consumer)", ge=0)
    step_delay_s: float = param(0.0, doc="wall time spent per step that brings data", ge=0)


class SlowSink(Block):
    """Consumes a stream slowly (sleeps per sample: a test stand-in for a slow consumer) and counts."""

    config_cls = SlowSinkConfig
    inputs = {"x": Port(dtype=None, doc="anything")}
    outputs = {}
    sink = True

    def specs(self, inputs):  # noqa: ARG002 — a source: its outputs come from its config
        return {}

    def reset(self):
        self.n = 0

    def step(self, x):
        import time

        if len(x):
            self.count("received", len(x))
            time.sleep(self.config.delay_s * len(x) + self.config.step_delay_s)
        return {}

    @classmethod
    def example(cls):
        return Example(params={"delay_s": 0.0}, inputs={"x": np.arange(5.0)})


@dataclass(frozen=True)
class PlantConfig(Config):
    rate_hz: float = param(100.0, doc="sample rate", gt=0)
    gain: float = param(0.5, doc="how much of the fed-back command the plant adds each sample")


class Plant(Source):
    """A source in a feedback loop: y[i] = 1 + gain · (latest command stamped before sample i)."""

    config_cls = PlantConfig
    inputs = {"u": Port(shape=(), units="1", delay=True, optional=True, doc="command fed back")}
    outputs = {"y": Port(shape=(), units="1", doc="the plant's output")}

    def specs(self, inputs):  # noqa: ARG002 — a source: its outputs come from its config
        return {"y": StreamSpec(units="1", rate_hz=self.config.rate_hz)}

    def reset(self):
        self.i = 0
        self.ut = np.empty(0)
        self.u = np.zeros(1)  # u[0]: the command before any came

    def step(self, now, u=None):
        if u is not None and len(u):
            self.ut = np.concatenate([self.ut, u.t])
            self.u = np.concatenate([self.u, u.data])
        n = self.due(now, self.config.rate_hz) - self.i
        t = (self.i + np.arange(n)) / self.config.rate_hz
        self.i += n
        latest = self.u[np.searchsorted(self.ut, t, side="left")]
        return {"y": Chunk(t, 1.0 + self.config.gain * latest, end=now)}

    @classmethod
    def example(cls):
        return Example(params={}, inputs={"u": np.linspace(0, 1, 50)}, rate_hz=100.0, duration_s=0.5)


@dataclass(frozen=True)
class HangConfig(Config):
    at_s: float = param(float("inf"), doc="graph time at which the step hangs (inf: never)")
    hang_s: float = param(3600.0, doc="wall time the step hangs for", ge=0)


class Hang(Block):
    """Passes its input through; the step that reaches graph time ``at_s`` hangs (a test stand-in for a
    block stuck in a driver call or an endless loop). A worker resumed past ``at_s`` does not hang again."""

    config_cls = HangConfig
    inputs = {"x": Port(doc="anything")}
    outputs = {"y": Port(doc="the input, unchanged")}

    def reset(self):
        self.started = None

    def step(self, x):
        import time

        if len(x):
            if self.started is None:
                self.started = float(x.t[0])
            if self.started < self.config.at_s <= float(x.t[-1]):
                time.sleep(self.config.hang_s)
        return {"y": x}

    @classmethod
    def example(cls):
        return Example(inputs={"x": np.arange(5.0)})
