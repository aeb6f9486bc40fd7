"""Toy blocks for the read-only delivery tests (graphs name them as ``sealblocks:Class``)."""

from __future__ import annotations

import numpy as np

from flowtact import Block, Chunk, Example, Port, Source, StreamSpec

made: list[tuple[int, int]] = []
"""ids of the (t, data) arrays Fresh produced, tick by tick (ids only: no reference kept)."""
got: dict[str, list[tuple[int, int, bool, bool]]] = {}
"""Per Probe node: ids of what it received and whether each array was writable."""


class Fresh(Source):
    """One new sample a tick (1 kHz ticks), in arrays it keeps no reference to."""

    outputs = {"y": Port(doc="ones")}

    def specs(self, inputs):  # noqa: ARG002 - a source: its outputs come from its config
        return {"y": StreamSpec(shape=(1,), rate_hz=1000.0)}

    def reset(self) -> None:
        self.i = 0

    def step(self, now: float) -> dict[str, Chunk]:
        n = self.due(now, 1000.0) - self.i
        t = (self.i + np.arange(n)) / 1000.0
        self.i += n
        d = np.ones((n, 1))
        made.append((id(t), id(d)))
        return {"y": Chunk(t, d)}

    @classmethod
    def example(cls) -> Example:
        return Example()


class FreshFrames(Fresh):
    """Fresh's samples as 96x96 float64 frames (72 KiB: sent as zero-copy frames between processes)."""

    def specs(self, inputs):  # noqa: ARG002 - a source: its outputs come from its config
        return {"y": StreamSpec(shape=(96, 96), rate_hz=1000.0)}

    def step(self, now: float) -> dict[str, Chunk]:
        c = super().step(now)["y"]
        return {"y": Chunk(c.t, np.ones((len(c.t), 96, 96)))}


class Reuses(Block):
    """Writes each step's result into the one buffer it keeps and returns that buffer."""

    inputs = {"x": Port(doc="in")}
    outputs = {"y": Port(doc="x + step number")}

    def reset(self) -> None:
        self.buf = np.zeros((1, 1))
        self.k = 0

    def step(self, x: Chunk) -> dict[str, Chunk]:
        self.k += 1
        self.buf[:] = x.data[-1:] + self.k  # raises if the executor sealed the kept buffer
        return {"y": Chunk(x.t[-1:].copy(), self.buf)}

    @classmethod
    def example(cls) -> Example:
        return Example(inputs={"x": np.ones((3, 1))})


class Probe(Block):
    """Passes x on and notes what it received."""

    inputs = {"x": Port(doc="in")}
    outputs = {"y": Port(doc="x")}

    def step(self, x: Chunk) -> dict[str, Chunk]:
        got.setdefault(self.node, []).append(
            (id(x.t), id(x.data), bool(x.t.flags.writeable), bool(x.data.flags.writeable))
        )
        return {"y": x}

    @classmethod
    def example(cls) -> Example:
        return Example(inputs={"x": np.ones((3, 1))})


class Writes(Block):
    """Adds one to its input in place (a bug: inputs are read-only)."""

    inputs = {"x": Port(doc="in")}
    outputs = {"y": Port(doc="x + 1")}

    def step(self, x: Chunk) -> dict[str, Chunk]:
        x.data[:] += 1.0
        return {"y": x}

    @classmethod
    def example(cls) -> Example:
        return Example(inputs={"x": np.ones((3, 1))})


class Relabels(Block):
    """Hands on the float64 chunk it got as its float32 output (a bug the output check must catch)."""

    inputs = {"x": Port(doc="in")}
    outputs = {"y": Port(dtype="float32", doc="x, claimed float32")}

    def step(self, x: Chunk) -> dict[str, Chunk]:
        return {"y": x}

    @classmethod
    def example(cls) -> Example:
        return Example(inputs={"x": np.ones((3, 1))})


class KeepsChunk(Block):
    """Keeps the chunk it returned (only the chunk) and writes into its data on the next step."""

    inputs = {"x": Port(doc="in")}
    outputs = {"y": Port(doc="x, then overwritten")}

    def reset(self) -> None:
        self.prev: Chunk | None = None

    def step(self, x: Chunk) -> dict[str, Chunk]:
        if self.prev is not None:
            self.prev.data[:] = -1.0  # raises if the executor sealed the kept chunk's array
        self.prev = Chunk(x.t, x.data.copy())
        return {"y": self.prev}

    @classmethod
    def example(cls) -> Example:
        return Example(inputs={"x": np.ones((3, 1))})
