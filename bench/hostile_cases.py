"""Hostile inputs too large to keep in the corpus, generated on demand, and a child that measures itself.

Each case writes its file(s) into a folder and returns the ``flowtact`` arguments and the
``file:line:col: text`` the refusal must show. :func:`run_measured` runs ``flowtact`` in a child
Python that reports its own peak RSS, under a generous timeout that only catches hangs.
Used by tests/inputs/test_hostile_input.py (through tests/hostile.py) and by the ``hostile_input`` suite
(wall time, peak RSS); it lives here so that the suite runs from an installed wheel.
"""

from __future__ import annotations

import io
import os
import re
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from importlib.resources import files
from importlib.util import find_spec
from pathlib import Path
from typing import Any

TOUCH = str(files("flowtact.graphs") / "touch.yaml")

# the child: run the CLI, then print its own peak resident set size: VmHWM, which starts afresh at
# exec (ru_maxrss would carry the parent's peak across fork + exec, e.g. a 1 GB pytest process)
_CHILD = (
    "import resource, sys\n"
    "resource.setrlimit(resource.RLIMIT_AS, (4 << 30, 4 << 30))  # a backstop: fail, never swap\n"
    "from flowtact.cli import main\n"
    "try:\n"
    "    rc = main(sys.argv[1:])\n"
    "except SystemExit as e:\n"
    "    rc = e.code\n"
    "hwm = next(x for x in open('/proc/self/status') if x.startswith('VmHWM:')).split()[1]\n"
    "print(f'peak_rss_kib={hwm}', file=sys.stderr)\n"
    "sys.exit(rc)\n"
)


@dataclass(frozen=True)
class Measured:
    """What one child run did: exit status, stderr, wall seconds and peak RSS in MiB."""

    returncode: int
    stderr: str
    seconds: float
    peak_mib: float


def run_measured(args: list[str], timeout_s: float = 120.0) -> Measured:
    """``flowtact ARGS`` in a child process; a hang raises ``subprocess.TimeoutExpired``."""
    start = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-c", _CHILD, *args],
        capture_output=True,
        text=True,
        timeout=timeout_s,
        env={**os.environ, "PYTHONFAULTHANDLER": "1"},
    )
    seconds = time.perf_counter() - start
    m = re.search(r"peak_rss_kib=(\d+)", proc.stderr)
    peak = int(m.group(1)) / 1024 if m else float("nan")
    return Measured(proc.returncode, proc.stderr, seconds, peak)


def _write(folder: Path, name: str, text: str | bytes) -> str:
    path = folder / name
    path.write_bytes(text.encode() if isinstance(text, str) else text)
    return str(path)


def big_file(folder: Path) -> tuple[list[str], str]:
    path = folder / "big.yaml"
    with open(path, "wb") as f:
        f.truncate(50 << 20)  # 50 MB (sparse): only the size matters
    return ["validate", str(path)], f"{path}:1:1: graph file larger than 1 MiB"


def big_file_grown_text(folder: Path) -> tuple[list[str], str]:
    line = b"# " + b"x" * 1000 + b"\n"
    path = _write(folder, "comments.yaml", line * (60 << 10))  # 60 MB of comments
    return ["validate", path], f"{path}:1:1: graph file larger than 1 MiB"


def alias_bomb(folder: Path) -> tuple[list[str], str]:
    lines = ['a0: &a0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    for i in range(1, 10):
        lines.append(f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 9)}]")
    path = _write(folder, "laughs.yaml", "\n".join(lines) + "\nnodes: {}\n")
    return ["validate", path], "the document expands to more than 50000 values"


def deep_lists(folder: Path) -> tuple[list[str], str]:
    path = _write(folder, "deep_lists.yaml", "nodes: " + "[" * 5000 + "]" * 5000 + "\n")
    return ["validate", path], f"{path}:1:71: nested more than 64 levels deep"


def deep_mappings(folder: Path) -> tuple[list[str], str]:
    path = _write(folder, "deep_maps.yaml", "nodes: " + "{a: " * 3000 + "1" + "}" * 3000 + "\n")
    return ["validate", path], f"{path}:1:"  # the column of the 65th '{'


def wide_list(folder: Path) -> tuple[list[str], str]:
    # just under the size limit: half a million values, refused by the node count, not by memory
    path = _write(folder, "wide.yaml", "nodes: [" + "0," * ((1 << 19) - 16) + "0]\n")
    return ["validate", path], "the document expands to more than 50000 values"


