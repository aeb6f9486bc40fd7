"""The start-up suite: it reads what the run prints about compiling (the two must not drift apart),
and its one start-up measurement, which scripts/startup_table.py uses too."""

import importlib.util
import os
import subprocess

import pytest
from runs import ROOT

from flowtact.bench import startup
from flowtact.bench.startup import COMPILED
from flowtact.runtime.compile_notice import CompileNotices
from flowtact.runtime.forked import NO_FORK_ENV
from flowtact.runtime.protocol import Beat, Ready


def _beat(compiling: str, compiled: int, node: str) -> Beat:
    """A heartbeat of a worker compiling ``compiling`` in ``node``."""
    return Beat("w", 1, 0, 0, node, False, 0.0, compiling, compiled, "warming", (0, 0, 0), 0)


def test_the_suite_parses_the_supervisors_compile_lines():
    said = []
    notices = CompileNotices(said.append)
    notices.on_beat("sink", "process 'sink' (nodes nlif)", False, _beat("m.k", 0, "nlif"))
    notices.on_ready("process 'sink' (nodes nlif)", Ready({}, compiled=12, compile_s=23.75))
    notices.on_ready("process 'filter' (nodes savgol)", Ready({}, compiled=1, compile_s=0.5))
    assert said[0] == (
        "process 'sink' (nodes nlif): compiling kernels for nlif (first run after an install or upgrade; "
        "numba caches them for the next runs)..."
    )
    assert [(int(n), float(s)) for n, s in COMPILED.findall("\n".join(said))] == [(12, 23.8), (1, 0.5)]


def test_compiling_after_the_start_is_told_once():
    said = []
    notices = CompileNotices(said.append)
    notices.on_beat("w", "process 'w'", False, _beat("m.a", 3, "n"))
    notices.on_beat("w", "process 'w'", True, _beat("m.b", 4, "n"))
    notices.on_beat("w", "process 'w'", True, _beat("m.c", 5, "n"))
    late = [s for s in said if "after the start" in s]
    assert late == [
        "process 'w': compiling kernel m.b in node 'n' after the start: the run stalls meanwhile "
        "(the warm-up missed this signature; please report it)"
    ]


def _fake_run(seen, returncode=0, stdout='{"startup_s": 0.7, "startup_parts": {"launch": 0.4}}'):
    def run(cmd, env, **_):
        seen.append((cmd, env))
        return subprocess.CompletedProcess(cmd, returncode, stdout, "boom\n")

    return run


@pytest.mark.parametrize(
    ("fork", "caller_no_fork", "no_fork"), [(True, "1", None), (False, None, "1"), (None, "1", "1")]
)
def test_graph_startup_forks_or_not_as_asked_and_reads_the_summary(
    monkeypatch, fork, caller_no_fork, no_fork
):
    """One start-up measurement for the suite and scripts/startup_table.py: fork True/False forces
    the workers' start, None keeps the caller's FLOWTACT_NO_FORK (the script's documented usage)."""
    seen = []
    monkeypatch.setattr(startup.subprocess, "run", _fake_run(seen))
    if caller_no_fork:
        monkeypatch.setenv(NO_FORK_ENV, caller_no_fork)
    else:
        monkeypatch.delenv(NO_FORK_ENV, raising=False)
    got = startup.graph_startup("touch", duration_s=0.2, fork=fork, cache="/tmp/c")
    assert got == {"startup_s": 0.7, "parts": {"launch": 0.4}}
    ((cmd, env),) = seen
    assert cmd[4:] == ["touch", "--duration", "0.2", "--json", "--quiet"]
    assert env.get(NO_FORK_ENV) == no_fork and env["NUMBA_CACHE_DIR"] == "/tmp/c"


def test_the_startup_table_script_measures_with_the_suites_function(monkeypatch):
    """scripts/startup_table.py has no start-up code of its own: its rows come from graph_startup,
    and a failed run exits with a message naming the graph and ending with the run's stderr."""
    spec = importlib.util.spec_from_file_location("startup_table", ROOT / "scripts" / "startup_table.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    assert script.graph_startup is startup.graph_startup
    seen = []
    monkeypatch.setattr(startup.subprocess, "run", _fake_run(seen))
    assert script.start_up("slip", None) == {"total": 0.7, "launch": 0.4}
    assert seen[0][0][4:6] == [str(ROOT / "graphs" / "slip.yaml"), "--duration"]
    assert seen[0][1].get("NUMBA_CACHE_DIR") == os.environ.get("NUMBA_CACHE_DIR")  # the usual cache
    monkeypatch.setattr(startup.subprocess, "run", _fake_run(seen, returncode=1))
    with pytest.raises(SystemExit, match=r"^slip: flowtact run .*slip\.yaml exited with 1:\nboom$"):
        script.start_up("slip", None)
