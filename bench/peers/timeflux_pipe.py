"""The bench pipeline in Timeflux: source -> stage -> sink, one graph (process) each, plus the Broker.

Run by bench/transport.py with the Python of a throw-away venv holding timeflux:

    python timeflux_pipe.py --payload small|image --rate HZ (0: flat out) --seconds S --out DIR

Configured as shared/PEERS-BENCH.md describes: every graph is a Timeflux worker process; the
inter-process edges are Timeflux's own ``Pub``/``Sub`` nodes through a ``Broker`` graph (XSUB/XPUB
proxy on tcp://127.0.0.1), pickled pandas DataFrames (Timeflux's default; its msgpack serializer
needs a pandas API removed in 1.0). Paced runs set every graph's ``rate`` to the message rate, and
the source emits at each cycle the samples that are due (a late cycle sends 2 rows in one
message); flat-out runs use ``rate: 0`` (a busy loop) and one row per cycle. Small samples are
rows of 4 float64 columns; a frame is one row whose ``frame`` column holds the 240x320 uint8
array. Each row carries ``t_ns``, the ``monotonic_ns()`` stamped by the source just before the
graph's Pub node sends it; the sink stamps every row of what its Sub node delivers on entry to
its update. PUB/SUB drops under overload, so end of stream is repeated, and the sink also stops
after 3 s without data. Results: DIR/source.json and DIR/sink.npz, as for the other pipelines.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import pandas as pd
from timeflux.core.exceptions import WorkerInterrupt
from timeflux.core.logging import init_listener, terminate_listener
from timeflux.core.manager import Manager
from timeflux.core.node import Node

SETTLE_S = 2.0
"""The source waits this long after loading (Timeflux's PUB/SUB 'slow joiner' problem)."""
END_REPEATS = 20
IDLE_STOP_S = 3.0


def _frame(rows: dict, n: int) -> pd.DataFrame:
    return pd.DataFrame(rows, index=pd.to_datetime(np.full(n, time.time_ns()), unit="ns"))


class BenchSource(Node):
    """Emits the payload: paced (the samples due at each cycle) or one row per cycle (rate 0)."""

    def __init__(self, payload: str, rate_hz: float, seconds: float, out: str) -> None:
        self.payload, self.rate, self.seconds, self.out = payload, rate_hz, seconds, out
        self.t_load = time.monotonic_ns()
        self.start = 0
        self.k = 0
        self.first = self.last = 0
        self.ends = 0
        self.done = False
        self.image = np.random.default_rng(0).integers(0, 256, (240, 320), dtype=np.uint8)

    def _rows(self, ks: np.ndarray, end: bool = False) -> pd.DataFrame:
        """The rows of samples ``ks``, stamped last (the Pub node sends them right after)."""
        n = len(ks)
        rows: dict = {"seq": ks, "t_ns": np.zeros(n, np.int64), "end": np.full(n, end)}
        if self.payload == "small":
            for c in range(4):
                rows[f"x{c}"] = ks.astype(np.float64)
        else:
            rows["frame"] = [self.image] * n
        df = _frame(rows, n)
        df["t_ns"] = np.full(n, time.monotonic_ns(), np.int64)
        return df

    def update(self) -> None:
        now = time.monotonic_ns()
        if self.done:
            if self.ends < END_REPEATS:  # end of stream, repeated: PUB/SUB may drop it
                self.ends += 1
                self.o.data = self._rows(np.array([self.k]), end=True)
            return
        if now < self.t_load + int(SETTLE_S * 1e9):
            return
        if not self.start:
            self.start = now
        if self.rate > 0:
            total = round(self.seconds * self.rate)
            due = min(int((now - self.start) * self.rate / 1e9) + 1, total)
            ks = np.arange(self.k, due)
            finished = due >= total
        else:
            ks = np.array([self.k])
            finished = now >= self.start + int(self.seconds * 1e9)
            if finished:
                ks = ks[:0]
        if len(ks):
            self.o.data = self._rows(ks)
            stamp = int(self.o.data["t_ns"].iat[0])
            self.first = self.first or stamp
            self.last = stamp
            self.k += len(ks)
        if finished:
            self.done = True
            info = {
                "sent": self.k,
                "start_ns": self.start,
                "end_ns": time.monotonic_ns(),
                "first_ns": self.first,
                "last_ns": self.last,
            }
            Path(self.out, "source.json").write_text(json.dumps(info))


class BenchStage(Node):
    """y = 2 x (small) or 255 - x (image), into a new DataFrame; seq, t_ns and end pass through."""

    def __init__(self, payload: str) -> None:
        self.payload = payload

    def update(self) -> None:
        if not self.i.ready():
            return
        df = self.i.data
        out = df[["seq", "t_ns", "end"]].copy()
        if self.payload == "small":
            cols = [f"x{c}" for c in range(4)]
            out[cols] = 2.0 * df[cols]
        else:
            out["frame"] = [255 - f for f in df["frame"]]
        self.o.data = out


class BenchSink(Node):
    """Stamps each delivered row; stops the app at end of stream or after 3 s without data."""

    def __init__(self, out: str) -> None:
        self.out = out
        self.sent: list[np.ndarray] = []
        self.recv: list[np.ndarray] = []
        self.last_data = 0
        self.seen: set[int] = set()

    def update(self) -> None:
        now = time.monotonic_ns()
        if self.i.ready():
            df = self.i.data
            data = df[~df["end"].to_numpy(bool)]
            self.sent.append(data["t_ns"].to_numpy(np.int64))
            self.recv.append(np.full(len(data), now, np.int64))
            self.last_data = now
            if len(data) < len(df):
                self._finish()
        elif self.last_data and now - self.last_data > IDLE_STOP_S * 1e9:
            self._finish()

    def _finish(self) -> None:
        np.savez(
            Path(self.out, "sink.npz"),
            sent_ns=np.concatenate(self.sent) if self.sent else np.empty(0, np.int64),
            recv_ns=np.concatenate(self.recv) if self.recv else np.empty(0, np.int64),
        )
        raise WorkerInterrupt("end of stream")


def app(payload: str, rate_hz: float, seconds: float, out: str) -> dict:
    """The Timeflux application: Broker, source, stage and sink graphs."""
    here = "timeflux_pipe"
    rate = rate_hz if rate_hz > 0 else 0

    def node(nid: str, module: str, cls: str, **params: object) -> dict:
        return {"id": nid, "module": module, "class": cls, "params": params}

    zmq = "timeflux.nodes.zmq"
    return {
        "graphs": [
            {"id": "broker", "nodes": [node("broker", zmq, "Broker")], "rate": 1},
            {
                "id": "source",
                "nodes": [
                    node(
                        "src", here, "BenchSource", payload=payload, rate_hz=rate_hz, seconds=seconds, out=out
                    ),
                    node("pub", zmq, "Pub", topic="raw"),
                ],
                "edges": [{"source": "src", "target": "pub"}],
                "rate": rate,
            },
            {
                "id": "stage",
                "nodes": [
                    node("sub", zmq, "Sub", topics=["raw"]),
                    node("stage", here, "BenchStage", payload=payload),
                    node("pub", zmq, "Pub", topic="staged"),
                ],
                "edges": [{"source": "sub:raw", "target": "stage"}, {"source": "stage", "target": "pub"}],
                "rate": rate,
            },
            {
                "id": "sink",
                "nodes": [
                    node("sub", zmq, "Sub", topics=["staged"]),
                    node("sink", here, "BenchSink", out=out),
                ],
                "edges": [{"source": "sub:staged", "target": "sink"}],
                "rate": rate,
            },
        ]
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--payload", choices=["small", "image"], default="small")
    ap.add_argument("--rate", type=float, default=1000.0, help="messages/s and graph rate (0: flat out)")
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--out", required=True, help="folder for source.json and sink.npz")
    a = ap.parse_args()
    # as the `timeflux` command does: the workers log through a queue that a listener drains
    # (without one, a worker that logs blocks at exit on its queue's feeder thread)
    init_listener("WARNING", "WARNING", None)
    try:
        Manager(app(a.payload, a.rate, a.seconds, a.out)).run()
    finally:
        terminate_listener()


if __name__ == "__main__":
    main()
