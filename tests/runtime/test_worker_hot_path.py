"""The worker's hot path: what its latency figures mean, and that fast runs stay exact."""

from __future__ import annotations

import json

import numpy as np
import pytest
from runs import TEST_BLOCKS, flowtact

from flowtact.chunk import Chunk, StreamSpec, concat
from flowtact.errors import WorkerFailed
from flowtact.graphfile.deployment import Flow
from flowtact.recording.hdf5 import read_recording
from flowtact.running.launch import load_compiled, run_compiled
from flowtact.runtime.links.zeromq.streams import MERGE_MAX_BYTES, ZmqInbound
from flowtact.runtime.protocol import InboundStream
from flowtact.runtime.worker import Worker
from flowtact.runtime.worker_plan import ticks_mergeable
from flowtact.runtime.worker_records import RecordBuffer
from flowtact.runtime.worker_ticks import FOREVER

pytestmark = pytest.mark.slow

SLOW_SOURCE = """
name: slow_source
tick_s: 0.1
nodes:
  src:  {block: "hotpathblocks:SlowRamp", process: a, params: {rate_hz: 100, step_delay_s: 0.06}}
  gain: {block: "toyblocks:Scale", process: b}
edges:
  - src.y -> gain.x
record: [gain.y]
"""


def test_a_source_s_own_step_time_is_not_counted_as_transport_latency(tmp_path):
    """Each source step takes 60 ms; the message's latency starts once the data exists."""
    path = tmp_path / "slow.yaml"
    path.write_text(SLOW_SOURCE)
    proc = flowtact("run", str(path), "--duration", "3", "--json")
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 0, stderr
    summary = json.loads(stdout)
    lat = summary["streams"]["src.y"]["latency_us"]
    assert lat["n"] >= 5, lat
    # stamped before the step, every latency would be >= 60 000 µs
    assert lat["p50"] < 30_000, lat


CHAIN = """
name: merged
tick_s: 0.001
seed: 3
nodes:
  src:  {block: "toyblocks:Ramp", process: a, params: {noise: 0.1, channels: 2}}
  slow: {block: "hotpathblocks:SlowScale", process: b, params: {gain: 2.0, step_delay_s: 0.002}}
  last: {block: "hotpathblocks:SlowScale", process: c, params: {gain: 3.0}}
edges:
  - src.y -> slow.x
  - slow.y -> last.x
record: [slow.y, last.y]
"""

FAN_IN = """
name: fan_in
tick_s: 0.001
seed: 3
nodes:
  src:  {block: "toyblocks:Ramp", process: a, params: {noise: 0.1}}
  slow: {block: "hotpathblocks:SlowScale", process: b, params: {gain: 2.0, step_delay_s: 0.002}}
  add:  {block: "toyblocks:Add", process: c}
edges:
  - src.y -> slow.x
  - src.y -> add.a
  - slow.y -> add.b
record: [add.y]
"""


def _same(a, b) -> None:
    ra, rb = read_recording(a), read_recording(b)
    assert set(ra.streams) == set(rb.streams)
    for name in rb.streams:
        x, y = ra.streams[name], rb.streams[name]
        assert len(y.t) > 0, name
        assert np.array_equal(x.t, y.t) and np.array_equal(x.data, y.data), name


def _fast_and_inproc(tmp_path, text: str):
    path = tmp_path / "g.yaml"
    path.write_text(text)
    summary = run_compiled(
        load_compiled(path, allow_modules=TEST_BLOCKS),
        duration_s=1.0,
        fast=True,
        record=tmp_path / "procs.h5",
    )
    run_compiled(
        load_compiled(path, allow_modules=TEST_BLOCKS),
        duration_s=1.0,
        fast=True,
        inproc=True,
        record=tmp_path / "inproc.h5",
    )
    _same(tmp_path / "procs.h5", tmp_path / "inproc.h5")
    return summary, load_compiled(path, allow_modules=TEST_BLOCKS)


