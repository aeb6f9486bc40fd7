"""The warm-up loads or compiles every kernel a run calls before the clock starts, and says so.

Offline tests check numba's own record (a dispatcher's ``signatures``) after a warm-up against the
signatures real input brings: messages through the real wire, every registered block's example
fed in chunks of 1 and 7, read-only and unaligned. Process tests run ``flowtact run`` and wait for
what the run prints: a compile announced while warming, and one after the start told as a stall.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numba
import numpy as np
import pytest
import zmq
from numba.core.registry import CPUDispatcher
from runs import env, flowtact
from warmblocks import JitScale, SlowWarmUp, scale_kernel

from flowtact.block import Source
from flowtact.catalog.blocks import block_names, load_block
from flowtact.chunk import Chunk, StreamSpec
from flowtact.runtime.links.zeromq.wire import recv_message, send_message
from flowtact.runtime.warm_up import CompileWatch, _unaligned, synthetic_inputs, warm_up
from flowtact.testing import example_of, infer_specs, run_offline, run_source

SPEC = StreamSpec(dtype="float64", shape=(3,), rate_hz=1000.0)


def _bound(cls, **params):
    block = cls(cls.config_cls.build(params, owner="n"), node="n")
    block.bind({"x": SPEC})
    return block


def test_warm_up_compiles_the_signatures_wire_messages_bring():
    real = _bound(JitScale)
    report = warm_up({"n": real}, 0.005)
    assert report.skipped == {}
    readonly = numba.typeof(_unaligned(np.zeros((2, 3))))
    assert not readonly.mutable
    warmed = set(scale_kernel.signatures)
    assert (readonly, numba.float64) in warmed  # blocks get read-only views: another numba type
    ctx = zmq.Context()
    push, pull = ctx.socket(zmq.PUSH), ctx.socket(zmq.PULL)
    pull.bind("inproc://warm")
    push.connect("inproc://warm")
    try:
        for seq, n in enumerate([1, 2, 3, 5, 8, 13, 200, 1, 1, 7]):  # headers of varied length
            t = (np.arange(n) + 10 * seq) / 1000.0
            send_message(push, 1, seq * 997, seq, Chunk(t, np.ones((n, 3))), {0: 123456789 * seq})
            m = recv_message(pull)
            real(x=m.chunk)
    finally:
        ctx.destroy(linger=0)
    assert set(scale_kernel.signatures) == warmed


def test_compile_watch_counts_compilations_not_calls():
    firsts = []
    watch = CompileWatch(on_first=firsts.append).install()
    try:
        fresh = numba.njit(lambda a: a + 1)
        fresh(np.zeros(2))
        fresh(np.zeros(3))
        assert watch.count == 1 and watch.current is None and watch.seconds > 0
        fresh(np.zeros(2, np.int32))  # a new signature compiles again
        assert watch.count == 2
        assert firsts == ["test_warm_up.<lambda>"]
    finally:
        watch.uninstall()


def test_a_blocks_warm_up_hook_runs_and_its_compiles_are_counted():
    report = warm_up({"n": _bound(SlowWarmUp, kernels=3)}, 0.005)
    assert report.skipped == {}
    assert report.compiled["n"] >= 3


def test_synthetic_inputs_cover_the_interval_at_the_streams_rate():
    ins = synthetic_inputs({"x": SPEC, "e": StreamSpec(dtype="int64", events=True, n_units=4)}, 0.01, 0.015)
    assert ins["x"].t.tolist() == pytest.approx([0.011, 0.012, 0.013, 0.014, 0.015])
    assert ins["x"].data.shape == (5, 3) and ins["x"].data.max() == 1.0
    assert ins["e"].end == 0.015 and set(ins["e"].data.tolist()) == {0, 1, 2, 3}


def _dispatchers():
    return [
        v
        for name, mod in list(sys.modules.items())
        if name.startswith("flowtact.blocks")
        for v in list(vars(mod).values())
        if isinstance(v, CPUDispatcher)
    ]


def _feed(cls, ex, block_specs, chunk, unaligned):
    block = cls(**ex.params)
    if issubclass(cls, Source):
        rate = float(ex.params.get("rate_hz", ex.rate_hz))
        return run_source(
            block, min(ex.duration_s, 0.2), tick_s=[chunk / rate], inputs=ex.inputs, rate_hz=ex.rate_hz
        )
    ins = {k: _unaligned(v) if unaligned and isinstance(v, np.ndarray) else v for k, v in ex.inputs.items()}
    return run_offline(block, chunk=chunk, rate_hz=ex.rate_hz, specs=block_specs, **ins)


def missed_signatures(name: str) -> dict[str, list[str]]:
    """Kernel signatures ``name``'s example brings (chunks of 1 and 7, aligned or not) that its warm-up did not load."""
    cls = load_block(name)
    ex = example_of(cls)
    real = cls(**ex.params)
    specs = {} if issubclass(cls, Source) else infer_specs(real, ex.inputs, ex.rate_hz, ex.units)
    real.bind(specs)
    if warm_up({name: real}, 0.005).skipped:
        return {}  # needs open(): documented as warmed by its own warm_up() or not at all
    warmed = {d: set(d.signatures) for d in _dispatchers()}
    for chunk, unaligned in ((1, True), (7, False), (7, True)):
        _feed(cls, ex, specs, chunk, unaligned)
    return {
        d.py_func.__qualname__: sorted(map(str, set(d.signatures) - warmed.get(d, set())))
        for d in _dispatchers()
        if set(d.signatures) - warmed.get(d, set())
    }


