"""Toy blocks with numba kernels compiled afresh in every process (no cache), for test_warm_up.py,
and one whose start-up is slow without numba (``Slow``: a warm-up in slow steps, an ``open()`` that hangs).

Graphs name them as ``warmblocks:Class`` (tests/ is on the workers' path, as for toyblocks).
Without ``cache=True`` every process compiles them, so a run always has something to compile.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass

import numpy as np
from numba import njit

from flowtact import Block, Chunk, Config, Example, Port, param


@njit
def scale_kernel(x, gain):
    """gain · x, on the array as delivered (read-only, aligned or not): its type picks the signature."""
    out = np.empty(x.shape)
    for i in range(x.shape[0]):
        for j in range(x.shape[1]):
            out[i, j] = x[i, j] * gain
    return out


@njit
def above_kernel(x, level):
    """How many values exceed ``level``: reached only on input above it."""
    n = 0
    for v in x.ravel():
        n += v > level
    return n


@dataclass(frozen=True)
class GainConfig(Config):
    gain: float = param(2.0, doc="multiplier")
    level: float = param(1e9, doc="above this, count with a second kernel (LateKernel)")
    kernels: int = param(0, doc="fresh kernels the warm_up() hook compiles (SlowWarmUp)", ge=0)


class JitScale(Block):
    """y = gain · x by a numba kernel called on the read-only input itself."""

    config_cls = GainConfig
    inputs = {"x": Port(doc="in")}
    outputs = {"y": Port(doc="out")}

    def reset(self):
        pass

    def step(self, x):
        flat = x.data.reshape(len(x), int(np.prod(x.data.shape[1:])))
        return {"y": Chunk(x.t, scale_kernel(flat, self.config.gain).reshape(x.data.shape))}

    @classmethod
    def example(cls):
        return Example(inputs={"x": np.ones((10, 2))})


class LateKernel(JitScale):
    """As JitScale; input above ``level`` also runs a second kernel a synthetic warm-up never reaches."""

    counter_docs = {"above": "values above level"}

    def step(self, x):
        if len(x) and float(np.max(x.data)) > self.config.level:
            self.count("above", above_kernel(x.data, self.config.level))
        return super().step(x)


class SlowWarmUp(JitScale):
    """As JitScale, with a ``warm_up()`` hook that compiles ``kernels`` fresh kernels (a long compile)."""

    def warm_up(self):
        for k in range(self.config.kernels):
            njit(_plus(k))(np.zeros(2))


def _plus(k):
    def plus(a):
        return a + k

    return plus


@dataclass(frozen=True)
class SlowConfig(Config):
    step_s: float = param(0.0, doc="wall time each of an instance's first slow_steps steps sleeps", ge=0)
    slow_steps: int = param(6, doc="how many of an instance's steps are slow", ge=0)
    open_s: float = param(0.0, doc="wall time open() sleeps (a device that never answers)", ge=0)
    mark: str = param("", doc="a file each instance appends its pid to as its first step begins")


class Slow(Block):
    """Passes its input through slowly: a start-up (warm-up, open) that takes a while, without numba.

    Its warm-up copy sleeps in each of the warm-up's steps (progress in steps); ``open_s`` makes
    ``open()`` hang without a word; ``mark`` tells a test that a warm-up has begun in this process.
    """

    config_cls = SlowConfig
    inputs = {"x": Port(doc="in")}
    outputs = {"y": Port(doc="the input, unchanged")}

    def reset(self):
        self.steps = 0

    def open(self):
        time.sleep(self.config.open_s)

    def step(self, x):
        if self.steps == 0 and self.config.mark:
            with open(self.config.mark, "a") as f:
                f.write(f"{os.getpid()} step\n")
        if self.steps < self.config.slow_steps:
            time.sleep(self.config.step_s)
        self.steps += 1
        return {"y": x}

    @classmethod
    def example(cls):
        return Example(inputs={"x": np.ones((10, 2))})
