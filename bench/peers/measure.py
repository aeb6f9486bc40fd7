"""Measurement tools shared by the raw baseline and the peer pipelines of bench/transport.py.

The peers run in throw-away venvs that do not have flowtact, so this module needs only the
standard library and numpy. Every pipeline measures the same way with it:

* latency: the source stamps ``time.monotonic_ns()`` just before the framework's send call, the
  sink takes ``time.monotonic_ns()`` when the message reaches user code (CLOCK_MONOTONIC is one
  clock for every process of the host); samples sent in the first ``drop_s`` are ignored;
* pacing: sleep until each deadline ``t0 + k / rate``, never spin;
* CPU: utime + stime from ``/proc/<pid>/stat`` (optionally of the whole process tree), sampled
  every 0.25 s, over the steady window from started + 1 s to end - 0.5 s, as % of one core
  (the machine's maximum is 100 % times its cores);
* throughput: received / (last receipt - first send), so a lossy transport gets no credit for a
  burst of receipts.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Mapping, Sequence

import numpy as np

__all__ = [
    "CLK_TCK",
    "CpuSampler",
    "Pacer",
    "cpu_ticks",
    "latency_stats",
    "summarize",
    "throughput_stats",
]

CLK_TCK = os.sysconf("SC_CLK_TCK")
STEADY_WINDOW = (1.0, 0.5)
"""The CPU window starts 1 s after the source started (start-up and JIT excluded) and ends 0.5 s
before it stopped."""


class Pacer:
    """Sleeps until ``t0 + k / rate_hz`` for the k-th message (no spinning; late: no sleep)."""

    def __init__(self, rate_hz: float, t0_ns: int | None = None) -> None:
        self.period_ns = round(1e9 / rate_hz)
        self.t0_ns = time.monotonic_ns() if t0_ns is None else t0_ns

    def wait(self, k: int) -> None:
        """Return at (or just after) the k-th deadline."""
        delay = self.t0_ns + k * self.period_ns - time.monotonic_ns()
        if delay > 0:
            time.sleep(delay / 1e9)


def _stat_fields(pid: int) -> list[str] | None:
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            text = f.read().decode()
    except OSError:
        return None
    # the command name (field 2) may hold spaces and parentheses: split after its last ')'
    return text[text.rindex(")") + 2 :].split()


def _children() -> dict[int, list[int]]:
    kids: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            fields = _stat_fields(int(entry))
            if fields is not None:
                kids.setdefault(int(fields[1]), []).append(int(entry))
    return kids


def cpu_ticks(pid: int, tree: bool = False, kids: dict[int, list[int]] | None = None) -> int | None:
    """utime + stime (clock ticks) of ``pid``, plus its live descendants' with ``tree``.

    ``kids`` (parent pid -> child pids, from one scan of /proc) saves rescanning for each pid.
    """
    fields = _stat_fields(pid)
    if fields is None:
        return None
    total = int(fields[11]) + int(fields[12])
    if tree:
        kids = _children() if kids is None else kids
        todo = list(kids.get(pid, []))
        while todo:
            p = todo.pop()
            f = _stat_fields(p)
            if f is not None:
                total += int(f[11]) + int(f[12])
            todo.extend(kids.get(p, []))
    return total


class CpuSampler:
    """A thread sampling the CPU ticks of named processes (or process trees) every ``period_s``.

    ``cpu_pct(start_ns, end_ns)`` gives each one's % of one core over the steady window
    ``[start + window[0], end - window[1]]`` (seconds), from the first and last samples inside
    it. A sample whose reading took longer than ``stall_s`` is dropped (its time stamp would be
    wrong).
    """

    def __init__(
        self,
        pids: Mapping[str, int],
        tree: bool = False,
        period_s: float = 0.25,
        stall_s: float = 0.05,
        window: tuple[float, float] = STEADY_WINDOW,
    ) -> None:
        self.pids = dict(pids)
        self.tree = tree
        self.period_s = period_s
        self.stall_s = stall_s
        self.window = window
        self.samples: list[tuple[int, dict[str, int | None]]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="cpu-sampler", daemon=True)

    def start(self) -> CpuSampler:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()

    def _run(self) -> None:
        while not self._stop.is_set():
            t0 = time.monotonic_ns()
            kids = _children() if self.tree else None
            ticks = {name: cpu_ticks(pid, self.tree, kids) for name, pid in self.pids.items()}
            t1 = time.monotonic_ns()
            if (t1 - t0) / 1e9 <= self.stall_s:
                self.samples.append(((t0 + t1) // 2, ticks))
            self._stop.wait(self.period_s)

    def _bounds(self, start_ns: int, end_ns: int) -> tuple[int, int]:
        return start_ns + int(self.window[0] * 1e9), end_ns - int(self.window[1] * 1e9)

    def cpu_pct(self, start_ns: int, end_ns: int) -> dict[str, float | None]:
        """% of one core per name over the steady window (None: too few samples or a dead pid)."""
        lo, hi = self._bounds(start_ns, end_ns)
        inside = [s for s in self.samples if lo <= s[0] <= hi]
        out: dict[str, float | None] = {}
        for name in self.pids:
            pts = [(t, v[name]) for t, v in inside if v.get(name) is not None]
            if len(pts) < 2 or pts[-1][0] == pts[0][0]:
                out[name] = None
                continue
            (ta, a), (tb, b) = pts[0], pts[-1]
            out[name] = 100.0 * (b - a) / CLK_TCK / ((tb - ta) / 1e9)
        return out

    def window_s(self, start_ns: int, end_ns: int) -> float:
        """Length of the steady window actually covered by samples (0 when none)."""
        lo, hi = self._bounds(start_ns, end_ns)
        ts = [t for t, _ in self.samples if lo <= t <= hi]
        return (ts[-1] - ts[0]) / 1e9 if len(ts) > 1 else 0.0


def latency_stats(
    sent_ns: Sequence[int] | np.ndarray,
    recv_ns: Sequence[int] | np.ndarray,
    start_ns: int,
    drop_s: float = 0.5,
) -> dict[str, float | int | None]:
    """p50 / p99 / max one-way latency in µs of the messages sent after ``start + drop_s``."""
    sent = np.asarray(sent_ns, np.int64)
    recv = np.asarray(recv_ns, np.int64)
    keep = sent >= start_ns + int(drop_s * 1e9)
    lat = (recv[keep] - sent[keep]) / 1e3
    if lat.size == 0:
        return {"p50": None, "p99": None, "max": None, "min": None, "n": 0}
    return {
        "p50": float(np.percentile(lat, 50)),
        "p99": float(np.percentile(lat, 99)),
        "max": float(lat.max()),
        "min": float(lat.min()),
        "n": int(lat.size),
    }


def throughput_stats(
    n_sent: int, n_received: int, first_send_ns: int, last_send_ns: int, last_recv_ns: int, nbytes: int
) -> dict[str, float | int]:
    """Delivered msg/s (received / (last receipt - first send)), sent msg/s, loss and bytes/s."""
    span = max(last_recv_ns - first_send_ns, 1) / 1e9
    send_span = max(last_send_ns - first_send_ns, 1) / 1e9
    delivered = n_received / span
    return {
        "sent": int(n_sent),
        "received": int(n_received),
        "delivered_msg_s": delivered,
        "sent_msg_s": n_sent / send_span,
        "loss_pct": 100.0 * (1 - n_received / n_sent) if n_sent else 0.0,
        "bytes_s": delivered * nbytes,
        "span_s": span,
    }


def summarize(
    source: Mapping[str, int],
    sent_ns: Sequence[int] | np.ndarray,
    recv_ns: Sequence[int] | np.ndarray,
    sampler: CpuSampler | None,
    nbytes: int,
    paced_hz: float | None,
    drop_s: float = 0.5,
) -> dict:
    """The figures of one pipeline run, the same for every stack.

    ``source`` holds ``sent``, ``start_ns``, ``end_ns`` (the source's start and stop), and
    ``first_ns`` / ``last_ns`` (its first and last send); ``sent_ns`` / ``recv_ns`` are the send
    stamp and arrival time of every message the sink got. Flat-out runs (``paced_hz=None``) add
    ``throughput``.
    """
    recv = np.asarray(recv_ns, np.int64)
    n_sent = int(source["sent"])
    out: dict = {
        "paced_hz": paced_hz,
        "sent": n_sent,
        "received": int(recv.size),
        "loss_pct": 100.0 * (1 - recv.size / n_sent) if n_sent else 0.0,
        "latency_us": latency_stats(sent_ns, recv, source["start_ns"], drop_s),
    }
    if sampler is not None:
        cpu = sampler.cpu_pct(source["start_ns"], source["end_ns"])
        out["cpu_pct"] = cpu
        values = list(cpu.values())
        out["cpu_total_pct"] = None if None in values else float(sum(v for v in values if v is not None))
        out["cpu_window_s"] = sampler.window_s(source["start_ns"], source["end_ns"])
    if paced_hz is None:
        last_recv = int(recv.max()) if recv.size else int(source["first_ns"])
        out["throughput"] = throughput_stats(
            n_sent, int(recv.size), int(source["first_ns"]), int(source["last_ns"]), last_recv, nbytes
        )
    return out