def main() -> None:
    """Print, as JSON, what each registered block's warm-up missed (a fresh process: nothing loaded yet)."""
    print(json.dumps({n: m for n in block_names() if (m := missed_signatures(n))}))


@pytest.mark.slow
def test_no_blocks_example_calls_a_kernel_signature_its_warm_up_missed():
    # in a fresh process: kernels loaded by earlier tests in this one would hide a miss
    code = "import test_warm_up as t; t.main()"
    child_env = env()
    child_env["PYTHONPATH"] = os.pathsep.join([str(Path(__file__).resolve().parent), child_env["PYTHONPATH"]])
    done = subprocess.run(
        [sys.executable, "-c", code], env=child_env, capture_output=True, text=True, timeout=900
    )
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout.strip().splitlines()[-1]) == {}


SHARED = """
import sys
from pathlib import Path
import numpy as np
from flowtact.chunk import StreamSpec
from flowtact.finite import all_finite
from flowtact.runtime.warm_up import CompileWatch, _unaligned, warm_shared_kernels
spec = StreamSpec(dtype="float64", shape=(3,), rate_hz=1000.0)
if sys.argv[1] == "supervisor":
    print(warm_shared_kernels([spec]))
else:  # a worker's bad-data screen on the inputs it gets: read-only, aligned or not
    watch = CompileWatch().install()
    for n in (1, 7, 2000):  # 2000 x 3: a wide tick, the vectorised test
        a = np.ones((n, 3))
        a.setflags(write=False)
        all_finite(a)
        all_finite(_unaligned(a))
    print(watch.count)
"""