def test_a_fast_consumer_behind_steps_once_over_the_ticks_it_holds_and_stays_bit_identical(tmp_path):
    """The slow stage holds many ticks whenever it looks: it sends far fewer messages than ticks."""
    summary, plan = _fast_and_inproc(tmp_path, CHAIN)
    assert ticks_mergeable(plan)
    slow = summary.streams["slow.y"]
    assert slow["samples"] == 1000
    assert slow["messages"] < 500, slow  # one per tick without merging
    assert summary.streams["src.y"]["messages"] == 1000  # a source still sends every tick


def test_fan_in_keeps_one_message_per_tick(tmp_path):
    """Add pairs its inputs chunk by chunk: merging ticks on one path would misalign them."""
    summary, plan = _fast_and_inproc(tmp_path, FAN_IN)
    assert not ticks_mergeable(plan)
    assert summary.streams["slow.y"]["messages"] == 1000


def test_loops_and_sources_with_inputs_are_not_mergeable(tmp_path):
    loop = tmp_path / "loop.yaml"
    loop.write_text(
        "name: loop\nnodes:\n  src: {block: 'toyblocks:Ramp', process: a}\n"
        "  l: {block: 'toyblocks:Loop', process: b}\n  g: {block: 'toyblocks:Scale', process: c}\n"
        "edges:\n  - src.y -> l.x\n  - l.y -> g.x\n  - g.y -> l.fb\nrecord: [g.y]\n"
    )
    plant = tmp_path / "plant.yaml"
    plant.write_text(
        "name: plant\nnodes:\n  p: {block: 'toyblocks:Plant', process: a}\n"
        "  g: {block: 'toyblocks:Scale', process: b, params: {gain: 0.5}}\n"
        "edges:\n  - p.y -> g.x\n  - g.y -> p.u\nrecord: [p.y]\n"
    )
    assert not ticks_mergeable(load_compiled(loop, allow_modules=TEST_BLOCKS))
    assert not ticks_mergeable(load_compiled(plant, allow_modules=TEST_BLOCKS))


def test_blocks_not_known_to_be_chunking_invariant_are_not_merged(tmp_path):
    """toyblocks:Scale is neither registered nor declared chunking-invariant; savgol is registered."""
    undeclared = tmp_path / "undeclared.yaml"
    undeclared.write_text(
        CHAIN.replace('"hotpathblocks:SlowScale", process: c', '"toyblocks:Scale", process: c')
    )
    assert not ticks_mergeable(load_compiled(undeclared, allow_modules=TEST_BLOCKS))
    registered = tmp_path / "registered.yaml"
    registered.write_text(
        "name: reg\nnodes:\n  src: {block: 'toyblocks:Ramp', process: a}\n"
        "  f: {block: savgol, process: b, params: {window: 5, order: 2}}\n"
        "edges:\n  - src.y -> f.x\nrecord: [f.y]\n"
    )
    assert ticks_mergeable(load_compiled(registered, allow_modules=TEST_BLOCKS))


READ_ONLY = """
name: read_only
tick_s: 0.001
nodes:
  src: {{block: "sealblocks:{source}", process: a}}
  w:   {{block: "sealblocks:Writes", process: {where}}}
edges:
  - src.y -> w.x
record: [w.y]
"""


@pytest.mark.parametrize(
    ("source", "where"),
    [("Fresh", "a"), ("Fresh", "b"), ("FreshFrames", "b")],
    ids=["same process", "another process", "zero-copy frames"],
)
def test_a_block_in_a_worker_cannot_write_what_it_receives(tmp_path, source, where):
    """The worker calls ``step`` directly: what it passes must already be read-only, whether a
    producer in the same process made it (sealed as it is delivered) or it came from another
    (views of the received message, copied or zero-copy)."""
    path = tmp_path / "g.yaml"
    path.write_text(READ_ONLY.format(source=source, where=where))
    with pytest.raises(WorkerFailed, match=r"node 'w' \(writes\).*read-only"):
        run_compiled(load_compiled(path, allow_modules=TEST_BLOCKS), duration_s=0.05, fast=True)


