"""``--debug`` / FLOWTACT_DEBUG=1 print a failing block's traceback, in process and from a worker."""

import io
import subprocess
import sys

import pytest
from runs import allow_args, env, flowtact

from flowtact.console.debug import HINT, debug_enabled, print_error
from flowtact.errors import NodeError, WorkerFailed

BOOM = """
name: boom
nodes:
  src:  {block: "toyblocks:Ramp", process: source}
  boom: {block: "brokenblocks:Boom", process: worker, params: {at_s: 0.5}}
edges: [src.y -> boom.x]
record: [boom.y]
"""
LINE = "flowtact: error: node 'boom' (boom) failed at t=1.000 s"


def run(*args, environ=None):
    if environ is None:
        proc = flowtact(*args)
        out, err = proc.communicate(timeout=120)
        return proc.returncode, out, err
    done = subprocess.run(
        [sys.executable, "-m", "flowtact.cli", *allow_args(args)],
        capture_output=True,
        text=True,
        env=environ,
        timeout=120,
    )
    return done.returncode, done.stdout, done.stderr


@pytest.fixture
def boom(tmp_path):
    path = tmp_path / "boom.yaml"
    path.write_text(BOOM)
    return str(path)


@pytest.mark.cli
@pytest.mark.parametrize("mode", [["--inproc"], []], ids=["inproc", "workers"])
def test_without_debug_one_line_that_offers_the_traceback(boom, mode):
    code, _, err = run("run", boom, "--fast", "--duration", "2", "--quiet", *mode)
    assert code == 1
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(LINE) and lines[0].endswith(f"ZeroDivisionError: boom at t=0.999 {HINT}")
    assert "Traceback" not in err


@pytest.mark.cli
@pytest.mark.parametrize("mode", [["--inproc"], []], ids=["inproc", "workers"])
def test_debug_prints_the_blocks_own_traceback_after_the_line(boom, mode):
    code, _, err = run("run", boom, "--fast", "--duration", "2", "--quiet", "--debug", *mode)
    assert code == 1
    first, rest = err.split("\n", 1)
    assert first.startswith(LINE) and HINT not in first
    assert rest.startswith("Traceback (most recent call last):")
    # the frames inside the block, down to the line that raised, and the exception itself
    assert 'brokenblocks.py", line' in rest and "in _explode" in rest and "self._explode(" in rest
    assert rest.rstrip().endswith("ZeroDivisionError: boom at t=0.999")
    if not mode:
        assert "flowtact/runtime/worker_watch.py" in rest  # formatted in the worker, sent to the supervisor


@pytest.mark.cli
def test_the_environment_variable_and_the_global_flag_do_the_same(boom):
    e = env()
    e["FLOWTACT_DEBUG"] = "1"
    code, _, err = run("run", boom, "--fast", "--duration", "2", "--quiet", "--inproc", environ=e)
    assert code == 1 and "in _explode" in err
    code, _, err = run("--debug", "run", boom, "--fast", "--duration", "2", "--quiet", "--inproc")
    assert code == 1 and "in _explode" in err


@pytest.mark.cli
def test_validate_a_graph_whose_block_has_a_bug(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text(
        'nodes:\n  src: {block: "toyblocks:Ramp"}\n  bad: {block: "brokenblocks:BadSpecs"}\nedges: [src.y -> bad.x]\n'
    )
    code, _, err = run("validate", str(path))
    assert code == 1 and err.strip().endswith(HINT) and "Traceback" not in err, err
    assert f"error: {path}:3:3: node 'bad' (bad_specs): specs() raised ZeroDivisionError" in err, err
    code, _, err = run("validate", str(path), "--debug")
    assert code == 1 and "in specs" in err and "1 // 0" in err


def test_print_error_shows_the_cause_of_an_in_process_failure():
    try:
        1 / 0  # noqa: B018 — the failure under test
    except ZeroDivisionError as cause:
        e = NodeError("n", "blk", 0.5, cause)
    out = io.StringIO()
    print_error(f"flowtact: error: {e}", e, debug=True, file=out)
    line, tb = out.getvalue().split("\n", 1)
    assert line == "flowtact: error: node 'n' (blk) failed at t=0.500 s: ZeroDivisionError: division by zero"
    assert tb.startswith("Traceback") and "1 / 0" in tb


def test_a_stalled_worker_has_no_traceback_to_offer():
    out = io.StringIO()
    print_error("flowtact: error: stalled", WorkerFailed("stalled"), debug=False, file=out)
    assert out.getvalue() == "flowtact: error: stalled\n"
    out = io.StringIO()
    print_error(
        "flowtact: error: x", WorkerFailed("x", "Traceback (most recent call last):\n  ...\n"), True, out
    )
    assert out.getvalue() == "flowtact: error: x\nTraceback (most recent call last):\n  ...\n"


@pytest.mark.parametrize(("value", "on"), [("1", True), ("true", True), ("0", False), ("", False)])
def test_flowtact_debug_values(monkeypatch, value, on):
    monkeypatch.setenv("FLOWTACT_DEBUG", value)
    assert debug_enabled() is on
    assert debug_enabled(True)
