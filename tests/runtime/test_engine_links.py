"""A new link kind is one module: a toy link registered here carries a graph bit-identically.

The toy link is written against the link interface alone (:class:`flowtact.runtime.links.Link`,
not the local link): it keeps a copy of every chunk it carries and hands the consumer a copy, so
the engine can only have got the schedule right (what is due when, delays, the final flush) by
going through the interface, never through the local link's lists.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from runs import TEST_BLOCKS

from flowtact.chunk import Chunk
from flowtact.graphfile.graph import load_graph
from flowtact.running.compile import compile_graph
from flowtact.runtime.inproc import InprocExecutor
from flowtact.runtime.links import LINKS, Link, link_kind, register_link

ROOT = Path(__file__).resolve().parents[2]


def _copy(c: Chunk) -> Chunk:
    return Chunk(c.t.copy(), c.data.copy(), c.end).readonly()


@register_link("toy_copying")
class CopyingLink(Link):
    """Records every chunk it is given; delivers a copy, held to the tick's end through a delay port."""

    made: list[CopyingLink] = []

    def __init__(self, spec, inbox, *, delayed=False):
        super().__init__(spec, inbox, delayed=delayed)
        self.holds = delayed
        self.carried: list[Chunk] = []
        self.held: list[Chunk] = []
        self.ended = False
        CopyingLink.made.append(self)

    def put(self, chunk: Chunk) -> None:
        self.carried.append(chunk)
        (self.held if self.holds and not self.ended else self.inbox).append(_copy(chunk))

    def tick_done(self) -> None:
        self.inbox.extend(self.held)
        self.held.clear()

    def end(self) -> None:
        self.ended = True

    def drop(self) -> None:
        self.held.clear()


class Memory:
    """A recorder in memory: stream -> chunks written."""

    def __init__(self) -> None:
        self.streams: dict[str, list[Chunk]] = {}

    def write(self, stream: str, chunk: Chunk) -> None:
        self.streams.setdefault(stream, []).append(chunk)

    def maybe_flush(self) -> None:
        pass

    def joined(self) -> dict[str, tuple[bytes, bytes]]:
        return {
            s: (np.concatenate([c.t for c in cs]).tobytes(), np.concatenate([c.data for c in cs]).tobytes())
            for s, cs in self.streams.items()
        }


LOOP = """
nodes:
  src: {block: "toyblocks:Ramp", params: {noise: 0.5, channels: 2}}
  a:   {block: "toyblocks:Loop"}
  b:   {block: "toyblocks:Scale", params: {gain: 3.0}}
  sum: {block: "toyblocks:Add", params: {wb: -0.25}}
edges:
  - src.y -> a.x
  - a.y -> b.x
  - b.y -> a.fb
  - src.y -> sum.a
  - b.y -> sum.b
record: [b.y, sum.y, src.y]
"""


def _run(text: str, link: str, duration: float, tick: float, **load) -> tuple[InprocExecutor, Memory]:
    plan = compile_graph(load_graph("g.yaml", text=textwrap.dedent(text), allow_modules=TEST_BLOCKS, **load))
    rec = Memory()
    ex = InprocExecutor(plan, fast=True, tick_s=tick, recorder=rec, link=link)
    ex.run(duration)
    return ex, rec


def test_a_registered_toy_link_carries_a_graph_with_a_loop_and_a_fan_in_bit_identically():
    CopyingLink.made.clear()
    local_ex, local = _run(LOOP, "local", 1.0, 0.013)
    toy_ex, toy = _run(LOOP, "toy_copying", 1.0, 0.013)
    assert LINKS["toy_copying"] is CopyingLink and link_kind("toy_copying") is CopyingLink
    assert toy.joined() == local.joined()
    assert len(local.joined()["sum.y"][0]) == 1000 * 8  # every sample, the last tick's included
    # the feedback went through the toy link's delay: every sample came back (the last at the flush)
    assert toy_ex.blocks["a"].got_feedback == local_ex.blocks["a"].got_feedback == 1000
    # every edge's chunks went through a toy link, each sample once (Ramp: 1000 samples a second)
    assert len(CopyingLink.made) == 5
    assert [sum(len(c) for c in ln.carried) for ln in CopyingLink.made] == [1000] * 5
    assert [ln.delayed for ln in CopyingLink.made].count(True) == 1


@pytest.mark.parametrize("link", ["toy_copying", "zmq"])
def test_a_graph_with_a_loop_runs_bit_identically_over_every_link_kind(link):
    _, local = _run(LOOP, "local", 0.5, 0.007)
    ex, other = _run(LOOP, link, 0.5, 0.007)
    assert other.joined() == local.joined() and len(local.joined()["b.y"][0]) == 500 * 8
    assert ex.blocks["a"].got_feedback == 500  # the delay held and released through the link
    assert {type(ln).__name__ for ln in ex.engine.links} == {
        "CopyingLink" if link == "toy_copying" else "ZmqLink"
    }


def test_an_unknown_link_kind_is_refused_with_the_known_ones():
    with pytest.raises(ValueError, match=r"unknown link kind 'nope' \(known: .*local"):
        link_kind("nope")


@pytest.mark.parametrize("link", ["toy_copying", "zmq"])
def test_a_shipped_graph_runs_bit_identically_over_the_toy_and_zeromq_links(link):
    graph = ROOT / "graphs" / "teleop.yaml"
    text = graph.read_text()
    sets = ["exo.port=sim"]
    _, local = _run(text, "local", 0.5, 0.01, overrides=sets)
    _, other = _run(text, link, 0.5, 0.01, overrides=sets)
    assert local.streams and other.joined() == local.joined()


