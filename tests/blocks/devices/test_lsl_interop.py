"""Issue 34's Done means for LSL: plain pylsl peers in other processes around a `flowtact run`.

Process 1 (tests/blocks/devices/lsl_peers.py send) publishes a 3-channel force stream at 1 kHz;
process 2 runs graphs/lsl_touch.yaml (touch encoding of that stream; the force republished and the
SA1 spikes published on LSL); processes 3 and 4 (lsl_peers.py receive) read the republished force
and the spikes. Every sample sent arrives, in order, with its LSL timestamp within 1 ms; every
spike the run reports arrives; and LSL stays on 127.0.0.1 (the config file is in force in every
process, and no socket of any of them is bound or connected elsewhere). The end-to-end latency
(the sender's stamp to the receiver's pull) is printed, not asserted. Nothing sleeps: each step
waits for a line from a process, with generous bounds.
"""

from __future__ import annotations

import json
import os
import select
import signal
import subprocess
import sys
import uuid
from pathlib import Path

import numpy as np
import pytest
import yaml
from lsl_confine import confined_env, socket_problems, write_config

pytest.importorskip("pylsl")

ROOT = Path(__file__).resolve().parents[3]
PEERS = Path(__file__).with_name("lsl_peers.py")
N = 2000
RATE = 1000.0
BOUND_S = 180.0  # a hang bound for each wait, never a timing assertion


class Lines:
    """A child's stdout read line by line without blocking past a bound (os.read after select)."""

    def __init__(self, proc: subprocess.Popen[bytes], what: str) -> None:
        self.proc, self.what, self.buf, self.seen = proc, what, b"", []

    def next(self, bound: float = BOUND_S) -> str:
        assert self.proc.stdout is not None
        fd = self.proc.stdout.fileno()
        while b"\n" not in self.buf:
            ready, _, _ = select.select([fd], [], [], bound)
            chunk = os.read(fd, 65536) if ready else b""
            if not chunk:
                err = (
                    self.proc.stderr.read().decode(errors="replace") if self.proc.stderr and not ready else ""
                )
                raise AssertionError(
                    f"{self.what}: no line within {bound:g} s or it ended; saw {self.seen}\n{err}"
                )
            self.buf += chunk
        line, self.buf = self.buf.split(b"\n", 1)
        self.seen.append(line.decode()[:200])
        return line.decode()


def _start(
    argv: list[str], env: dict[str, str], stdin: int | None = subprocess.DEVNULL
) -> subprocess.Popen[bytes]:
    return subprocess.Popen(argv, env=env, stdin=stdin, stdout=subprocess.PIPE, stderr=subprocess.PIPE)


def _graph(tmp_path: Path, tag: str) -> tuple[Path, dict[str, str]]:
    """graphs/lsl_touch.yaml with stream names of this test only, the force stream's spec asked of
    the live stream rather than declared, and outlets that wait for their readers."""
    g = yaml.safe_load((ROOT / "graphs" / "lsl_touch.yaml").read_text())
    names = {"force": f"ft_force_{tag}", "force_out": f"ft_force_out_{tag}", "sa1_out": f"ft_sa1_{tag}"}
    force = g["nodes"]["force"]["params"]
    force["name"] = names["force"]
    for declared in ("channels", "format", "rate_hz", "units", "labels"):  # asked of the live stream:
        force.pop(declared)  # compiled in the supervisor, bound in a worker forked from it
    for node in ("force_out", "sa1_out"):
        g["nodes"][node]["params"].update(name=names[node], wait_for_consumers_s=BOUND_S)
    g["nodes"]["fa1_out"]["params"]["name"] = f"ft_fa1_{tag}"
    path = tmp_path / "lsl_touch_test.yaml"
    path.write_text(yaml.safe_dump(g, sort_keys=False))
    return path, names


