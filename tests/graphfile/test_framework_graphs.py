"""Loader, compiler and in-process executor on small graphs of generic toy blocks."""

import sys
import textwrap

import numpy as np
import pytest
from runs import TEST_BLOCKS

from flowtact.errors import GraphFileError, NodeError
from flowtact.graphfile.graph import load_graph
from flowtact.running.compile import compile_graph
from flowtact.runtime.inproc import InprocExecutor

BASE = """
name: toy
seed: 5
nodes:
  src:  {block: "toyblocks:Ramp", params: {channels: 2, noise: 0.01}}
  dbl:  {block: "toyblocks:Scale", params: {gain: 2.0}}
  add:  {block: "toyblocks:Add", params: {wb: 0.0}}
  dead: {block: "toyblocks:Scale"}
edges:
  - src.y -> dbl.x
  - dbl.y -> add.a
  - src.z -> add.b
  - src.y -> dead.x
record: [add.y, dbl.y]
"""


def load(text, **kw):
    return load_graph("g.yaml", text=textwrap.dedent(text), allow_modules=TEST_BLOCKS, **kw)


class Collect:
    """An in-memory recorder."""

    def __init__(self):
        self.chunks = {}

    def write(self, stream, chunk):
        self.chunks.setdefault(stream, []).append(chunk)

    def maybe_flush(self):
        pass

    def joined(self, stream):
        cs = self.chunks[stream]
        return np.concatenate([c.t for c in cs]), np.concatenate([c.data for c in cs])


def run(text, duration=2.0, tick=0.25, **kw):
    plan = compile_graph(load(text, **kw))
    rec = Collect()
    summary = InprocExecutor(plan, fast=True, tick_s=tick, recorder=rec).run(duration)
    return plan, rec, summary


def test_demand_propagation_prunes_dead_nodes_unused_outputs_and_zero_weight_inputs():
    plan = compile_graph(load(BASE))
    assert plan.order == ["src", "dbl", "add"]
    assert plan.pruned == ["dead"]
    assert plan.needed["add"] == {"a"}  # wb = 0: b is not demanded
    assert plan.demanded["src"] == {"y"}  # so z is never computed
    _, _, summary = run(BASE)
    assert "src" not in summary.counters  # Ramp counts the z chunks it computes: none


def test_prune_false_keeps_every_node_output_and_input_and_records_the_same():
    full = compile_graph(load(BASE), prune=False)
    assert sorted(full.order) == ["add", "dbl", "dead", "src"] and full.pruned == [] and full.notes == []
    assert full.needed["add"] == {"a", "b"} and full.demanded["src"] == {"y", "z"}
    assert {(e.src, e.dst) for e in full.active_edges} == {("src", "dbl"), ("dbl", "add"), ("src", "add"),
                                                            ("src", "dead")}  # fmt: skip
    pruned = compile_graph(load(BASE))  # the default is unchanged
    assert pruned.pruned == ["dead"] and pruned.needed["add"] == {"a"}
    recs, sums = [], []
    for plan in (pruned, full):
        rec = Collect()
        sums.append(InprocExecutor(plan, fast=True, tick_s=0.25, recorder=rec).run(2.0))
        recs.append(rec)
    for stream in ("add.y", "dbl.y"):
        for a, b in zip(recs[0].joined(stream), recs[1].joined(stream), strict=True):
            np.testing.assert_array_equal(a, b)  # wb = 0: the extra work changes nothing recorded
    assert "src" not in sums[0].counters and sums[1].counters["src"]["z_chunks"] > 0  # z computed


def test_nonzero_weight_demands_the_input_and_its_upstream_output():
    plan = compile_graph(load(BASE.replace("wb: 0.0", "wb: 0.5")))
    assert plan.needed["add"] == {"a", "b"}
    assert plan.demanded["src"] == {"y", "z"}
    _, rec, _ = run(BASE.replace("wb: 0.0", "wb: 0.5"))
    t, y = rec.joined("add.y")
    expected = 2 * t[:, None] * [1, 2] - 0.5 * t[:, None] * [1, 2]
    np.testing.assert_allclose(y, expected, atol=0.1)