def _compiled(role: str, cache) -> int:
    run = subprocess.run(
        [sys.executable, "-c", SHARED, role],
        env={**env(), "NUMBA_CACHE_DIR": str(cache)},
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stderr
    return int(run.stdout.split()[-1])


@pytest.mark.slow
def test_kernels_every_worker_shares_are_compiled_once_before_the_workers_start(tmp_path):
    assert _compiled("worker", tmp_path / "alone") > 0  # a worker on a fresh install compiles them
    assert _compiled("supervisor", tmp_path / "warmed") > 0  # ... unless the supervisor did first:
    assert _compiled("worker", tmp_path / "warmed") == 0  # then every worker loads them from the cache


# -- through flowtact run ---------------------------------------------------------------------

GRAPH = """
name: warm
nodes:
  src:   {block: "toyblocks:Ramp", process: source, params: {channels: 2}}
  gain:  {block: "toyblocks:Scale", process: work, params: {gain: 100.0}}
  scale: {block: "warmblocks:BLOCK", process: work, params: PARAMS}
edges: [src.y -> gain.x, gain.y -> scale.x]
record: [scale.y]
processes:
  work: {startup_s: STARTUP}
"""


def _graph(tmp_path, block="JitScale", params="{}", startup=60):
    path = tmp_path / "warm.yaml"
    path.write_text(GRAPH.replace("BLOCK", block).replace("PARAMS", params).replace("STARTUP", str(startup)))
    return str(path)


@pytest.mark.slow
def test_a_worker_that_compiles_says_so_before_the_start_and_not_after(tmp_path):
    proc = flowtact("run", _graph(tmp_path), "--duration", "1", "--quiet")
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    assert (
        "process 'work' (nodes gain, scale): compiling kernels for scale (first run after an install" in err
    )
    assert re.search(r"process 'work' \(nodes gain, scale\): \d+ kernels? compiled in [\d.]+ s", err), err
    assert "after the start" not in err, err


@pytest.mark.slow
def test_a_kernel_first_compiled_after_the_start_is_told_as_a_stall(tmp_path):
    # the ramp reaches 50 (gain 100) at t = 0.5 s: only then does above_kernel run, and compile
    proc = flowtact("run", _graph(tmp_path, "LateKernel", "{level: 50.0}"), "--duration", "1.5", "--quiet")
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    assert (
        "process 'work' (nodes gain, scale): compiling kernel warmblocks.above_kernel in node 'scale' after the start"
        in err
    )


@pytest.mark.slow
def test_a_worker_compiling_longer_than_its_startup_window_is_not_killed(tmp_path):
    startup_s = 1.0  # the 40 kernels take about 3 s to compile on an idle 2-core machine
    graph = _graph(tmp_path, "SlowWarmUp", "{kernels: 40}", startup=startup_s)
    proc = flowtact("run", graph, "--duration", "0.5", "--quiet")
    _, err = proc.communicate(timeout=600)
    assert proc.returncode == 0, err
    took = float(re.search(r"(\d+) kernels? compiled in ([\d.]+) s", err).group(2))
    assert took > startup_s, f"the warm-up took {took} s: not longer than startup_s, the test proves nothing"


@pytest.mark.slow
def test_a_worker_warming_up_longer_than_its_window_joins_while_it_reports_progress(tmp_path):
    # six warm-up steps of 0.4 s each: 2.4 s of warm-up (sleeps, not compiling) against a window of
    # 1.5 s without progress; each step is a start-up report that restarts the window
    graph = _graph(tmp_path, "Slow", "{step_s: 0.4}", startup=1.5)
    proc = flowtact("run", graph, "--fast", "--duration", "1", "--quiet")
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    assert "did not join" not in err


@pytest.mark.slow
def test_a_worker_without_start_up_progress_is_named_with_how_to_widen_its_window(tmp_path):
    # open() hangs without a word; --startup-s replaces the graph's window of 600 s
    graph = _graph(tmp_path, "Slow", "{open_s: 600}", startup=600)
    proc = flowtact("run", graph, "--fast", "--duration", "1", "--startup-s", "2")
    _, err = proc.communicate(timeout=120)  # a hang bound: the graph's own window would take 600 s
    assert proc.returncode == 1, err
    assert "process 'work' (nodes gain, scale) did not join: no start-up progress for" in err, err
    assert "(its start-up window, 2 s) while opening node 'scale'" in err, err
    assert "widen the window with --startup-s S or startup_s under processes: work: in the graph" in err, err
    assert len(err.strip().splitlines()) == 1, err  # one line, no traceback


@pytest.mark.slow
def test_an_inprocess_real_time_run_warms_up_and_says_so(tmp_path):
    proc = flowtact("run", _graph(tmp_path), "--inproc", "--duration", "0.5", "--quiet")
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    assert "compiling kernels for scale (first run after an install" in err
    assert re.search(r"\d+ kernels? compiled in [\d.]+ s", err), err
