"""A graph across two hosts: tcp with CurveZMQ between the supervisor and a remote worker.

Network namespaces need privileges CI does not have, so the "remote" host is loopback: the graph
names ``host: 127.0.0.1`` for one group, which makes every stream to and from it tcp + CURVE,
and the test starts that group's worker itself, as a user would on the other machine.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from flowtact.recording.hdf5 import read_recording
from flowtact.running.launch import load_compiled, run_compiled
from flowtact.runtime.links.zeromq.security import generate_keys

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.slow


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _graph(tmp_path: Path, port: int, keys: Path) -> Path:
    text = (ROOT / "graphs" / "touch.yaml").read_text()
    text += (
        "processes:\n  afferents: {host: 127.0.0.1}\n"
        f"network: {{listen: 127.0.0.1, port: {port}, keys: {keys.name}}}\n"
    )
    path = tmp_path / "two_hosts.yaml"
    path.write_text(text)
    return path


def _cli(*args: str) -> subprocess.Popen:
    env = {k: v for k, v in os.environ.items() if k != "FLOWTACT_KEYS"}
    return subprocess.Popen(
        [sys.executable, "-m", "flowtact.cli", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )


def _wait_for(proc: subprocess.Popen, text: str, timeout: float = 30.0) -> str:
    """Read the supervisor's stderr until it prints ``text`` (its instructions for the remote host)."""
    deadline = time.monotonic() + timeout
    seen = ""
    while time.monotonic() < deadline:
        line = proc.stderr.readline()
        seen += line
        if text in line:
            return line
    raise AssertionError(f"never printed {text!r}: {seen}")


def test_a_remote_group_runs_over_curve_tcp_and_matches_in_process(tmp_path):
    keys = generate_keys(tmp_path / "keys")
    port = _free_port()
    graph = _graph(tmp_path, port, keys)
    sup = _cli("run", str(graph), "--fast", "--duration", "2", "--record", str(tmp_path / "remote.h5"))
    line = _wait_for(sup, "flowtact worker tcp://")
    assert f"tcp://127.0.0.1:{port}" in line
    worker = _cli("worker", f"tcp://127.0.0.1:{port}", "--process", "afferents", "--keys", str(keys))
    _, err = sup.communicate(timeout=60)
    worker.communicate(timeout=10)
    assert sup.returncode == 0, err
    assert worker.returncode == 0
    run_compiled(load_compiled(graph), duration_s=2.0, fast=True, inproc=True, record=tmp_path / "inproc.h5")
    a, b = read_recording(tmp_path / "remote.h5"), read_recording(tmp_path / "inproc.h5")
    for name in b.streams:
        assert np.array_equal(a.streams[name].data, b.streams[name].data), name
    assert len(a.streams["sa1.spikes"].t) > 0  # made by the remote group


def test_a_remote_worker_started_30_s_late_joins_and_the_run_completes(tmp_path):
    """Workers already started wait for the late one (the run says for whom) instead of giving up."""
    keys = generate_keys(tmp_path / "keys")
    port = _free_port()
    graph = _graph(tmp_path, port, keys)
    sup = _cli("run", str(graph), "--fast", "--duration", "2", "--record", str(tmp_path / "late.h5"))
    line = _wait_for(sup, "flowtact worker tcp://")
    assert "waiting for process 'afferents' on 127.0.0.1 (up to 120 s" in line
    time.sleep(30.0)  # the user walks to the other machine
    worker = _cli("worker", f"tcp://127.0.0.1:{port}", "--process", "afferents", "--keys", str(keys))
    _, err = sup.communicate(timeout=120)
    worker.communicate(timeout=30)
    assert sup.returncode == 0, err
    assert worker.returncode == 0
    assert "still waiting for process 'afferents' on 127.0.0.1" in err  # told while it waited
    assert len(read_recording(tmp_path / "late.h5").streams["sa1.spikes"].t) > 0


def test_a_worker_with_another_key_is_refused_with_a_clear_message(tmp_path):
    keys = generate_keys(tmp_path / "keys")
    wrong = generate_keys(tmp_path / "other")
    port = _free_port()
    sup = _cli("run", str(_graph(tmp_path, port, keys)), "--fast", "--duration", "2")
    _wait_for(sup, "flowtact worker tcp://")
    worker = _cli("worker", f"tcp://127.0.0.1:{port}", "--process", "afferents", "--keys", str(wrong))
    _, werr = worker.communicate(timeout=30)
    assert worker.returncode == 1
    assert "CURVE handshake" in werr and "same `flowtact keys` directory" in werr
    line = _wait_for(sup, "refused a connection")
    assert "key" in line
    sup.send_signal(2)
    sup.communicate(timeout=30)


def test_off_host_groups_need_keys(tmp_path):
    port = _free_port()
    graph = _graph(tmp_path, port, tmp_path / "missing")
    proc = _cli("run", str(graph), "--fast", "--duration", "1")
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 1
    assert "flowtact keys" in err