def test_runs_are_deterministic_and_independent_of_the_tick():
    _, a, _ = run(BASE, tick=0.25)
    _, b, _ = run(BASE, tick=0.0137)
    _, c, _ = run(BASE, tick=2.0)
    for rec in (b, c):
        for stream in ("add.y", "dbl.y"):
            ta, ya = a.joined(stream)
            tb, yb = rec.joined(stream)
            assert np.array_equal(ta, tb) and np.array_equal(ya, yb)
    t, _ = a.joined("add.y")
    assert len(t) == 2000 and t[-1] == pytest.approx(1.999)


def test_seed_changes_the_noise():
    _, a, _ = run(BASE)
    _, b, _ = run(BASE.replace("seed: 5", "seed: 6"))
    assert not np.array_equal(a.joined("dbl.y")[1], b.joined("dbl.y")[1])


def test_overrides_are_validated_like_the_file():
    plan = compile_graph(load(BASE, overrides=["dbl.gain=3"]))
    node = plan.graph.nodes["dbl"]
    assert node.config.gain == 3.0
    with pytest.raises(GraphFileError) as e:
        load(BASE, overrides=["dbl.gain=fast"])
    assert "--set:1:1: dbl (scale): 'gain' must be a number; got 'fast'" in str(e.value)
    with pytest.raises(GraphFileError) as e:
        load(BASE, overrides=["dbll.gain=3"])
    assert "unknown node 'dbll' (did you mean 'dbl'?)" in str(e.value)


def test_cycle_through_a_delay_port_runs_and_feeds_back_one_tick_late():
    text = """
    nodes:
      src: {block: "toyblocks:Ramp"}
      a:   {block: "toyblocks:Loop"}
      b:   {block: "toyblocks:Scale"}
    edges:
      - src.y -> a.x
      - a.y -> b.x
      - b.y -> a.fb
    record: [b.y]
    """
    plan = compile_graph(load(text))
    assert plan.order == ["src", "a", "b"]
    ex = InprocExecutor(plan, fast=True, tick_s=0.5)
    ex.run(2.0)
    assert ex.blocks["a"].got_feedback == 2000  # every sample came back, the last tick's at flush


def test_cycle_without_delay_is_rejected_with_its_path():
    text = """
    nodes:
      src: {block: "toyblocks:Ramp"}
      a:   {block: "toyblocks:Add"}
      b:   {block: "toyblocks:Scale"}
    edges:
      - src.y -> a.a
      - a.y -> b.x
      - b.y -> a.b
    """
    with pytest.raises(GraphFileError) as e:
        compile_graph(load(text))
    msg = str(e.value)
    assert "g.yaml:9:5: cycle without a delay: a -> b -> a" in msg
    assert "one-step delay" in msg


def test_units_and_rate_mismatches_are_errors_at_the_edge():
    text = """
    nodes:
      src: {block: "toyblocks:Ramp", params: {units: mN}}
      add: {block: "toyblocks:Add"}
    edges:
      - src.y -> add.a
    """
    with pytest.raises(GraphFileError) as e:
        compile_graph(load(text))
    assert (
        "g.yaml:6:5: src.y -> add.a: input 'a' of 'add' (add: first) expects units 'N' but gets 'mN'"
        in str(e.value)
    )
    text = """
    nodes:
      src: {block: "toyblocks:Ramp", params: {rate_hz: 1000}}
      s:   {block: "toyblocks:Scale", params: {rate_hz: 250}}
    edges:
      - src.y -> s.x
    record: [s.y]
    """
    with pytest.raises(GraphFileError) as e:
        compile_graph(load(text))
    assert "g.yaml:6:5: node 's' (scale): expects 250 Hz (rate_hz) but the stream is 1000 Hz" in str(e.value)