@pytest.mark.slow
@pytest.mark.cli
@pytest.mark.timeout(900)
def test_pylsl_to_flowtact_to_pylsl_loses_nothing_maps_time_and_stays_on_loopback(tmp_path):
    cfg = write_config(tmp_path)
    env = confined_env(cfg)
    tag = uuid.uuid4().hex[:8]
    graph, names = _graph(tmp_path, tag)
    procs: list[subprocess.Popen[bytes]] = []
    try:
        sender = _start(
            [sys.executable, str(PEERS), "send", names["force"], str(N), str(RATE)], env, subprocess.PIPE
        )
        procs.append(sender)
        send_out = Lines(sender, "sender")
        assert send_out.next() == "ready"
        run = _start([sys.executable, "-m", "flowtact.cli", "run", str(graph), "--duration", "3600"], env)
        procs.append(run)
        # the graph's outlets exist once it opened its blocks: the readers find them and connect
        recv_force = _start(
            [sys.executable, str(PEERS), "receive", names["force_out"], str(N), str(BOUND_S)], env
        )
        recv_sa1 = _start(
            [sys.executable, str(PEERS), "receive", names["sa1_out"], str(10**9), str(BOUND_S)], env
        )
        procs += [recv_force, recv_sa1]
        force_out, sa1_out = Lines(recv_force, "force reader"), Lines(recv_sa1, "spike reader")
        assert force_out.next() == "ready"
        assert sa1_out.next() == "ready"
        assert sender.stdin is not None
        sender.stdin.write(b"go\n")
        sender.stdin.flush()
        sent = send_out.next().split()
        assert sent[:2] == ["sent", str(N)]
        t_first = float(sent[2])
        # every process is alive and connected now: where are their sockets?
        problems, seen = socket_problems([p.pid for p in procs])
        got = json.loads(force_out.next())
        run.send_signal(signal.SIGINT)  # the force reader has everything: stop the graph (Ctrl-C)
        run_out, run_err = run.communicate(timeout=BOUND_S)
        spikes = json.loads(sa1_out.next())  # its stream went away with the graph
        sender.stdin.close()
        stderrs = {"graph": run_err.decode()}
        for name, p in (("sender", sender), ("force reader", recv_force), ("spike reader", recv_sa1)):
            p.wait(timeout=BOUND_S)
            stderrs[name] = p.stderr.read().decode(errors="replace") if p.stderr else ""
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()
            for f in (p.stdin, p.stdout, p.stderr):
                if f is not None:
                    f.close()
    out, err = run_out.decode(), run_err.decode()
    assert run.returncode == 0, err
    assert "interrupted" in out

    # LSL stayed on this machine: the file was read in every process, and no socket left loopback
    for name, text in stderrs.items():
        assert f"Configuration loaded from {cfg}" in text, f"{name} did not read {cfg}:\n{text[-1500:]}"
    assert seen >= 8, f"only {seen} sockets seen: the check looked at nothing"
    assert not problems, problems

    # every sample, in order, none twice (Fy carries the index), values exact, stamps within 1 ms
    values = np.array(got["values"])
    assert values.shape == (N, 3), f"{len(values)} of {N} samples arrived"
    np.testing.assert_array_equal(np.round(values[:, 1] * 1e6), np.arange(N))
    fz = 0.12 + 0.02 * (np.arange(N) % 400 >= 200)
    np.testing.assert_array_equal(values[:, 2], fz)
    stamps = np.array(got["stamps"])
    expected = t_first + np.arange(N) / RATE
    err_ms = np.abs(stamps - expected) * 1e3
    assert err_ms.max() < 1.0, f"timestamps mapped {err_ms.max():.3f} ms off at worst"
    assert (got["label"], got["unit"], got["format"], got["rate"]) == ("Fx", "N", 2, RATE)  # 2: double64

    # every spike the graph published arrived, as int32 unit indices of an irregular stream
    n_spikes = int(next(ln for ln in out.splitlines() if "sa1_out: sent=" in ln).split("sent=")[1].split()[0])
    assert n_spikes > 0, out
    assert len(spikes["values"]) == n_spikes
    assert spikes["kind"] == "events" and spikes["rate"] == 0.0 and spikes["lost"]
    units = np.array(spikes["values"])[:, 0]
    assert ((units >= 0) & (units < 20)).all()

    latency = (np.array(got["arrivals"]) - expected) * 1e3
    print(
        f"\nLSL end to end (pylsl outlet -> flowtact run -> pylsl inlet), {N} samples at {RATE:g} Hz: "
        f"latency median {np.median(latency):.2f} ms, p99 {np.percentile(latency, 99):.2f} ms, "
        f"max {latency.max():.2f} ms; stamp error max {err_ms.max() * 1e3:.1f} µs; "
        f"{n_spikes} spikes; load average {os.getloadavg()[0]:.2f}"
    )
