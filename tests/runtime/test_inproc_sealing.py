"""The in-process executor seals each produced chunk once: consumers share it and cannot write it."""

import textwrap

import numpy as np
import pytest
import sealblocks
from runs import TEST_BLOCKS

from flowtact.chunk import Chunk
from flowtact.errors import NodeError
from flowtact.graphfile.graph import load_graph
from flowtact.running.compile import compile_graph
from flowtact.runtime.inproc import InprocExecutor


def run(text: str, ticks: int = 5) -> dict[str, list[Chunk]]:
    sealblocks.made.clear()
    sealblocks.got.clear()
    plan = compile_graph(load_graph("g.yaml", text=textwrap.dedent(text), allow_modules=TEST_BLOCKS))
    rec: dict[str, list[Chunk]] = {}

    class Memory:
        def write(self, stream, chunk):
            rec.setdefault(stream, []).append(chunk)

        def maybe_flush(self):
            pass

    InprocExecutor(plan, fast=True, tick_s=0.001, recorder=Memory()).run(ticks * 0.001)
    return rec


FAN_OUT = """
nodes:
  src: {block: "sealblocks:Fresh"}
  a: {block: "sealblocks:Probe"}
  b: {block: "sealblocks:Probe"}
edges: [src.y -> a.x, src.y -> b.x]
record: [a.y, b.y]
"""


def test_fresh_arrays_are_sealed_in_place_and_every_consumer_gets_the_same_ones():
    run(FAN_OUT)
    made = sealblocks.made
    assert len(made) == 5
    for name in ("a", "b"):
        got = sealblocks.got[name]
        assert [(t, d) for t, d, _, _ in got] == made  # no view, no copy: the source's own arrays
        assert not any(tw or dw for _, _, tw, dw in got)  # and read-only


def test_a_block_that_rewrites_the_buffer_it_returned_keeps_running_and_consumers_get_views():
    rec = run(
        """
        nodes:
          src: {block: "sealblocks:Fresh"}
          re: {block: "sealblocks:Reuses"}
          p: {block: "sealblocks:Probe"}
        edges: [src.y -> re.x, re.y -> p.x]
        record: [p.y]
        """
    )
    got = sealblocks.got["p"]
    assert len(got) == 5 and not any(tw or dw for _, _, tw, dw in got)
    # every tick's chunk is a read-only view of the one buffer, which holds the last value
    assert [float(c.data[0, 0]) for c in rec["p.y"]] == [6.0] * 5


def test_a_block_that_keeps_the_chunk_it_returned_may_still_write_into_it():
    rec = run(
        """
        nodes:
          src: {block: "sealblocks:Fresh"}
          k: {block: "sealblocks:KeepsChunk"}
        edges: [src.y -> k.x]
        record: [k.y]
        """
    )
    assert len(rec["k.y"]) == 5 and all(not c.data.flags.writeable for c in rec["k.y"])


def test_a_consumer_cannot_write_what_another_consumer_also_receives():
    with pytest.raises(NodeError, match=r"node 'w' \(writes\) failed.*read-only"):
        run(
            """
            nodes:
              src: {block: "sealblocks:Fresh"}
              p: {block: "sealblocks:Probe"}
              w: {block: "sealblocks:Writes"}
            edges: [src.y -> p.x, src.y -> w.x]
            record: [p.y, w.y]
            """
        )


def test_readonly_returns_a_read_only_chunk_itself_and_views_otherwise():
    t, d = np.arange(3.0), np.ones((3, 1))
    c = Chunk(t, d)
    r = c.readonly()
    assert r is not c and r.t.base is t and not (r.t.flags.writeable or r.data.flags.writeable)
    assert t.flags.writeable and d.flags.writeable  # the given arrays stay writable
    assert r.readonly() is r


def test_a_chunk_handed_on_is_checked_again_against_a_stream_of_another_kind():
    # the source's chunk was checked as float64 this tick; handed on as float32 it must not pass
    with pytest.raises(
        RuntimeError, match=r"node 'r' produced float64\[1, 1\].*on 'y'.*float32.*a bug in the block"
    ):
        run(
            """
            nodes:
              src: {block: "sealblocks:Fresh"}
              p: {block: "sealblocks:Probe"}
              r: {block: "sealblocks:Relabels"}
            edges: [src.y -> p.x, p.y -> r.x]
            record: [r.y]
            """
        )


def test_step_gets_its_one_input_by_position_only_where_that_binds_the_same():
    from flowtact.runtime.step_plan import takes_first

    one = (("x", [], None, None),)

    def first(x, gain=None):
        return {"x": x, "gain": gain}

    def second(gain=None, x=None):
        return {"x": x, "gain": gain}

    def kw_only(*, x):
        return {"x": x}

    def anything(*_a, **_k):
        return {}

    assert takes_first(first, one)
    assert not takes_first(second, one)  # step(chunk) would bind it to gain
    assert not takes_first(kw_only, one)
    assert not takes_first(anything, one)
    assert not takes_first(first, (("x", [], None, None), ("y", [], None, None)))
    assert not takes_first(first, ((None, [], None, None),))  # drained, not passed
