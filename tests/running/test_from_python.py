"""``flowtact.run`` and ``flowtact.GraphBuilder``: runs from Python (issue 34, Deliver 4).

The oracle for "the same run" is the command line: a graph built in Python, written out and run by
``flowtact run --record``, must give the arrays ``flowtact.run`` returns, bit for bit; in-process and
multi-process runs on the virtual clock must agree as the design promises.
"""

from __future__ import annotations

import signal
import subprocess
import sys

import numpy as np
import pytest

import flowtact
from flowtact.chunk import StreamSpec
from flowtact.cli import main
from flowtact.errors import GraphFileError
from flowtact.graphfile.graph import load_graph, parse_override, shipped_graphs
from flowtact.running.builder import GraphBuilder
from flowtact.running.compile import compile_graph
from flowtact.running.from_python import compile_source, override_texts
from flowtact.running.launch import load_compiled, resolved_graph
from flowtact.running.results import Stream, read_streams


def press(duration_s: float = 0.5) -> GraphBuilder:
    """Sensor -> force -> derivative -> drive -> SA1 afferents, in two process groups."""
    g = GraphBuilder("press", seed=3, duration_s=duration_s)
    g.node("sensor", "aunp_sensor", scenario="touch", rate_hz=1000, process="sensing")
    g.node("force", "gauge_force", mode="reduced")
    g.node("dforce", "savgol", preset="touch.rager", deriv=1, mode="causal", padding="hold")
    g.node("drive", "weighted_sum", preset="touch.SA1")
    g.node("sa1", "nlif", preset="touch.SA1", n=6, process="afferents")
    g.edge("sensor.r -> force.r").edge("sensor.ref", "force.ref").edge("force.f -> dforce.x")
    g.edge("force.f -> drive.x1").edge("dforce.y -> drive.x2").edge(
        "drive.y -> sa1.x", policy="block", queue=8
    )
    return g.record("force.f", "sa1.spikes")


def same(a, b) -> bool:
    return set(a) == set(b) and all(
        np.array_equal(a[k].t, b[k].t) and np.array_equal(a[k].data, b[k].data) and a[k].spec == b[k].spec
        for k in a
    )


def test_a_built_graph_is_the_graph_file_it_writes(tmp_path):
    g = press()
    path = g.save(tmp_path / "press.yaml")
    built, written = resolved_graph(compile_graph(g.load())), resolved_graph(compile_graph(load_graph(path)))
    assert built == written
    assert built["edges"][-1] == {"from": "drive.y", "to": "sa1.x", "policy": "block", "queue": 8}


@pytest.mark.parametrize("name", shipped_graphs())
def test_a_shipped_graph_read_into_a_builder_is_unchanged(name):
    """Its files (npz currents, models) still found beside the graph file."""
    g = GraphBuilder.from_file(name)
    assert resolved_graph(compile_graph(g.load())) == resolved_graph(load_compiled(name))


def test_a_builder_changes_a_nodes_parameters():
    g = GraphBuilder.from_file("touch")
    g.set("sa1", n=3)
    assert g.load().nodes["sa1"].config.n == 3 and g.load().nodes["sa1"].config.tau_s > 0  # preset kept
    with pytest.raises(KeyError, match="no node 'sa9'"):
        g.set("sa9", n=3)


@pytest.mark.slow
def test_a_run_returns_what_the_command_line_records(tmp_path):
    g = press()
    result = flowtact.run(g, record=tmp_path / "py.h5")
    assert (
        main(
            [
                "run",
                str(g.save(tmp_path / "press.yaml")),
                "--fast",
                "--inproc",
                "--quiet",
                "--record",
                str(tmp_path / "cli.h5"),
            ]
        )
        == 0
    )
    cli = read_streams(tmp_path / "cli.h5")
    assert same(result.streams, cli) and same(result.streams, read_streams(result.path))
    assert (
        len(result["force.f"]) == 500 and result["sa1.spikes"].n_units == 6 and len(result["sa1.spikes"]) > 0
    )
    assert result.summary.stopped_by == "duration"


@pytest.mark.slow
@pytest.mark.cli
def test_processes_give_the_in_process_arrays_and_leave_the_signal_handlers_alone():
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    g = press()
    here = flowtact.run(g)
    apart = flowtact.run(g, processes=True)
    assert sorted(apart.summary.processes) == ["afferents", "sensing"]
    assert same(here.streams, apart.streams)
    assert {s: signal.getsignal(s) for s in before} == before
    assert apart.path is None  # the temporary recording is gone


def test_overrides_reach_the_nodes_as_set_does():
    plan = compile_source(press(), overrides={"sa1.n": 2, "dforce.window": 7})
    assert plan.graph.nodes["sa1"].config.n == 2 and plan.graph.nodes["dforce"].config.window == 7
    with pytest.raises(GraphFileError, match=r"--set:1:1: .*'n' must be"):
        compile_source(press(), overrides={"sa1.n": -1})