def dev_zero(folder: Path) -> tuple[list[str], str]:  # noqa: ARG001 - every case takes the folder
    return ["validate", "/dev/zero"], "/dev/zero:1:1: not a regular file"


def fifo(folder: Path) -> tuple[list[str], str]:
    path = folder / "graph.fifo"
    os.mkfifo(path)  # nobody ever writes: opening it for reading would block forever
    return ["validate", str(path)], f"{path}:1:1: not a regular file"


def huge_population(folder: Path) -> tuple[list[str], str]:  # noqa: ARG001
    return [
        "validate",
        TOUCH,
        "--set",
        "sa1.n=99999999999999",
    ], "--set:1:1: sa1 (nlif): 'n' must be small enough"


def huge_window(folder: Path) -> tuple[list[str], str]:  # noqa: ARG001
    return [
        "validate",
        TOUCH,
        "--set",
        "dforce.window=1000001",
    ], "--set:1:1: dforce (savgol): 'window' must be <= 10001"


def alias_bomb_in_set(folder: Path) -> tuple[list[str], str]:  # noqa: ARG001
    value = "[" + ", ".join(["&a [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]"] + ["*a"] * 20000) + "]"
    return ["validate", TOUCH, "--set", f"sa1.tau_s={value}"], "--set:1:1: --set 'sa1.tau_s="


# -- replay readers (``--replay NODE=FILE`` and the ``replay`` block): one case per class ----------
# Every file a replay reads is bounded before it allocates (blocks/signal/replay_limits.py).

_GAUGES = "t,r[0],r[1],r[2],r[3],ref\n"  # the columns that stand in for touch.yaml's sensor


def _zip_member(name: str, data: bytes | None, *, zeros: int = 0) -> tuple[bytes, bytes]:
    """(local entry, central directory entry) of one deflated zip member: ``data`` then ``zeros``
    zero bytes, deflated 16 MiB at a time (each block compresses to the same 16 kB: fast)."""
    import struct
    import zlib

    comp = zlib.compressobj(9, zlib.DEFLATED, -15)
    block = bytes(16 << 20)
    head = comp.compress(data or b"") + comp.flush(zlib.Z_FULL_FLUSH)
    crc = zlib.crc32(data or b"")
    body = [head]
    full, rest = divmod(zeros, len(block))
    if full:
        packed = comp.compress(block) + comp.flush(zlib.Z_FULL_FLUSH)
        body += [packed] * full
        for _ in range(full):
            crc = zlib.crc32(block, crc)
    body.append(comp.compress(bytes(rest)) + comp.flush())
    crc = zlib.crc32(bytes(rest), crc)
    packed = b"".join(body)
    size, key = len(data or b"") + zeros, name.encode()
    fields = (20, 0, 8, 0, 0x21, crc, len(packed), size, len(key))
    local = struct.pack("<4s5H3L2H", b"PK\x03\x04", *fields, 0) + key + packed
    central = struct.pack("<4s4H2H3L5H2L", b"PK\x01\x02", 20, *fields, 0, 0, 0, 0, 0, 0) + key
    return local, central


def _zip(path: Path, members: list[tuple[bytes, bytes]]) -> None:
    """A zip archive of prepared members (see :func:`_zip_member`)."""
    import struct

    out, directory, offsets = b"", b"", []
    for local, _ in members:
        offsets.append(len(out))
        out += local
    for (_, central), offset in zip(members, offsets, strict=True):
        directory += central[:42] + struct.pack("<L", offset) + central[46:]
    end = struct.pack(
        "<4s4H2LH", b"PK\x05\x06", 0, 0, len(members), len(members), len(directory), len(out), 0
    )
    path.write_bytes(out + directory + end)


def _npy_header(shape: tuple[int, ...], descr: str = "<f8") -> bytes:
    import numpy as np

    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, {"descr": descr, "fortran_order": False, "shape": shape})
    return buf.getvalue()


def _replay_graph(folder: Path, data: str) -> str:
    """A graph of one ``replay`` node playing ``data``, recorded."""
    return _write(
        folder,
        "replay.yaml",
        f"nodes:\n  log: {{block: replay, params: {{path: {data}}}}}\nrecord: [log.y]\n",
    )


def replay_npz_zip_bomb(folder: Path) -> tuple[list[str], str]:
    """1.2 MB of .npz whose 't' inflates (honestly: sizes and CRC agree) to 1.125 GiB."""
    n = 9 << 24  # 1.125 GiB of float64 time stamps
    path = folder / "bomb.npz"
    head = _npy_header((n,))
    _zip(path, [_zip_member("data.npy", _npy_header((n, 0))), _zip_member("t.npy", head, zeros=8 * n)])
    return ["validate", _replay_graph(folder, str(path))], f"array 't' ({n},) float64 takes 1.1 GiB, over the"