def test_optional_heavy_imports_load_only_for_active_nodes():
    text = """
    nodes:
      src: {block: "toyblocks:Ramp"}
      h:   {block: "toyblocks:Heavy"}
    edges:
      - src.y -> h.x
    record: [src.y]
    """
    sys.modules.pop("toyheavy", None)
    plan, _, _ = run(text)
    assert plan.pruned == ["h"] and "toyheavy" not in plan.requires
    assert "toyheavy" not in sys.modules
    plan, _, _ = run(text.replace("record: [src.y]", "record: [h.y]"))
    assert plan.requires == {"toyheavy"}
    assert "toyheavy" in sys.modules


def test_a_failing_block_is_named():
    text = """
    nodes:
      src: {block: "toyblocks:Ramp", params: {channels: 2}}
      add: {block: "toyblocks:Add", params: {wb: 1.0}}
    edges:
      - src.y -> add.a
      - src.y -> add.b
    record: [add.y]
    """
    # a and b are the same stream here; break the block by feeding it a mismatched shape on purpose
    plan = compile_graph(load(text))
    ex = InprocExecutor(plan, fast=True, tick_s=0.5)
    ex.blocks["add"].step = lambda *_args, **_kwargs: 1 / 0
    with pytest.raises(NodeError, match=r"node 'add' \(add\) failed at t=0.500 s: ZeroDivisionError"):
        ex.run(1.0)


def test_errors_are_all_collected_with_locations():
    text = """
    name: broken
    nodse: {}
    nodes:
      src: {block: "toyblocks:Ramp", params: {rate_hz: -1}}
      s:   {block: "toyblocks:Scale", params: {gian: 2}}
    edges:
      - src.w -> s.x
    record: [s.q]
    """
    with pytest.raises(GraphFileError) as e:
        load(text)
    lines = str(e.value).splitlines()
    assert lines[0].startswith("g.yaml:3:1: unknown top-level key 'nodse' (did you mean 'nodes'?)")
    text_all = str(e.value)
    assert "g.yaml:5:52: src (ramp): 'rate_hz' must be > 0; got -1" in text_all
    assert "g.yaml:6:44: s (scale): unknown parameter 'gian' (did you mean 'gain'?)" in text_all
    assert "g.yaml:8:5: block 'ramp' (node 'src') has no output 'w' (valid: y, z)" in text_all
    assert "g.yaml:9:10: cannot record 's.q': block 'scale' (node 's') has no output 'q'" in text_all


DELAY_LOOP = """
nodes:
  src: {block: "toyblocks:Ramp"}
  a:   {block: "toyblocks:Loop"}
  d:   {block: delay, params: {shape: [1], units: N, rate_hz: 1000}}
edges:
  - src.y -> a.x
  - a.y -> d.x
  - d.y -> a.fb
record: [a.y]
"""


def test_a_delay_block_closes_a_loop_when_it_declares_the_fed_back_stream():
    plan = compile_graph(load(DELAY_LOOP))
    ex = InprocExecutor(plan, fast=True, tick_s=0.5)
    ex.run(2.0)
    assert ex.blocks["a"].got_feedback == 2000
    with pytest.raises(GraphFileError, match="declare the fed-back stream"):
        compile_graph(load(DELAY_LOOP.replace("units: N,", "units: mN,")))


def test_an_unknown_parameter_is_located_at_its_key_whatever_its_spelling():
    """The graph locates the unknown key from the error's data (ConfigError.unknown), not by reading
    its message: a key with a quote in it is still pointed at, not its node."""
    text = """
    name: quoted
    nodes:
      src: {block: "toyblocks:Ramp"}
      s:   {block: "toyblocks:Scale", params: {"ga'in": 2}}
    edges:
      - src.y -> s.x
    record: [s.y]
    """
    with pytest.raises(GraphFileError) as e:
        load(text)
    assert "g.yaml:5:44: s (scale): unknown parameter 'ga'in' (did you mean 'gain'?)" in str(e.value)
