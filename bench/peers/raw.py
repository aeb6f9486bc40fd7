"""The raw baseline: plain pyzmq with flowtact's framing, source -> stage -> sink in 3 processes.

Each hop is a PUSH/PULL pair over ipc:// with a high-water mark of 1000 and blocking sends
(lossless backpressure); messages are framed by ``flowtact.runtime.links.zeromq.wire`` (a fixed
binary header + raw buffers, zero-copy above 64 KiB), exactly as flowtact's runtime frames them, so the difference
between this and flowtact is the runtime's own cost. The source stamps ``monotonic_ns()`` just
before each send in the message's ``origins`` ({0: ns}); the stage computes ``2 x`` (small) or
``255 - x`` (image) into a new array and forwards the origins; the sink records the arrival.
With ``stages=0`` the source feeds the sink directly (the one-way floor).

End of stream is an ``END`` message, and no socket is closed before the parent has the sink's
results: with libzmq 4.3.5 closing a PUSH socket while the receiver lags loses the queued tail
despite LINGER (see shared PEERS-BENCH.md), so nobody relies on linger.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import queue
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import zmq

from flowtact.bench.peers.measure import CLK_TCK, STEADY_WINDOW, CpuSampler, Pacer, summarize
from flowtact.chunk import Chunk
from flowtact.runtime.links.zeromq.wire import END, recv_message, send_message

__all__ = ["CLK_TCK", "PAYLOADS", "make_payload", "run_pipeline"]

HWM = 1000
PAYLOADS: dict[str, tuple[tuple[int, ...], str]] = {
    "small": ((4,), "float64"),
    "image": ((240, 320), "uint8"),
}
"""Sample shape and dtype of each payload: 4 float64 (32 B) or a 240x320 uint8 frame (76.8 kB)."""


def make_payload(kind: str, k: int, frame: np.ndarray | None = None, n: int = 1) -> np.ndarray:
    """The k-th message's data: ``n`` new small samples, sample i of the stream holding i in all 4 values
    (message k holds samples k n ... k n + n - 1), or the shared frame (one sample)."""
    if kind == "small":
        return np.repeat(np.arange(k * n, (k + 1) * n, dtype=np.float64)[:, None], 4, axis=1)
    assert frame is not None
    return frame


def stage_compute(kind: str, x: np.ndarray) -> np.ndarray:
    """The stage's work: y = 2 x (small) or y = 255 - x (image), always a new array."""
    return 2.0 * x if kind == "small" else 255 - x


def _frame(shape: tuple[int, ...]) -> np.ndarray:
    """The image payload: one fixed random frame, shape (1, *shape)."""
    return np.random.default_rng(0).integers(0, 256, (1, *shape), dtype=np.uint8)


def _socket(ctx: zmq.Context, kind: int) -> zmq.Socket:
    sock = ctx.socket(kind)
    sock.setsockopt(zmq.SNDHWM, HWM)
    sock.setsockopt(zmq.RCVHWM, HWM)
    return sock


def _source(cfg: dict[str, Any], results: Any, stop: Any, go: Any) -> None:
    ctx = zmq.Context()
    out = _socket(ctx, zmq.PUSH)
    out.connect(cfg["out"])
    kind, rate, seconds, per = cfg["payload"], cfg["rate_hz"], cfg["seconds"], cfg["per_message"]
    shape, dtype = PAYLOADS[kind]
    frame = _frame(shape) if kind == "image" else None
    results.put(("ready", "source", os.getpid()))
    go.wait()
    start = time.monotonic_ns()
    first = last = start
    k = 0
    if rate:  # paced: one message of `per` samples per period (per / rate), sleeping to each deadline
        pacer = Pacer(rate / per, start)
        n = round(seconds * rate / per)
        for k in range(n):
            pacer.wait(k)
            chunk = Chunk(np.arange(k * per, (k + 1) * per) / rate, make_payload(kind, k, frame, per))
            now = time.monotonic_ns()
            send_message(out, 0, k, k, chunk, {0: now})
            if k == 0:
                first = now
            last = now
        k = n
    else:  # flat out for `seconds`
        stop_at = start + int(seconds * 1e9)
        while True:
            chunk = Chunk(np.full(1, float(k)), make_payload(kind, k, frame))
            now = time.monotonic_ns()
            if now >= stop_at:
                break
            send_message(out, 0, k, k, chunk, {0: now})
            if k == 0:
                first = now
            last = now
            k += 1
    end = time.monotonic_ns()
    empty = Chunk(np.empty(0), np.empty((0, *shape), dtype))
    send_message(out, 0, k, k, empty, {}, flags=END)
    results.put(("source", {"sent": k, "start_ns": start, "end_ns": end, "first_ns": first, "last_ns": last}))
    stop.wait()
    out.close(linger=0)
    ctx.term()


def _stage(cfg: dict[str, Any], results: Any, stop: Any) -> None:
    ctx = zmq.Context()
    inp, out = _socket(ctx, zmq.PULL), _socket(ctx, zmq.PUSH)
    inp.bind(cfg["in"])
    out.connect(cfg["out"])
    kind = cfg["payload"]
    results.put(("ready", "stage", os.getpid()))
    while True:
        msg = recv_message(inp)
        if msg.is_end:
            send_message(out, 0, msg.seq, msg.tick, msg.chunk, msg.origins, flags=END)
            break
        y = stage_compute(kind, msg.chunk.data)
        send_message(out, 0, msg.seq, msg.tick, Chunk(msg.chunk.t, y), msg.origins)
    stop.wait()
    inp.close(linger=0)
    out.close(linger=0)
    ctx.term()


