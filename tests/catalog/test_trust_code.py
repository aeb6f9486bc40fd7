"""Files from others stay data (issue 30, "code runs that nobody asked for").

A graph, a recording's stored graph, ``--set`` and ``--replay`` never make flowtact import a module
the user did not allow on the command line (``--allow-module``; ``allow_modules=`` in Python), and
the Python children flowtact starts (workers, emulators, benchmark parts) never import from the
working directory. Each refusal is checked by a module that leaves a marker file when imported.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from runs import TESTS

from flowtact.catalog.blocks import module_allowed
from flowtact.errors import GraphFileError
from flowtact.graphfile.graph import load_graph
from flowtact.running.python_child import python_command

MARKING = """
import pathlib
pathlib.Path({mark!r}).write_text("imported")
from toyblocks import Ramp, Scale
"""

GRAPH = """\
duration_s: 0.2
nodes:
  src:  {block: "evilblocks:Ramp", process: a}
  gain: {block: "evilblocks:Scale", process: b}
edges: [src.y -> gain.x]
record: [gain.y]
"""
REFUSAL = (
    "node 'src': block 'evilblocks:Ramp' names a Python module; flowtact imports only registered "
    "blocks unless you allow it: --allow-module evilblocks"
)


@pytest.fixture
def evil(tmp_path: Path) -> tuple[Path, Path]:
    """(a graph naming ``evilblocks:Ramp``, the file that module writes when it is imported)."""
    mods = tmp_path / "mods"
    mods.mkdir()
    mark = tmp_path / "IMPORTED"
    (mods / "evilblocks.py").write_text(MARKING.format(mark=str(mark)))
    graph = tmp_path / "g.yaml"
    graph.write_text(GRAPH)
    return graph, mark


def flowtact(*args: str, cwd: Path, path: Path | None = None) -> subprocess.CompletedProcess[str]:
    """``flowtact ARGS`` through the installed console script, as a user types it."""
    exe = Path(sys.executable).parent / "flowtact"
    argv = [str(exe)] if exe.exists() else [sys.executable, "-m", "flowtact.cli"]
    parts = [str(path) if path else "", str(TESTS), os.environ.get("PYTHONPATH", "")]
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join(p for p in parts if p),
    }  # an empty entry would be the cwd
    return subprocess.run([*argv, *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=300)


@pytest.mark.parametrize("command", [["validate"], ["run", "--fast"], ["graph", "-o", "g.svg"]])
def test_a_graph_naming_a_module_is_refused_and_nothing_is_imported(evil, command):
    graph, mark = evil
    done = flowtact(command[0], str(graph), *command[1:], cwd=graph.parent, path=graph.parent / "mods")
    assert done.returncode == 2, done.stderr
    first = done.stderr.splitlines()[0]
    assert first == f"{graph}:3:17: {REFUSAL}", done.stderr
    assert "Traceback" not in done.stderr
    assert not mark.exists()  # the module never ran
    assert not (graph.parent / "g.svg").exists()


def test_allowing_the_module_runs_it_across_processes_and_a_recording_never_widens_it(evil):
    graph, mark = evil
    mods, rec = graph.parent / "mods", graph.parent / "r.h5"
    done = flowtact("run", str(graph), "--fast", "--quiet", "--record", str(rec), "--allow-module", "evilblocks",
                    cwd=graph.parent, path=mods)  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert mark.exists() and rec.exists()  # two worker processes loaded it with the user's permission
    mark.unlink()
    for command in (["run", str(rec), "--fast", "--quiet"], ["validate", str(rec)]):
        done = flowtact(*command, cwd=graph.parent, path=mods)
        assert done.returncode == 2, done.stderr
        assert REFUSAL in done.stderr and "Traceback" not in done.stderr, done.stderr
        assert f"{rec}#graph:" in done.stderr
        assert not mark.exists()  # re-running someone's recording imports nothing it names
    done = flowtact(
        "run", str(rec), "--fast", "--quiet", "--allow-module", "evilblocks", cwd=graph.parent, path=mods
    )
    assert done.returncode == 0, done.stderr


def test_replay_and_set_do_not_import_a_module_either(evil):
    graph, mark = evil
    csv = graph.parent / "log.csv"
    csv.write_text("t,y\n0,1\n0.001,2\n")
    mods = graph.parent / "mods"
    done = flowtact("validate", str(graph), "--replay", f"src={csv}", "--set", "gain.gain=2", cwd=graph.parent,
                    path=mods)  # fmt: skip
    assert done.returncode == 2, done.stderr
    assert "--allow-module evilblocks" in done.stderr and "Traceback" not in done.stderr
    assert not mark.exists()


def test_a_stored_replay_stand_in_does_not_smuggle_a_module_in(evil, monkeypatch):
    graph, mark = evil
    monkeypatch.syspath_prepend(str(graph.parent / "mods"))
    text = 'nodes:\n  src: {block: "flowtact.blocks.signal.replay_ports:evilblocks:Ramp", params: {path: x.csv}}\n'
    with pytest.raises(GraphFileError, match="--allow-module evilblocks"):
        load_graph("rec.h5#graph", text=text)
    assert "evilblocks" not in sys.modules and not mark.exists()


def test_the_python_api_takes_allow_modules(evil, monkeypatch):
    graph, mark = evil
    monkeypatch.syspath_prepend(str(graph.parent / "mods"))
    with pytest.raises(GraphFileError) as e:
        load_graph(graph)
    gain = REFUSAL.replace("'src'", "'gain'").replace(":Ramp", ":Scale")
    assert str(e.value).splitlines() == [f"{graph}:3:17: {REFUSAL}", f"{graph}:4:17: {gain}"]
    assert "evilblocks" not in sys.modules and not mark.exists()
    assert set(load_graph(graph, allow_modules=["evilblocks"]).nodes) == {"src", "gain"}
    assert mark.exists()


@pytest.mark.parametrize(
    ("module", "allow", "ok"),
    [
        ("mypkg", ["mypkg"], True),
        ("mypkg.blocks.x", ["mypkg"], True),  # a package allows the modules inside it
        ("mypkg.blocks", ["mypkg.blocks"], True),
        ("mypkgx", ["mypkg"], False),  # a prefix of the name is not a package
        ("mypkg", ["mypkg.blocks"], False),  # nor does a module allow its package
        ("mypkg", [], False),
    ],
)
def test_what_an_allowed_module_covers(module, allow, ok):
    assert module_allowed(module, allow) is ok


def test_the_flag_takes_module_names_only(evil):
    graph, _ = evil
    done = flowtact("validate", str(graph), "--allow-module", "../evil", cwd=graph.parent)
    assert done.returncode == 2
    assert "argument --allow-module: '../evil' is not a module name" in done.stderr
    assert "Traceback" not in done.stderr


POISON = (
    "import pathlib; pathlib.Path({mark!r}).write_text('imported'); raise SystemExit('poisoned {name}')\n"
)


def test_workers_ignore_a_poisoned_working_directory(tmp_path):
    for name in ("msgpack", "numpy", "zmq", "yaml"):  # each imported by every worker
        (tmp_path / f"{name}.py").write_text(POISON.format(mark=str(tmp_path / f"MARK-{name}"), name=name))
    done = flowtact("run", "touch", "--fast", "--duration", "0.5", "--quiet", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert sorted(p.name for p in tmp_path.glob("MARK-*")) == []


@pytest.mark.parametrize("executor", ["local", "dask"])
def test_a_sweep_pool_ignores_a_poisoned_working_directory(tmp_path, executor):
    pytest.importorskip("pandas")
    pytest.importorskip("pyarrow")
    if executor == "dask":
        pytest.importorskip("distributed")
    for name in ("struct", "threading", "socket", "selectors"):  # what multiprocessing's helpers import first
        (tmp_path / f"{name}.py").write_text(POISON.format(mark=str(tmp_path / f"MARK-{name}"), name=name))
    done = flowtact("sweep", "touch", "--set-grid", "sa1.tau_s=0.005,0.01", "--duration", "0.2", "--workers", "1",
                    "--executor", executor, "--quiet", cwd=tmp_path)  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert sorted(p.name for p in tmp_path.glob("MARK-*")) == []


def test_python_children_leave_the_working_directory_off_their_path_and_keep_pythonpath(tmp_path):
    mine = tmp_path / "mine"
    code = "import json, sys; print(json.dumps(sys.path))"
    env = {**os.environ, "PYTHONPATH": str(mine)}
    out = subprocess.run(python_command("-c", code), cwd=tmp_path, env=env, capture_output=True, text=True,
                         check=True, timeout=60).stdout  # fmt: skip
    path = json.loads(out)
    assert "" not in path and str(tmp_path) not in path
    assert str(mine) in path


def test_a_sweep_refuses_the_module_before_any_run(evil, monkeypatch):
    pytest.importorskip("pandas")
    pytest.importorskip("pyarrow")
    import flowtact

    graph, mark = evil
    monkeypatch.syspath_prepend(str(graph.parent / "mods"))
    with pytest.raises(GraphFileError, match="--allow-module evilblocks"):
        flowtact.sweep(graph, grid={"gain.gain": [1.0, 2.0]}, workers=1)
    assert not mark.exists()


REMOTE = """\
duration_s: 0.5
nodes:
  src:  {{block: "evilblocks:Ramp", process: a}}
  gain: {{block: "evilblocks:Scale", process: b}}
