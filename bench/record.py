"""Cost of HDF5 recording: Recorder.write per call and Recorder.flush per second of data (one core).

A flush makes one second of data durable: it appends to a hidden full copy of the file and swaps
it in with an atomic rename (flowtact/record.py explains why plain HDF5 is not crash-safe).

    python bench/record.py
"""

from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from flowtact.chunk import Chunk, StreamSpec
from flowtact.record import Recorder


def run(streams: dict[str, StreamSpec], per_write: int, n_flush: int = 20) -> tuple[float, float]:
    """Median µs per write() call and ms per flush() of 1 s of 1 kHz data."""
    tmp = Path(tempfile.mkdtemp())
    rec = Recorder(tmp / "b.h5", streams, {"graph_yaml": "bench"}, flush_interval_s=1e9)
    i, write_s, flush_s = 0, [], []
    for _ in range(n_flush):
        for _ in range(1000 // per_write):
            t = (i + np.arange(per_write)) / 1000.0
            t0 = time.perf_counter()
            for name, spec in streams.items():
                if spec.events:
                    rec.write(name, Chunk(t[::5], np.zeros(len(t[::5]), np.int64), end=t[-1]))
                elif spec.rate_hz == 40.0:
                    if i % 25 == 0:
                        rec.write(name, Chunk(t[:1], np.zeros((1, *spec.shape), np.uint8)))
                else:
                    rec.write(name, Chunk(t, np.ones((per_write, *spec.shape))))
            write_s.append((time.perf_counter() - t0) / len(streams))
            i += per_write
        t0 = time.perf_counter()
        rec.flush()
        flush_s.append(time.perf_counter() - t0)
    rec.close()
    return statistics.median(write_s), statistics.median(flush_s)


def main() -> None:
    streams = {f"n{k}.f": StreamSpec("float64", (3,), "N", 1000.0) for k in range(3)}
    streams["sa1.spikes"] = StreamSpec("int64", (), "1", None, events=True, n_units=24)
    print(f"{'case':52s} {'write/call':>12s} {'flush (1 s data)':>18s}")
    for per in (1, 5, 100):
        w, f = run(streams, per)
        case = f"3 x float64[3] @ 1 kHz + spikes, {per} samples/write"
        print(f"{case:52s} {w * 1e6:9.1f} us {f * 1e3:15.2f} ms")
    frames = {**streams, "cam.frame": StreamSpec("uint8", (240, 320), "1", 40.0)}
    w, f = run(frames, 5)
    print(
        f"{'same + 240x320 uint8 frames @ 40 Hz, 5 samples/write':52s} {w * 1e6:9.1f} us {f * 1e3:15.2f} ms"
    )


if __name__ == "__main__":
    main()