@pytest.mark.parametrize(
    "value", [1e-05, 200, "touch", [1.0, 2.5], [[1, 2], [3, 4]], "a: b", True, None, 1e300]
)
def test_an_override_value_survives_the_set_text(value):
    (text,) = override_texts({"node.p": value})
    assert parse_override(text) == ("node", "p", value)


def test_a_bad_graph_raises_its_located_error_naming_node_and_rule():
    bad = GraphBuilder("bad").node("df", "savgol", window=4)
    with pytest.raises(GraphFileError) as e:
        flowtact.run(bad)
    assert "<python graph bad>:6:15: df (savgol): 'window' must be odd; got 4" in str(e.value)


def test_a_mapping_is_a_graph_document_too():
    doc = press().document()
    assert resolved_graph(compile_source(doc)) == resolved_graph(compile_graph(press().load()))


def sample_stream(labels=("Fx", "Fy", "Fz"), categories=None, shape=(3,)) -> Stream:
    t = np.arange(4) / 1000
    data = np.arange(4 * int(np.prod(shape)), dtype=float).reshape(4, *shape) % 2
    spec = StreamSpec(shape=shape, units="N", rate_hz=1000.0, labels=labels, categories=categories)
    return Stream("force.f", t, data, spec)


def test_a_sample_stream_is_a_table_indexed_by_time_with_labelled_columns():
    s = sample_stream()
    df = s.frame()
    assert list(df.columns) == ["Fx", "Fy", "Fz"] and df.index.name == "t"
    np.testing.assert_array_equal(df.index.to_numpy(), s.t)
    np.testing.assert_array_equal(df.to_numpy(), s.data)
    assert df.attrs == {"stream": "force.f", "units": "N", "rate_hz": 1000.0}
    unlabelled = sample_stream(labels=None).frame()
    assert list(unlabelled.columns) == ["force.f[0]", "force.f[1]", "force.f[2]"]


def test_categories_become_pandas_categories_and_events_two_columns():
    s = sample_stream(labels=None, categories=("rest", "touch"), shape=())
    assert list(s.frame()["force.f"].astype(str)) == ["rest", "touch", "rest", "touch"]
    spikes = Stream(
        "sa1.spikes",
        np.array([0.1, 0.2]),
        np.array([3, 1]),
        StreamSpec(dtype="int64", events=True, n_units=4),
    )
    df = spikes.frame()
    assert list(df.columns) == ["t", "unit"] and list(df["unit"]) == [3, 1]


def test_frames_refuse_a_table_and_say_what_to_use():
    with pytest.raises(ValueError, match=r"2x3 samples \(frames\).*use .t and .data"):
        sample_stream(labels=None, shape=(2, 3)).frame()


def test_without_pandas_the_error_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "pandas", None)
    with pytest.raises(ModuleNotFoundError, match=r'pip install "flowtact\[pandas\]"'):
        sample_stream().frame()


def test_an_unknown_stream_lists_the_recorded_ones():
    result = flowtact.RunResult({"force.f": sample_stream()})
    with pytest.raises(KeyError, match=r"no recorded stream 'force.x' \(recorded: force.f\)"):
        result["force.x"]


def test_import_flowtact_stays_light_and_the_names_are_the_modules():
    code = "import sys, flowtact; print('flowtact.running.from_python' in sys.modules, 'h5py' in sys.modules)"
    out = subprocess.run(
        [sys.executable, "-P", "-c", code], capture_output=True, text=True, check=True
    ).stdout
    assert out.split() == ["False", "False"]
    from flowtact.running import from_python, results

    assert flowtact.run is from_python.run and flowtact.Stream is results.Stream
    with pytest.raises(AttributeError):
        flowtact.no_such_name  # noqa: B018


NOTEBOOK = """
import threading, numpy as np, flowtact
from flowtact.runtime.forked import can_fork
stop = threading.Event()
threading.Thread(target=stop.wait, daemon=True).start()  # a kernel's threads: no fork
assert not can_fork()
g = flowtact.GraphBuilder.from_file(PATH)
here, apart = flowtact.run(g), flowtact.run(g, processes=True)
print(sorted(apart.summary.processes), all(
    np.array_equal(here[k].t, apart[k].t) and np.array_equal(here[k].data, apart[k].data) for k in here))
stop.set()
"""


@pytest.mark.slow
@pytest.mark.cli
@pytest.mark.timeout(900)
def test_a_process_with_threads_starts_its_workers_as_fresh_interpreters(tmp_path):
    """As from a notebook kernel (threads running: a fork could inherit a held lock)."""
    path = press().save(tmp_path / "press.yaml")
    code = f"PATH = {str(path)!r}\n" + NOTEBOOK
    done = subprocess.run(
        [sys.executable, "-P", "-c", code], capture_output=True, text=True, timeout=850, cwd=tmp_path
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.split("\n")[0] == "['afferents', 'sensing'] True"
