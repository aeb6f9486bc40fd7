"""The bench pipeline in ezmsg: source -> stage -> sink, each unit in its own process.

Run by bench/transport.py with the Python of a throw-away venv holding ezmsg and numpy:

    python ezmsg_pipe.py --payload small|image --rate HZ (0: flat out) --seconds S --out DIR

Configured as shared/PEERS-BENCH.md describes: ``ez.run`` with ``process_components`` (stage and
sink in their own processes, the source in the main process beside the GraphServer), default
shared-memory transport (32 buffers; 128 KiB each for images), non-leaky subscribers (lossless
backpressure). Messages are a small dataclass holding the numpy sample, pickled by ezmsg.
The source stamps ``monotonic_ns()`` just before yielding (ezmsg's send), pacing with
``asyncio.sleep`` to each deadline; the sink records ``monotonic_ns()`` on entry to its
subscriber. Results: DIR/source.json (sent count, start/end) and DIR/sink.npz (sent_ns, recv_ns).
The caller samples the CPU of this process tree.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import time
from collections.abc import AsyncGenerator
from dataclasses import dataclass
from pathlib import Path

import ezmsg.core as ez
import numpy as np

SHAPES = {"small": ((1, 4), "float64"), "image": ((1, 240, 320), "uint8")}
# Shared-memory buffer size: ezmsg's 64 KiB default, 128 KiB for 76.8 kB frames. Streams are class
# attributes built at import (also in the unit processes), hence an environment variable.
BUF_SIZE = 2**17 if os.environ.get("FTBENCH_PAYLOAD") == "image" else 2**16


@dataclass
class Sample:
    """One message: sequence number, send stamp (ns), one sample, and the end-of-stream flag."""

    seq: int
    t_ns: int
    data: np.ndarray
    end: bool = False


class SourceSettings(ez.Settings):
    payload: str
    rate_hz: float
    seconds: float
    out: str


class Source(ez.Unit):
    SETTINGS = SourceSettings
    OUTPUT = ez.OutputStream(Sample, buf_size=BUF_SIZE)

    @ez.publisher(OUTPUT)
    async def emit(self) -> AsyncGenerator:
        s = self.SETTINGS
        await asyncio.sleep(0.5)  # let every subscriber attach before the clock starts
        frame = np.random.default_rng(0).integers(0, 256, SHAPES["image"][0], dtype=np.uint8)
        start = time.monotonic_ns()
        first = last = start
        k = 0
        if s.rate_hz > 0:
            period = 1e9 / s.rate_hz
            for k in range(round(s.seconds * s.rate_hz)):
                delay = start + k * period - time.monotonic_ns()
                if delay > 0:
                    await asyncio.sleep(delay / 1e9)
                data = np.full((1, 4), float(k)) if s.payload == "small" else frame
                now = time.monotonic_ns()
                yield self.OUTPUT, Sample(k, now, data)
                first = now if k == 0 else first
                last = now
            k = round(s.seconds * s.rate_hz)
        else:
            stop_at = start + int(s.seconds * 1e9)
            while True:
                data = np.full((1, 4), float(k)) if s.payload == "small" else frame
                now = time.monotonic_ns()
                if now >= stop_at:
                    break
                yield self.OUTPUT, Sample(k, now, data)
                first = now if k == 0 else first
                last = now
                k += 1
        end = time.monotonic_ns()
        info = {"sent": k, "start_ns": start, "end_ns": end, "first_ns": first, "last_ns": last}
        Path(s.out, "source.json").write_text(json.dumps(info))
        yield self.OUTPUT, Sample(k, time.monotonic_ns(), data, end=True)


class StageSettings(ez.Settings):
    payload: str


class Stage(ez.Unit):
    SETTINGS = StageSettings
    INPUT = ez.InputStream(Sample)
    OUTPUT = ez.OutputStream(Sample, buf_size=BUF_SIZE)

    @ez.subscriber(INPUT)
    @ez.publisher(OUTPUT)
    async def on_sample(self, msg: Sample) -> AsyncGenerator:
        if msg.end:
            yield self.OUTPUT, msg
            return
        y = 2.0 * msg.data if self.SETTINGS.payload == "small" else 255 - msg.data
        yield self.OUTPUT, Sample(msg.seq, msg.t_ns, y)


class SinkSettings(ez.Settings):
    out: str


class SinkState(ez.State):
    sent: list
    recv: list


class Sink(ez.Unit):
    SETTINGS = SinkSettings
    STATE = SinkState
    INPUT = ez.InputStream(Sample)

    async def initialize(self) -> None:
        self.STATE.sent = []
        self.STATE.recv = []

    @ez.subscriber(INPUT)
    async def on_sample(self, msg: Sample) -> None:
        now = time.monotonic_ns()
        if msg.end:
            np.savez(
                Path(self.SETTINGS.out, "sink.npz"),
                sent_ns=np.asarray(self.STATE.sent, np.int64),
                recv_ns=np.asarray(self.STATE.recv, np.int64),
            )
            raise ez.NormalTermination
        self.STATE.sent.append(msg.t_ns)
        self.STATE.recv.append(now)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--payload", choices=sorted(SHAPES), default="small")
    ap.add_argument("--rate", type=float, default=1000.0, help="messages/s (0: flat out)")
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--out", required=True, help="folder for source.json and sink.npz")
    a = ap.parse_args()
    if os.environ.get("FTBENCH_PAYLOAD", "small") != a.payload:
        raise SystemExit("set FTBENCH_PAYLOAD to the --payload (it sizes the shared-memory buffers)")
    source = Source(SourceSettings(payload=a.payload, rate_hz=a.rate, seconds=a.seconds, out=a.out))
    stage = Stage(StageSettings(payload=a.payload))
    sink = Sink(SinkSettings(out=a.out))
    ez.run(
        components={"SOURCE": source, "STAGE": stage, "SINK": sink},
        connections=((source.OUTPUT, stage.INPUT), (stage.OUTPUT, sink.INPUT)),
        process_components=(stage, sink),
    )


if __name__ == "__main__":
    main()