def replay_npz_lying_header(folder: Path) -> tuple[list[str], str]:
    """A .npz whose 't' header declares 2**40 samples in a 16-byte member."""
    path = folder / "lies.npz"
    _zip(
        path,
        [
            _zip_member("data.npy", _npy_header((2,)) + bytes(16)),
            _zip_member("t.npy", _npy_header((1 << 40,)) + bytes(16)),
        ],
    )
    return ["validate", _replay_graph(folder, str(path))], "declares shape (1099511627776,) of float64"


def _replayed(
    path: str | Path, refusal: str, *, command: str = "validate", line: int = 1
) -> tuple[list[str], str]:
    """touch.yaml with ``path`` replayed as its sensor, and the refusal located at the file (by name:
    the refusal shows the path as given, relative when the run is beside it)."""
    fast = ["--fast"] if command == "run" else []
    return [
        command,
        TOUCH,
        *fast,
        "--replay",
        f"sensor={path}",
    ], f"{Path(path).name}:{line}:1: node 'sensor' (replay): {refusal}"


def replay_h5_not_hdf5_sparse(folder: Path) -> tuple[list[str], str]:
    """A 1 GB sparse file named .h5: refused from its first bytes, never read whole."""
    path = folder / "big.h5"
    with open(path, "wb") as f:
        f.truncate(1 << 30)
    return _replayed(path, "")


def replay_csv_sparse(folder: Path) -> tuple[list[str], str]:
    """A 1 GB sparse .csv: over the size a .csv log may be, refused from its size."""
    path = folder / "big.csv"
    with open(path, "wb") as f:
        f.truncate(1 << 30)
    return _replayed(path, "1.0 GiB: larger than")


def replay_csv_wide_header(folder: Path) -> tuple[list[str], str]:
    """A .csv naming 100 000 columns (a quadratic header check took minutes)."""
    names = ",".join(["t", *(f"c{i}" for i in range(1, 100_000))])
    path = _write(folder, "wide.csv", names + "\n")
    return _replayed(path, "100000 columns")


def replay_csv_long_line(folder: Path) -> tuple[list[str], str]:
    """A .csv whose header is one 10 MB line."""
    path = _write(folder, "long.csv", "t," + "x" * (10 << 20) + "\n0,1\n")
    return _replayed(path, "a line longer than")


def replay_csv_far_times(folder: Path) -> tuple[list[str], str]:
    """Time stamps 1e300 s apart: a run to the file's end would never end."""
    path = _write(folder, "far.csv", _GAUGES + "0,0,0,0,0,0\n1e300,0,0,0,0,0\n")
    return _replayed(path, "", command="run", line=3)


def replay_csv_rate(folder: Path) -> tuple[list[str], str]:
    """Time stamps 1 ns apart: a 1 GHz stream, beyond what a replay may give."""
    rows = "".join(f"{i}e-9,0,0,0,0,0\n" for i in range(3))
    path = _write(folder, "fast.csv", _GAUGES + rows)
    return _replayed(path, "port 'r': sensor (replay): its time stamps step at 1e+09 Hz")


def _h5_stream(g: Any, samples: int, shape: tuple[int, ...]) -> None:
    """A stream group as record.py writes it (no checksums: an old-format file), declaring
    ``samples`` samples of which none is stored."""
    g.attrs.update(
        {"events": 0, "rate_hz": 1000.0, "units": "1", "dtype": "float64", "shape": str(list(shape))}
    )
    g.create_dataset("t", (samples,), "f8", maxshape=(None,), chunks=(8192,))
    g.create_dataset("data", (samples, *shape), "f8", maxshape=(None, *shape), chunks=(8192, *shape))


def replay_h5_huge_declared(folder: Path) -> tuple[list[str], str]:
    """A recording whose streams declare 2**40 samples (none stored): `validate` used to accept it."""
    import h5py

    path = folder / "huge.h5"
    with h5py.File(path, "w") as f:
        streams = f.create_group("streams")
        _h5_stream(streams.create_group("sensor.r"), 1 << 40, (4,))
        _h5_stream(streams.create_group("sensor.ref"), 1 << 40, ())
    return ["run", TOUCH, "--fast", "--replay", f"sensor={path}"], "declares 1,099,511,627,776 values"