def _sink(cfg: dict[str, Any], results: Any, stop: Any) -> None:
    ctx = zmq.Context()
    inp = _socket(ctx, zmq.PULL)
    inp.bind(cfg["in"])
    results.put(("ready", "sink", os.getpid()))
    kind, staged, per = cfg["payload"], cfg["staged"], cfg["per_message"]
    shape, _ = PAYLOADS[kind]
    # what the first value of message k must be: k (small) or the frame's first pixel, after the stage
    pixel = int(_frame(shape)[0, 0, 0]) if kind == "image" else 0
    sent: list[int] = []
    recv: list[int] = []
    bad = 0
    while True:
        msg = recv_message(inp)
        now = time.monotonic_ns()
        if msg.is_end:
            break
        sent.append(msg.origins[0])
        recv.append(now)
        x = msg.chunk.data
        if kind == "small":
            want = float(msg.seq * per) * (2.0 if staged else 1.0)
        else:
            want = 255 - pixel if staged else pixel
        bad += int(x.shape != (per, *shape) or x.flat[0] != want)
    results.put(
        ("sink", {"sent_ns": np.asarray(sent, np.int64), "recv_ns": np.asarray(recv, np.int64), "bad": bad})
    )
    stop.wait()
    inp.close(linger=0)
    ctx.term()


def _collect(results: Any, procs: list[Any], n: int, timeout_s: float, what: str) -> list[Any]:
    """``n`` items from the results queue; fail fast, naming it, when a process dies first."""
    items: list[Any] = []
    deadline = time.monotonic() + timeout_s
    while len(items) < n:
        try:
            items.append(results.get(timeout=0.25))
        except queue.Empty:
            dead = [p.name for p in procs if p.exitcode not in (None, 0)]
            if dead:
                raise RuntimeError(
                    f"raw pipeline: {', '.join(dead)} died (see its traceback above)"
                ) from None
            if time.monotonic() > deadline:
                raise TimeoutError(
                    f"raw pipeline: processes did not {what} within {timeout_s:.0f} s"
                ) from None
    return items


def run_pipeline(
    payload: str,
    seconds: float,
    rate_hz: float | None,
    stages: int = 1,
    drop_s: float = 0.5,
    timeout_s: float = 60.0,
    cpu_window: tuple[float, float] = STEADY_WINDOW,
    cpu_period_s: float = 0.25,
    per_message: int = 1,
) -> dict[str, Any]:
    """Run source -> [stage ->] sink once (``rate_hz=None``: flat out) and measure it.

    ``rate_hz`` counts samples; paced small runs may carry ``per_message`` samples in each message
    (one message every ``per_message / rate_hz`` s, like flowtact's source at tick ``per_message /
    rate_hz``); flat-out and image runs send one sample per message.

    Returns latency (µs, messages sent after ``drop_s``), loss, throughput (flat out), the CPU %
    of one core of each process over the steady window (``cpu_window``: seconds after the start
    and before the end, sampled every ``cpu_period_s``), and ``payload_ok``: every message the
    sink got held the stage's result for its sequence number.
    """
    if payload not in PAYLOADS:
        raise ValueError(f"payload must be one of {sorted(PAYLOADS)}; got {payload!r}")
    if stages not in (0, 1):
        raise ValueError(f"stages must be 0 (source -> sink) or 1; got {stages}")
    if per_message < 1 or (per_message > 1 and (payload != "small" or not rate_hz)):
        raise ValueError(f"per_message must be 1, or >= 1 for paced small runs; got {per_message}")
    ctx = mp.get_context("spawn")
    results, go, stop = ctx.Queue(), ctx.Event(), ctx.Event()
    with tempfile.TemporaryDirectory(prefix="ftbench-") as tmp:
        eps = [f"ipc://{Path(tmp) / f'hop{i}'}" for i in range(stages + 1)]
        base = {"payload": payload, "seconds": seconds, "rate_hz": rate_hz, "per_message": per_message}
        # (role, process body, its config, its extra arguments): only the source waits for `go`
        roles = [("sink", _sink, {"in": eps[-1], "staged": stages == 1}, ())]
        roles += [("stage", _stage, {"in": eps[i], "out": eps[i + 1]}, ()) for i in range(stages)]
        roles += [("source", _source, {"out": eps[0]}, (go,))]
        procs = [
            ctx.Process(
                target=fn, args=({**base, **c}, results, stop, *extra), name=f"raw-{role}", daemon=True
            )
            for role, fn, c, extra in roles
        ]
        got: dict[str, Any] = {}
        pids: dict[str, int] = {}
        sampler: CpuSampler | None = None
        try:
            for p in procs:
                p.start()
            started = {item[1]: item[2] for item in _collect(results, procs, len(procs), timeout_s, "start")}
            pids = {role: started[role] for role in ("source", "stage", "sink") if role in started}
            time.sleep(0.3)  # let the connects complete before the clock starts
            sampler = CpuSampler(pids, period_s=cpu_period_s, window=cpu_window).start()
            go.set()
            for key, value in _collect(results, procs, 2, seconds + timeout_s, "finish"):
                got[key] = value
        finally:
            if sampler is not None:
                sampler.stop()
            stop.set()
            for p in procs:
                p.join(timeout=5)
                if p.is_alive():
                    p.kill()
                    p.join()
    src, snk = got["source"], got["sink"]
    shape, dtype = PAYLOADS[payload]
    nbytes = int(np.prod(shape)) * np.dtype(dtype).itemsize
    out = summarize(src, snk["sent_ns"], snk["recv_ns"], sampler, nbytes, rate_hz, drop_s)
    return {
        "payload": payload,
        "processes": len(procs),
        "seconds": seconds,
        "per_message": per_message,
        **out,
        "payload_ok": int(snk["bad"]) == 0,
    }
