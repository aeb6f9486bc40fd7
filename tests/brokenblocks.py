"""Deliberately broken toy blocks: each breaks one rule, so tests can read what the suite says about it.

Graphs name them as ``brokenblocks:Class`` (tests/ is on the workers' path, as for toyblocks).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from flowtact import Block, Chunk, Config, Example, Port, param

_runs = itertools.count()  # state outside the block: what makes NotSeeded differ from run to run


@dataclass(frozen=True)
class GainConfig(Config):
    gain: float = param(1.0, doc="multiplier", gt=0)


def _ramp_example() -> Example:
    return Example(params={"gain": 0.5}, inputs={"x": np.linspace(0.0, 1.0, 1000)}, units={"x": "1"})


class _Toy(Block):
    """A toy: y from x."""

    config_cls = GainConfig
    inputs = {"x": Port(doc="in")}
    outputs = {"y": Port(doc="out")}

    @classmethod
    def example(cls) -> Example:
        return _ramp_example()


class PerChunkOffset(_Toy):
    """Subtracts each chunk's first sample: the output depends on where the chunks start."""

    def step(self, x: Chunk) -> dict[str, Chunk]:
        y = self.config.gain * (x.data - x.data[0]) if len(x) else x.data
        return {"y": Chunk(x.t, y)}


class Doubles(_Toy):
    """Doubles its input in place (inputs are read-only: this raises)."""

    def step(self, x: Chunk) -> dict[str, Chunk]:
        d = x.data
        d *= 2.0
        return {"y": Chunk(x.t, d)}


class Sneaky(_Toy):
    """Makes its read-only input writable again and clips it in place."""

    def step(self, x: Chunk) -> dict[str, Chunk]:
        d = x.data
        d.flags.writeable = True
        np.minimum(d, 0.5, out=d)
        return {"y": Chunk(x.t, d.copy())}


class NotSeeded(_Toy):
    """Adds a number that changes from run to run (not drawn from ``self.rng``)."""

    def reset(self) -> None:
        self.offset = float(next(_runs))

    def step(self, x: Chunk) -> dict[str, Chunk]:
        return {"y": Chunk(x.t, x.data + self.offset)}


class _Pass(_Toy):
    """Passes x through times the gain."""

    def step(self, x: Chunk) -> dict[str, Chunk]:
        return {"y": Chunk(x.t, x.data * self.config.gain)}


class PlainMethodExample(_Pass):
    """Its example is a plain method."""

    def example(self) -> Example:  # type: ignore[override]  # the mistake under test
        return _ramp_example()


class StaticExample(_Pass):
    """Its example is a staticmethod (accepted)."""

    @staticmethod
    def example() -> Example:  # type: ignore[override]
        return _ramp_example()


class AttributeExample(_Pass):
    """Its example is an Example attribute (accepted)."""

    example = _ramp_example()  # type: ignore[assignment]


class DictExample(_Pass):
    """Its example returns a dict, not an Example."""

    @classmethod
    def example(cls) -> Example:
        return {"params": {"gain": 0.5}}  # type: ignore[return-value]  # the mistake under test


class WrongPortExample(_Pass):
    """Its example feeds a port it does not have."""

    @classmethod
    def example(cls) -> Example:
        return Example(inputs={"u": np.zeros(10)})


class NoExample(Block):
    """Has no example at all."""

    config_cls = GainConfig
    inputs = {"x": Port(doc="in")}
    outputs = {"y": Port(doc="out")}

    def step(self, x: Chunk) -> dict[str, Chunk]:
        return {"y": x}


@dataclass(frozen=True)
class QuietConfig(Config):
    gain: float = param(1.0, doc="")


class Undocumented(_Pass):
    """A parameter without a doc."""

    config_cls = QuietConfig


@dataclass(frozen=True)
class BoomConfig(Config):
    at_s: float = param(0.5, doc="graph time from which every step raises", ge=0)


class Boom(Block):
    """Passes x through until graph time ``at_s``, then raises (a test stand-in for a buggy block)."""

    config_cls = BoomConfig
    inputs = {"x": Port(doc="anything")}
    outputs = {"y": Port(doc="the input, unchanged")}

    def step(self, x: Chunk) -> dict[str, Chunk]:
        if len(x) and float(x.t[-1]) >= self.config.at_s:
            self._explode(float(x.t[-1]))
        return {"y": x}

    def _explode(self, t: float) -> None:
        raise ZeroDivisionError(f"boom at t={t:.3f}")

    @classmethod
    def example(cls) -> Example:
        return Example(params={"at_s": 10.0}, inputs={"x": np.arange(5.0)})


class BadParamsExample(_Pass):
    """Its example's params break the config's rules."""

    @classmethod
    def example(cls) -> Example:
        return Example(params={"gain": -1.0}, inputs={"x": np.zeros(10)})


class BadSpecs(_Pass):
    """Its ``specs`` has a bug: compiling a graph that uses it fails."""

    def specs(self, inputs):  # type: ignore[no-untyped-def]
        return {"y": inputs["x"].with_(shape=(1 // 0,))}