class CopyingExecutor(InprocExecutor):
    """A toy executor found by name: the in-process engine over the toy link."""

    @classmethod
    def for_run(cls, plan, options):
        return cls(
            plan, fast=options.fast, tick_s=options.tick_s, recorder=options.recorder, link="toy_copying"
        )


def test_run_plan_finds_its_executor_by_name_in_the_registry():
    from flowtact.running.launch import run_compiled
    from flowtact.runtime.executors import EXECUTORS, executor_for, register_executor

    register_executor("toy_copying", CopyingExecutor)
    try:
        plan = compile_graph(load_graph("g.yaml", text=LOOP, allow_modules=TEST_BLOCKS))
        CopyingLink.made.clear()
        toy, local = Memory(), Memory()
        run_compiled(plan, duration_s=0.5, tick_s=0.01, executor="toy_copying", sink=toy)
        assert len(CopyingLink.made) == 5  # the run went through the registered executor
        plan = compile_graph(load_graph("g.yaml", text=LOOP, allow_modules=TEST_BLOCKS))
        run_compiled(plan, duration_s=0.5, tick_s=0.01, inproc=True, sink=local)
        assert toy.joined() == local.joined() and len(local.joined()["b.y"][0]) == 500 * 8
        assert executor_for("inproc") is InprocExecutor
        with pytest.raises(
            ValueError, match=r"unknown executor 'nope' \(known: inproc, processes, toy_copying\)"
        ):
            executor_for("nope")
    finally:
        EXECUTORS.pop("toy_copying", None)


LOOP_ACROSS = """
name: loop_across
nodes:
  src: {block: "toyblocks:Ramp", process: p, params: {noise: 0.5, channels: 2}}
  a:   {block: "toyblocks:Loop", process: q}
  b:   {block: "toyblocks:Scale", process: p, params: {gain: 3.0}}
  c:   {block: "toyblocks:Scale", process: p, params: {gain: -2.0}}
  sum: {block: "toyblocks:Add", process: q, params: {wb: -0.25}}
edges:
  - src.y -> a.x
  - a.y -> b.x
  - b.y -> a.fb
  - b.y -> c.x
  - src.y -> sum.a
  - a.y -> sum.b
record: [b.y, c.y, sum.y, src.y]
"""

WATCHED_RUN = """
import os, sys
from flowtact.runtime import engine
from flowtact.running.launch import load_compiled, run_compiled

seen, graph, record = sys.argv[1:4]
step = engine.Engine.step
told = set()


def watched(self, nodes, now, flush=False):
    nodes = tuple(nodes)
    for nd in nodes:
        if (os.getpid(), nd.name) not in told:  # once per process and node: what it ran on
            told.add((os.getpid(), nd.name))
            kinds = sorted({type(link).__name__ for link in self.links})
            with open(os.path.join(seen, f"{os.getpid()}-{nd.name}"), "w") as f:
                f.write(" ".join(kinds))
    return step(self, nodes, now, flush)


engine.Engine.step = watched  # the forked workers inherit it
summary = run_compiled(
    load_compiled(graph, allow_modules=("toyblocks",)), duration_s=0.5, fast=True, record=record
)
print(os.getpid(), " ".join(sorted(summary.processes)))
"""


@pytest.mark.slow
def test_a_worker_steps_its_nodes_through_the_engine_over_zeromq_links_bit_identically(tmp_path):
    """A worker IS the engine with ZeroMQ links: every node-step of both workers goes through
    ``Engine.step`` (wrapped in a fresh supervisor process; its forked workers inherit the wrapper),
    over local links within a process and the stream links across; a loop that crosses processes
    twice (a -> b -> a's delayed input) and a fan-in of a remote and a local stream (sum) record
    the same bits as in process."""
    from flowtact.recording.hdf5 import read_recording
    from flowtact.running.launch import load_compiled, run_compiled
    from flowtact.runtime.placement import place

    seen = tmp_path / "seen"
    seen.mkdir()
    graph = tmp_path / "loop.yaml"
    graph.write_text(LOOP_ACROSS)
    plan = load_compiled(graph, allow_modules=TEST_BLOCKS)
    assert place(plan, fast=True).groups == {"p": ["src", "b", "c"], "q": ["a", "sum"]}
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(ROOT / "tests"), os.environ.get("PYTHONPATH", "")]),
    }
    env.pop("FLOWTACT_NO_FORK", None)
    proc = subprocess.run(
        [sys.executable, "-c", WATCHED_RUN, str(seen), str(graph), str(tmp_path / "procs.h5")],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr
    supervisor, groups = proc.stdout.split()[0], proc.stdout.split()[1:]
    assert groups == ["p", "q"]
    ran = {}
    for f in seen.iterdir():
        pid, node = f.name.split("-", 1)
        assert pid != supervisor  # nothing stepped in the supervisor
        ran[node] = (pid, f.read_text())
    assert set(ran) == {"src", "a", "b", "c", "sum"}  # every node stepped inside Engine.step
    assert ran["src"][0] == ran["b"][0] == ran["c"][0] != ran["a"][0] == ran["sum"][0]
    assert {kinds for _, kinds in ran.values()} == {"InboundLink LocalLink OutboundLink"}
    run_compiled(
        load_compiled(graph, allow_modules=TEST_BLOCKS),
        duration_s=0.5,
        fast=True,
        inproc=True,
        record=tmp_path / "inproc.h5",
    )
    procs, inproc = read_recording(tmp_path / "procs.h5"), read_recording(tmp_path / "inproc.h5")
    assert set(procs.streams) == set(inproc.streams) == {"b.y", "c.y", "sum.y", "src.y"}
    for name, s in inproc.streams.items():
        assert len(s.t) == 500, name  # every sample, the last tick's included
        assert np.array_equal(procs.streams[name].t, s.t) and np.array_equal(
            procs.streams[name].data, s.data
        ), name