def replay_h5_many_streams(folder: Path) -> tuple[list[str], str]:
    """A recording of 10 001 (empty) streams: over the count a replay lists."""
    import h5py

    path = folder / "many.h5"
    with h5py.File(path, "w") as f:
        streams = f.create_group("streams")
        for i in range(10_001):
            streams.create_group(f"s{i}.y")
    return [
        "validate",
        TOUCH,
        "--replay",
        f"sensor={path}",
    ], "10001 streams; a replayed recording may hold at most"


def replay_fifo(folder: Path) -> tuple[list[str], str]:
    """A FIFO named like a log: refused without opening it for a blocking read."""
    path = folder / "log.csv"
    os.mkfifo(path)
    return _replayed(path, "not a regular file (a FIFO)")


REPLAY_CASES: dict[str, Callable[[Path], tuple[list[str], str]]] = {
    f.__name__: f
    for f in (
        replay_npz_zip_bomb,
        replay_npz_lying_header,
        replay_h5_not_hdf5_sparse,
        replay_csv_sparse,
        replay_csv_wide_header,
        replay_csv_long_line,
        replay_csv_far_times,
        replay_csv_rate,
        replay_h5_huge_declared,
        replay_h5_many_streams,
        replay_fifo,
    )
}
"""The replay readers' hostile cases (part of :data:`CASES`)."""

# -- end of the replay readers' cases ------------------------------------------------------------


CASES: dict[str, Callable[[Path], tuple[list[str], str]]] = REPLAY_CASES | {
    f.__name__: f
    for f in (
        big_file,
        big_file_grown_text,
        alias_bomb,
        deep_lists,
        deep_mappings,
        wide_list,
        dev_zero,
        fifo,
        huge_population,
        huge_window,
        alias_bomb_in_set,
    )
}
"""Every hostile case by name: folder -> (flowtact arguments, text the refusal must show)."""


# == recordings and model files (issue 30): every reader bounded before it allocates ==================
# Each case writes a small (or sparse) file whose headers promise far more than it holds, or a FIFO;
# the refusal must name the file and the bound, exit 2, within the harness's time and memory.


def _recording(folder: Path, name: str, build: Callable[[Any, Any], None]) -> str:
    """A minimal recording (a /streams group, no checksums: format 1) with ``build(file, stream)``."""
    import h5py

    path = folder / name
    with h5py.File(path, "w") as f:
        build(f, f.create_group("streams/s.y"))
    return str(path)


def recording_huge_chunk(folder: Path) -> tuple[list[str], str]:
    def build(_f: Any, g: Any) -> None:  # one 1 GiB chunk, never written: reading it fills 1 GiB
        g.create_dataset("data", shape=(1 << 27,), dtype="f8", chunks=(1 << 27,))

    path = _recording(folder, "chunk.h5", build)
    return ["info", path], f"{path}: /streams/s.y/data: stored in chunks of 1.0 GiB (at most 16.0 MiB)"


def recording_declared_samples(folder: Path) -> tuple[list[str], str]:
    def build(_f: Any, g: Any) -> None:  # 2^40 samples declared, none stored
        g.create_dataset("data", shape=(1 << 40,), dtype="f8", chunks=(8192,))

    path = _recording(folder, "declared.h5", build)
    return ["plot", path, "-o", str(folder / "p.png")], (
        f"{path}: /streams/s.y/data: declares 1,099,511,627,776 values (8.0 TiB) but stores 0 B"
    )


def recording_big_attribute(folder: Path) -> tuple[list[str], str]:
    def build(f: Any, _g: Any) -> None:  # 100 MB of text in one attribute (its heap is one piece)
        f.attrs["command"] = "x" * (100 << 20)

    path = _recording(folder, "attr.h5", build)
    return [
        "info",
        path,
    ], f"{path}: /: attribute 'command' is larger than 1.0 MiB (refused before it was read)"


def recording_forged_attribute_length(folder: Path) -> tuple[list[str], str]:
    import struct

    def build(f: Any, _g: Any) -> None:
        f.attrs["command"] = "q" * 12345

    path = _recording(folder, "forged.h5", build)
    raw = bytearray(Path(path).read_bytes())  # the text's stored length, 12345, becomes 1 GiB
    at = raw.index(struct.pack("<I", 12345), raw.index(b"command"))
    raw[at : at + 4] = struct.pack("<I", 1 << 30)
    Path(path).write_bytes(raw)
    return [
        "info",
        path,
    ], f"{path}: /: attribute 'command' is larger than 1.0 MiB (refused before it was read)"


