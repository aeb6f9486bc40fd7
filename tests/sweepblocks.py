"""Test blocks and metrics for sweeps (graphs name them as ``sweepblocks:Class``; tests/ is on the path).

``Probe`` passes its input through, and while its ``flag`` file exists it raises, kills its own
process (SIGKILL) or blocks forever at the first sample, as its ``mode`` says; each time it opens
it appends a line to ``log`` (so a test counts the runs that actually executed).
"""

from __future__ import annotations

import os
import signal
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from flowtact import Block, Chunk, Config, Example, Port, param

TOY_GRAPH = """
name: toy
seed: 3
duration_s: 0.3
nodes:
  src:   {block: "toyblocks:Ramp", params: {noise: 0.1}}
  probe: {block: "sweepblocks:Probe"}
edges: [src.y -> probe.x]
record: [src.y, probe.y]
"""
"""The sweep tests' graph: a noisy ramp through a probe (name both modules with --allow-module)."""

TOY_GRAPH_SCALED = (
    TOY_GRAPH.replace('  probe: {block: "sweepblocks:Probe"}\n',
                      '  probe: {block: "sweepblocks:Probe"}\n  dbl:   {block: "toyblocks:Scale", params: {gain: 2.0}}\n')
    .replace("edges: [src.y -> probe.x]", "edges: [src.y -> probe.x, src.y -> dbl.x]")
    .replace("record: [src.y, probe.y]", "record: [src.y, probe.y, dbl.y]")
)  # fmt: skip
""":data:`TOY_GRAPH` with a scaled copy of the ramp recorded too."""


@dataclass(frozen=True)
class ProbeConfig(Config):
    mode: Literal["ok", "raise", "kill", "hang"] = param("ok", doc="what to do while the flag file exists")
    flag: str = param("", doc="the flag file (empty: never act)")
    log: str = param("", doc="a file to append one line to at each open (empty: none)")


class Probe(Block):
    """y = x; raises, kills its process or hangs while ``flag`` exists, per ``mode``."""

    config_cls = ProbeConfig
    inputs = {"x": Port(doc="in")}
    outputs = {"y": Port(doc="the input, unchanged")}

    def open(self) -> None:
        if self.config.log:
            with open(self.config.log, "a") as f:
                f.write(f"{self.config.mode} {os.getpid()}\n")

    def step(self, x: Chunk) -> dict[str, Chunk]:
        armed = self.config.flag and Path(self.config.flag).exists()
        if armed and len(x) and self.config.mode == "raise":
            raise ZeroDivisionError("probe raised as asked")
        if armed and len(x) and self.config.mode == "kill":
            os.kill(os.getpid(), signal.SIGKILL)
        if armed and len(x) and self.config.mode == "hang":
            threading.Event().wait()  # a row that never returns
        return {"y": x}

    @classmethod
    def example(cls) -> Example:
        return Example(inputs={"x": np.arange(5.0)})


def mean_y(streams):
    """A user metric: the mean and sample count of ``probe.y``."""
    y = streams["probe.y"]
    return {"mean": float(np.mean(y.data)), "n": len(y.t)}


def not_a_dict(streams):  # noqa: ARG001 - a broken user metric
    return [1, 2]