edges: [src.y -> gain.x]
processes:
  b: {{host: 127.0.0.1}}
network: {{listen: 127.0.0.1, port: {port}, keys: keys}}
record: [gain.y]
"""
WHO = """
import pathlib, sys
with open({mark!r}, "a") as f:
    f.write(" ".join(sys.argv) + "\\n")
from toyblocks import Ramp, Scale
"""


@pytest.mark.slow
def test_a_worker_on_another_host_imports_only_what_its_own_command_line_allows(tmp_path):
    """The supervisor's --allow-module does not reach a worker started by hand on another host."""
    import socket

    from flowtact.runtime.links.zeromq.security import generate_keys

    generate_keys(tmp_path / "keys")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    mods, mark = tmp_path / "mods", tmp_path / "who"
    mods.mkdir()
    (mods / "evilblocks.py").write_text(WHO.format(mark=str(mark)))
    (tmp_path / "g.yaml").write_text(REMOTE.format(port=port))
    exe = Path(sys.executable).parent / "flowtact"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(mods), str(TESTS)])}
    env.pop("FLOWTACT_KEYS", None)
    run = [str(exe), "run", "g.yaml", "--fast", "--quiet", "--allow-module", "evilblocks"]
    sup = subprocess.Popen(run, cwd=tmp_path, env=env, stderr=subprocess.PIPE, text=True)
    line = sup.stderr.readline()  # the first line says how to start the remote group
    assert "--process b --allow-module evilblocks`" in line, line
    worker = subprocess.run([str(exe), "worker", f"tcp://127.0.0.1:{port}", "--process", "b", "--keys", "keys"],
                            cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)  # fmt: skip
    _, err = sup.communicate(timeout=120)
    assert worker.returncode == 1 and sup.returncode == 1
    assert "process 'b' (nodes gain) ModuleNotAllowedError: block 'evilblocks:Scale'" in err, err
    assert [
        w for w in mark.read_text().splitlines() if " worker " in w
    ] == []  # the remote worker never imported it


def test_modules_of_installed_block_packages_need_no_flag_but_never_a_main():
    from flowtact.catalog.blocks import load_block
    from flowtact.errors import ModuleNotAllowedError

    # what --replay writes into a graph (and so into recordings): loads without a flag
    stand_in = load_block("flowtact.blocks.signal.replay_ports:aunp_sensor")
    assert stand_in.outputs.keys() == load_block("aunp_sensor").outputs.keys()
    assert load_block("flowtact.blocks.signal.savgol:SavGol") is load_block("savgol")
    with pytest.raises(ModuleNotAllowedError, match=r"--allow-module flowtact\.blocks\.signal\.__main__$"):
        load_block("flowtact.blocks.signal.__main__:X")  # a package's command, never run by a graph