def recording_many_streams(folder: Path) -> tuple[list[str], str]:
    def build(f: Any, g: Any) -> None:  # 4097 links to one stream: one more than the bound
        for i in range(4096):
            f[f"streams/s{i}.y"] = g

    path = _recording(folder, "many.h5", build)
    return ["info", path], f"{path}: holds 4,097 streams (at most 4,096)"


def recording_sparse_not_hdf5(folder: Path) -> tuple[list[str], str]:
    path = folder / "sparse.h5"
    with open(path, "wb") as f:
        f.truncate(1 << 30)  # 1 GiB of nothing: only its first bytes may be read
    return ["info", str(path)], f"{path}: not a readable HDF5 file (it has no HDF5 signature)"


def recording_fifo(folder: Path) -> tuple[list[str], str]:
    path = folder / "rec.h5"
    os.mkfifo(path)  # nobody writes: h5py opening it would block forever
    return ["run", str(path), "--duration", "1"], f"{path}:1:1: not a regular file (a FIFO)"


BRAILLE = str(files("flowtact.graphs") / "braille.yaml")
TELEOP_CNN = str(files("flowtact.graphs") / "teleop_cnn.yaml")


def nb_model_zip_bomb(folder: Path) -> tuple[list[str], str]:
    import zipfile

    import numpy as np

    path = folder / "bomb.npz"  # about 4 MB on disk; its one member declares 1 GiB of zeros
    header = {"descr": "<f8", "fortran_order": False, "shape": (1 << 27,)}
    zf = zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED, compresslevel=1)
    with zf, zf.open("meta.npy", "w", force_zip64=True) as f:
        np.lib.format.write_array_header_1_0(f, header)
        block = bytes(16 << 20)
        for _ in range(64):
            f.write(block)
    return ["validate", BRAILLE, "--set", f"decoder.model={path}"], (
        f"{path}: not a readable naive Bayes model file (member meta.npy declares 1.0 GiB: over the "
        "64.0 MiB budget"
    )


def nb_model_fifo(folder: Path) -> tuple[list[str], str]:
    path = folder / "model.npz"
    os.mkfifo(path)
    return ["validate", BRAILLE, "--set", f"decoder.model={path}"], (
        f"{path}: not a readable naive Bayes model file (not a regular file (a FIFO))"
    )


def cnn_checkpoint_too_wide(folder: Path) -> tuple[list[str], str]:
    import json

    path = folder / "wide.pt"  # its metadata (the .json beside it) asks for 5000 filters per stage
    path.write_bytes(b"")
    meta = {
        "format": "flowtact-force-cnn",
        "format_version": 1,
        "arch": {"n_conv": 4, "width": 5000, "fc": 128, "kernel": 3, "batch_norm": True},
        "preprocess": {"input_hw": [90, 240], "crop": None, "downsample": 4},
        "label_mean_n": 0.0,
        "label_std_n": 1.0,
    }
    path.with_suffix(".json").write_text(json.dumps(meta))
    return ["validate", TELEOP_CNN, "--set", f"cnn.checkpoint={path}"], (
        f"{path}: arch.width must be an integer in 1..1024; got 5000"
    )


def cnn_checkpoint_escapes(folder: Path) -> tuple[list[str], str]:
    import types

    import torch

    path = folder / "evil.pt"  # pickles a class whose module name clears the screen and retitles
    module = "evil\x1b[2J\x1b]0;pwned\x07"
    sys.modules[module] = types.SimpleNamespace(Boom=type("Boom", (), {"__module__": module}))
    try:
        torch.save({"format": "flowtact-force-cnn", "x": sys.modules[module].Boom()}, path)
    finally:
        del sys.modules[module]
    return ["validate", TELEOP_CNN, "--set", f"cnn.checkpoint={path}"], (
        f"{path}: not a flowtact CNN checkpoint (torch refused it: Unsupported global: "
        "GLOBAL evil\\x1b[2J\\x1b]0;pwned\\x07.Boom was not an allowed global by default.)"
    )


CASES.update(
    {
        f.__name__: f
        for f in (
            *(
                (cnn_checkpoint_too_wide, cnn_checkpoint_escapes) if find_spec("torch") else ()
            ),  # the cnn extra
            nb_model_zip_bomb,
            nb_model_fifo,
            recording_huge_chunk,
            recording_declared_samples,
            recording_big_attribute,
            recording_forged_attribute_length,
            recording_many_streams,
            recording_sparse_not_hdf5,
            recording_fifo,
        )
    }
)
