"""Hostile graphs and command-line misuse are refused at their place, exit 2, without a traceback,
within a bounded time and memory; missing optional packages are refused before anything starts.

The static corpus is tests/graphfile/graphs/bad/ (test_malformed_graphs.py); the cases here are generated
(too large to keep), command lines, or need a changed environment.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from hostile import CASES, ROOT, TOUCH, run_measured

from flowtact.blocks.spiking.nlif import Nlif
from flowtact.cli import main
from flowtact.errors import ConfigError, SafeYamlError
from flowtact.graphfile.extras import module_available
from flowtact.graphfile.safe_yaml import MAX_GRAPH_BYTES, load_value, read_graph_text
from flowtact.inputs.limits import STATE_BUDGET_BYTES, host_problem

PEAK_MIB = 500  # the bound on a refusal's peak memory


@pytest.mark.parametrize("case", sorted(CASES), ids=str)
def test_a_hostile_input_is_refused_located_in_bounded_memory(case, tmp_path):
    args, expect = CASES[case](tmp_path)
    m = run_measured(args, timeout_s=120)  # a hang fails here; wall time is measured by the bench
    assert m.returncode == 2, m.stderr
    assert expect in m.stderr, m.stderr
    assert "Traceback" not in m.stderr
    assert m.stderr.splitlines()[0].count(":") >= 3  # file:line:col: message
    assert m.peak_mib < PEAK_MIB, f"{case}: peak RSS {m.peak_mib:.0f} MiB"


CLI_MISUSE = [
    (["run", TOUCH, "--duration", "-1"], "argument --duration: must be a finite number of seconds > 0"),
    (["run", TOUCH, "--duration", "0"], "argument --duration: must be a finite number of seconds > 0"),
    (["run", TOUCH, "--duration", "nan"], "argument --duration: must be a finite number of seconds > 0"),
    (["run", TOUCH, "--duration", "inf"], "argument --duration: must be a finite number of seconds > 0"),
    (["run", TOUCH, "--duration", "3s"], "argument --duration: expected a number of seconds, got '3s'"),
    (["run", TOUCH, "--tick", "0"], "argument --tick: must be a finite number of seconds > 0"),
    (["run", TOUCH, "--tick", "inf"], "argument --tick: must be a finite number of seconds > 0"),
    (["run", TOUCH, "--tick", "-0.005"], "argument --tick: must be a finite number of seconds > 0"),
    (["run", TOUCH, "--tick", "3600"], "argument --tick: must be at most 10 s"),
    (["plot", "x.h5", "-o", "x.png", "--from", "nan"], "argument --from: must be a finite number of seconds"),
    (["plot", "x.h5", "-o", "x.png", "--to=-inf"], "argument --to: must be a finite number of seconds"),
    (["plot", "x.h5", "-o", "x.png", "--from", "2", "--to", "1"], "--from (2) must be before --to (1)"),
]


@pytest.mark.parametrize("argv,text", CLI_MISUSE, ids=lambda a: " ".join(a) if isinstance(a, list) else "")
def test_a_bad_flag_is_a_one_line_usage_error(argv, text, capsys):
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert text in err
    assert "Traceback" not in err


SET_MISUSE = [
    (
        "sa1.n=99999999999999",
        "--set:1:1: sa1 (nlif): 'n' must be small enough for the block's state to fit in 1.0 GiB",
    ),
    ("sa1.n=1e12", "--set:1:1: sa1 (nlif): 'n' must be an integer; got '1e12'"),
    ("sa1.tau_s=.nan", "--set:1:1: sa1 (nlif): 'tau_s' must be a finite number; got nan"),
    ("dforce.window=1000001", "--set:1:1: dforce (savgol): 'window' must be <= 10001; got 1000001"),
    ("sa1.n=&r [*r]", "the value is not valid YAML (recursive alias '*r' (it refers to itself))"),
    ("sa1.n={? [a, b]: 1}", "the value is not valid YAML (a mapping key must be a plain value"),
    ("sa1.n=[1", "the value is not valid YAML (YAML syntax error"),
    ("sa1.n=!!python/name:os.system", "the value is not valid YAML (unsupported YAML value"),
    ("sa1.n", "--set:1:1: --set 'sa1.n': expected node.param=value"),
    ("sa9.n=3", "--set:1:1: --set 'sa9.n=3': unknown node 'sa9' (did you mean 'sa1'?)"),
    ("sa1.tau_s=2020-13-45", "the value is not valid YAML (unsupported YAML value: month must be in 1..12)"),
]


@pytest.mark.parametrize("override,text", SET_MISUSE, ids=[s for s, _ in SET_MISUSE])
def test_a_bad_override_is_refused_located(override, text, capsys):
    assert main(["validate", TOUCH, "--set", override]) == 2
    err = capsys.readouterr().err
    assert text in err, err
    assert "Traceback" not in err


def test_a_missing_or_unreadable_graph_is_located(tmp_path, capsys):
    assert main(["validate", str(tmp_path / "nope.yaml")]) == 2
    assert f"{tmp_path / 'nope.yaml'}:1:1: no such graph file" in capsys.readouterr().err
    assert main(["validate", str(tmp_path)]) == 2
    assert f"{tmp_path}:1:1: not a regular file" in capsys.readouterr().err


def test_the_size_limit_is_a_bounded_read(tmp_path):
    just = tmp_path / "just.yaml"
    just.write_bytes(b"nodes: {}\n" + b"#" * (MAX_GRAPH_BYTES - 11) + b"\n")
    assert read_graph_text(just).startswith("nodes: {}")  # exactly at the limit: read
    just.write_bytes(just.read_bytes() + b"#")
    with pytest.raises(SafeYamlError, match="graph file larger than 1 MiB"):
        read_graph_text(just)


def test_a_bad_byte_is_located_by_line_and_character_column(tmp_path):
    path = tmp_path / "g.yaml"
    path.write_bytes("name: ünï\ndescription: ça\xa0va \x01\n".encode())
    with pytest.raises(SafeYamlError) as e:
        read_graph_text(path)
    assert (e.value.line, e.value.col) == (2, 20) and "U+0001" in e.value.message
    path.write_bytes(b"name: ok\nnodes:\n  a\xffb: {}\n")
    with pytest.raises(SafeYamlError) as e:
        read_graph_text(path)
    assert (e.value.line, e.value.col) == (3, 4) and "0xff" in e.value.message


def test_aliases_still_work_within_the_limits():
    assert load_value("[&a [1, 2], *a, *a]") == [[1, 2], [1, 2], [1, 2]]
    with pytest.raises(SafeYamlError, match="recursive alias"):
        load_value("&a {x: *a}")


def test_the_state_budget_refuses_before_anything_is_allocated():
    import tracemalloc

    tracemalloc.start()
    try:
        with pytest.raises(ConfigError) as e:
            Nlif.configure({"preset": "touch.SA1", "n": 10**12})
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert e.value.field == "n" and "1.0 GiB" in str(e.value)
    assert peak < 50 << 20
    per_neuron = sum(Nlif.configure({"preset": "touch.SA1", "n": 1}).state_bytes().values())
    n_max = int(STATE_BUDGET_BYTES // per_neuron)
    assert 100_000 < n_max < 1_000_000  # SA1 keeps a post-spike history ring per neuron
    assert Nlif.configure({"preset": "touch.SA1", "n": n_max}).n == n_max
    with pytest.raises(ConfigError, match="'n' must be small enough"):
        Nlif.configure({"preset": "touch.SA1", "n": 2 * n_max})


@pytest.mark.parametrize(
    "host", ["10.0.0.2", "::1", "fe80::1", "rig-2.lab.example.org", "localhost", "rig.", "a" * 63]
)
def test_valid_hosts(host):
    assert host_problem(host) is None


@pytest.mark.parametrize(
    "host",
    [
        "10.0.0.2; touch x",
        "$(reboot)",
        "a b",
        "-rig",
        "rig-",
        "",
        "a" * 64,
        "a..b",
        "10.0.0.2:5550",
        10,
        None,
    ],
)
def test_invalid_hosts(host):
    assert host_problem(host) is not None


# -- extras: a graph needing a package that is not installed is refused before it starts -------------


def _hiding(tmp_path: Path, *modules: str) -> dict[str, str]:
    """An environment whose Python cannot import ``modules`` (a sitecustomize marks them missing)."""
    shim = tmp_path / "shim"
    shim.mkdir(exist_ok=True)
    (shim / "sitecustomize.py").write_text(
        "import sys\n" + "".join(f"sys.modules[{m!r}] = None\n" for m in modules)
    )
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(shim), os.environ.get("PYTHONPATH", "")])}


def _flowtact(env: dict[str, str], *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "flowtact.cli", *args],
        capture_output=True,
        text=True,
        env=env,
        cwd=ROOT,
        timeout=300,
    )


@pytest.mark.parametrize("command", ["validate", "run"])
def test_teleop_without_pyserial_is_refused_before_start(command, tmp_path):
    env = _hiding(tmp_path, "serial")
    extra = ["--fast", "--duration", "0.5", "--record", str(tmp_path / "r.h5")] if command == "run" else []
    proc = _flowtact(env, command, "graphs/teleop.yaml", *extra)
    assert proc.returncode == 2, proc.stderr
    assert (
        "graphs/teleop.yaml:14:3: node 'exo': block serial_io needs pyserial: pip install \"flowtact[serial]\""
        in proc.stderr
    )
    assert "Traceback" not in proc.stderr
    assert not (tmp_path / "r.h5").exists()  # nothing started, nothing recorded


def test_teleop_cnn_without_torch_is_refused_and_the_sim_port_needs_no_pyserial(tmp_path):
    proc = _flowtact(_hiding(tmp_path, "torch"), "validate", "graphs/teleop_cnn.yaml")
    assert proc.returncode == 2
    assert (
        "graphs/teleop_cnn.yaml:22:3: node 'cnn': block cnn_force needs torch: pip install \"flowtact[cnn]\""
        in (proc.stderr)
    )
    proc = _flowtact(_hiding(tmp_path, "serial"), "validate", "graphs/teleop.yaml", "--set", "exo.port=sim")
    assert proc.returncode == 0, proc.stderr


def test_the_extras_check_imports_nothing_heavy():
    code = (
        "import sys\n"
        "from flowtact.running.launch import load_compiled\n"
        "plan = load_compiled('graphs/teleop_cnn.yaml')\n"
        "print(sorted(plan.requires), 'torch' in sys.modules, 'cv2' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert out.stdout.split("\n")[0] == "['serial', 'torch'] False False", out.stderr


def test_a_block_without_an_extra_names_the_module(tmp_path):
    from runs import TESTS

    graph = tmp_path / "g.yaml"
    graph.write_text(
        "nodes:\n  src: {block: 'toyblocks:Ramp'}\n  h: {block: 'toyblocks:Heavy'}\nedges: [src.y -> h.x]\nrecord: [h.y]\n"
    )
    env = _hiding(tmp_path, "toyheavy")
    env["PYTHONPATH"] += os.pathsep + str(TESTS)
    proc = _flowtact(env, "validate", str(graph), "--allow-module", "toyblocks")
    assert proc.returncode == 2
    assert f"{graph}:3:3: node 'h': block heavy needs module 'toyheavy': pip install toyheavy" in proc.stderr


def test_module_available_sees_hidden_and_present_modules(monkeypatch):
    assert module_available("json") and not module_available("no_such_module_xyz")
    assert not module_available("no_such_package_xyz.sub")
    monkeypatch.setitem(sys.modules, "json", None)
    assert not module_available("json")
