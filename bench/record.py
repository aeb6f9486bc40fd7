"""Suite ``record``: cost of HDF5 recording, Recorder.write per call and Recorder.flush per second of data.

A flush makes one second of data durable: it appends to a hidden full copy of the file and swaps
it in with an atomic rename (flowtact/recording/hdf5.py explains why plain HDF5 is not crash-safe). The
baseline writes the same chunks with plain h5py (resizable datasets, ``file.flush()``), which is
neither checksummed nor crash-safe: the ratio is the price of those guarantees.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from flowtact.benchmark import Context, Suite
from flowtact.chunk import Chunk, StreamSpec
from flowtact.recording.hdf5 import Recorder


class PlainH5:
    """The baseline: append each chunk to resizable h5py datasets, ``flush()`` on request."""

    def __init__(self, path: Path, streams: dict[str, StreamSpec]) -> None:
        import h5py

        self.f = h5py.File(path, "w")
        self.ds = {}
        for name, spec in streams.items():
            g = self.f.create_group(name)
            shape = () if spec.events else tuple(spec.shape)
            self.ds[name] = (
                g.create_dataset("t", (0,), "f8", maxshape=(None,), chunks=(4096,)),
                g.create_dataset("data", (0, *shape), spec.dtype, maxshape=(None, *shape), chunks=True),
            )

    def write(self, name: str, c: Chunk) -> None:
        for ds, x in zip(self.ds[name], (c.t, c.data), strict=True):
            n = ds.shape[0]
            ds.resize(n + len(x), axis=0)
            ds[n:] = x

    def flush(self) -> None:
        self.f.flush()

    def close(self) -> None:
        self.f.close()


def run_case(
    streams: dict[str, StreamSpec], per_write: int, n_flush: int, plain: bool
) -> tuple[list[float], list[float]]:
    """µs per write() call and ms per flush() of 1 s of 1 kHz data, every call's."""
    tmp = Path(tempfile.mkdtemp(prefix="flowtact-bench-record-"))
    rec = (
        PlainH5(tmp / "b.h5", streams)
        if plain
        else Recorder(tmp / "b.h5", streams, {"graph_yaml": "bench"}, flush_interval_s=1e9)
    )
    i, write_us, flush_ms = 0, [], []
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
            write_us.append((time.perf_counter() - t0) / len(streams) * 1e6)
            i += per_write
        t0 = time.perf_counter()
        rec.flush()
        flush_ms.append((time.perf_counter() - t0) * 1e3)
    rec.close()
    return write_us, flush_ms


def run(ctx: Context) -> None:
    streams = {f"n{k}.f": StreamSpec("float64", (3,), "N", 1000.0) for k in range(3)}
    streams["sa1.spikes"] = StreamSpec("int64", (), "1", None, events=True, n_units=24)
    frames = {**streams, "cam.frame": StreamSpec("uint8", (240, 320), "1", 40.0)}
    n_flush = 5 if ctx.quick else 20
    cases = [(f"3 x float64[3] @ 1 kHz + spikes, {per} samples/write", streams, per) for per in (1, 5, 100)]
    cases.append(("same + 240x320 uint8 frames @ 40 Hz, 5 samples/write", frames, 5))
    for label, st, per in cases:
        ctx.step(label)
        params = {"samples_per_write": per, "streams": sorted(st)}
        w0, f0 = run_case(st, per, n_flush, plain=True)
        w1, f1 = run_case(st, per, n_flush, plain=False)
        ctx.figure(
            f"plain h5py write, {label}",
            w0,
            "µs per write",
            "lower",
            is_baseline=True,
            reference=True,
            params=params,
        )
        ctx.figure(
            f"Recorder.write, {label}",
            w1,
            "µs per write",
            "lower",
            baseline=f"plain h5py write, {label}",
            params=params,
        )
        ctx.figure(
            f"plain h5py flush, {label}",
            f0,
            "ms per flush (1 s of data)",
            "lower",
            is_baseline=True,
            reference=True,
            params=params,
        )
        ctx.figure(
            f"Recorder.flush, {label}",
            f1,
            "ms per flush (1 s of data)",
            "lower",
            baseline=f"plain h5py flush, {label}",
            params=params,
        )
    ctx.note(
        "Recorder.flush writes every sample a second time (the crash-safe atomic-rename scheme) and checksums "
        "it, once per second; plain h5py does neither, so expect the Recorder's flush to be the slower one. "
        "Recorder.write buffers in memory until a flush while plain h5py writes through on every call, so "
        "the write ratio mostly shows the buffering."
    )


SUITE = Suite(
    name="record",
    title="HDF5 recording: write per call and flush per second of data",
    measures="µs per `Recorder.write` call and ms per `Recorder.flush` of 1 s of data, for 3 float64[3] "
    "streams at 1 kHz plus spikes (1, 5, 100 samples per write), and with 240×320 frames at 40 Hz.",
    baseline="plain h5py appending the same chunks to resizable datasets and calling `File.flush()` "
    "(no checksums, not crash-safe)",
    run=run,
    minutes_quick=0.3,
    minutes_full=0.5,
)