def _inbound(spec: StreamSpec, messages: int, samples: int) -> ZmqInbound:
    """A block stream as a worker holds it, having received ``messages`` carrying ``samples``."""
    ib = ZmqInbound(
        InboundStream(id=0, stream="s.y", spec=spec, flow=Flow("block", 1000), dsts=(), same_host=True)
    )
    ib.messages, ib.samples = messages, samples
    return ib


def test_a_merged_step_takes_about_a_mebibyte_of_each_input():
    """Frames merge a dozen at a time, small samples by the tens of thousands (bytes per tick measured)."""
    frames = _inbound(StreamSpec(dtype="uint8", shape=(240, 320)), 10, 10)
    assert frames.merge_cap() == MERGE_MAX_BYTES // (240 * 320) == 13
    small = _inbound(StreamSpec(shape=(4,)), 100, 1000)  # 10 samples of 32 bytes per tick
    assert small.merge_cap() == MERGE_MAX_BYTES // 320
    assert _inbound(StreamSpec(dtype="uint8", shape=(2000, 2000)), 1, 1).merge_cap() == 1  # 4 MB: never 0


class _Merging:
    """The state ``Worker._merge_ahead`` reads, with one input whose queue grows as scripted."""

    def __init__(self, arrivals: list[int], ended: bool = False) -> None:
        self.ib = _inbound(StreamSpec(shape=(4,)), 1, 1)
        self.block_inputs = [self.ib]
        self.k, self.stop_k, self.n_ticks = 10, FOREVER, None
        self.arrivals, self.ended = arrivals, ended

    def _drain(self, ib) -> None:  # what each drain finds queued: ticks up to the next arrival
        if self.arrivals:
            ib.upto = self.arrivals.pop(0)
        ib.ended = ib.ended or (self.ended and not self.arrivals)

    # the worker's own methods, on this state
    _consumed = Worker._consumed  # noqa: SLF001
    merge = Worker._merge_ahead  # noqa: SLF001 — the method under test


def test_a_fast_consumer_that_keeps_pace_waits_for_a_batch(monkeypatch):
    """--fast: with fewer than COALESCE_TICKS ticks queued the worker waits once, then takes all
    that came (one step, one message downstream); with a batch queued, or its producer ended, it
    steps at once."""
    from flowtact.runtime import worker_ticks as worker

    waits: list[float] = []
    monkeypatch.setattr(worker.time, "sleep", waits.append)
    few = _Merging([13, 60])  # 3 ticks queued, then 50 after the wait
    few.merge()
    assert waits == [worker.COALESCE_S] and few.k == 60
    many = _Merging([10 + worker.COALESCE_TICKS])
    many.merge()
    assert waits == [worker.COALESCE_S] and many.k == 10 + worker.COALESCE_TICKS
    last = _Merging([12], ended=True)  # the producer has ended: nothing more is coming
    last.merge()
    assert waits == [worker.COALESCE_S] and last.k == 12


def test_recorded_watermarks_fold_into_the_last_chunk_kept_and_join_to_the_same_chunk():
    """An event stream ends every tick with a watermark: the record buffer grows with data only."""
    spec = StreamSpec(dtype="int64", shape=(), units="1", n_units=4)
    rng = np.random.default_rng(3)
    chunks, t = [], 0.0
    for _ in range(300):
        t += 0.001
        n = int(rng.integers(0, 3)) if rng.random() < 0.2 else 0
        times = np.sort(rng.uniform(t - 0.001, t, n))
        chunks.append(Chunk(times, rng.integers(0, 4, n), t if rng.random() < 0.9 else None))
    buf = RecordBuffer(7, spec)
    for c in chunks:
        if len(c) or c.end is not None:  # what the worker keeps for the recorder
            buf.keep(c)
    assert len(buf.chunks) <= 1 + sum(1 for c in chunks if len(c))
    joined, want = (
        buf.take(),
        concat([c for c in chunks if len(c) or c.end is not None], spec),
    )
    assert np.array_equal(joined.t, want.t) and np.array_equal(joined.data, want.data)
    assert joined.end == want.end == max(c.end for c in chunks if c.end is not None)
