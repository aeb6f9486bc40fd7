"""The wire format of a stream message: a fixed binary header, then the raw numpy buffers.

The header is little-endian: a fixed part (magic, flags, ndim, number of origins, dtype length,
stream, seq, tick, watermark ``end`` or NaN), the dtype string and the sample shape (cached per
stream: they rarely change), then the ``origins``: pairs mapping a source index to the monotonic
time (ns) at which the oldest data behind the chunk left that source, for latency. It is padded
to a multiple of 8 bytes (the arrays behind it are as aligned as the frame). A small chunk travels as one frame
``header + t + data`` (per-message costs dominate small messages; pyzmq advises zero-copy only
above ~64 KiB); a large one (data of :data:`COPY_THRESHOLD` bytes or more, a camera frame) as the
multipart message ``[header, t, data]``, flagged in the header so the receiver reads its frames
without asking the socket per frame, sent without copying and received as read-only views of the
ZeroMQ frames. The format is internal to workers of one flowtact version; a frame that does not
parse raises :class:`WireError` naming what is wrong. Never pickle.
"""

from __future__ import annotations

import functools
import math
import struct
from dataclasses import dataclass

import numpy as np
import zmq

from flowtact.chunk import Chunk
from flowtact.errors import WireError

__all__ = ["COPY_THRESHOLD", "END", "Message", "recv_message", "send_message"]

END = 1
"""Flag: the producer has finished; this message carries its end-of-stream output."""
_MULTI = 2
"""Flag (internal): the message is ``[header, t, data]`` in three frames."""

COPY_THRESHOLD = 65536
"""Buffers smaller than this are copied into the message (cheaper than zero-copy bookkeeping)."""

MAGIC = 0xF7
_FIXED = struct.Struct("<BBBBBxxxiqqd")  # magic, flags, ndim, n_origins, dtype len; stream seq tick end
_EMPTY_T = np.empty(0, np.float64)
_NAN = math.nan


@dataclass(slots=True)
class Message:
    """One decoded stream message."""

    stream: int
    seq: int
    tick: int
    flags: int
    origins: dict[int, int]
    chunk: Chunk

    @property
    def is_end(self) -> bool:
        """Is this the producer's end-of-stream marker?"""
        return bool(self.flags & END)


@functools.cache
def _describe(dtype: str, shape: tuple[int, ...]) -> tuple[bytes, int, int]:
    """The dtype/shape bytes of a header (cached per stream layout), their ndim and dtype length."""
    d = dtype.encode()
    return d + struct.pack(f"<{len(shape)}q", *shape), len(shape), len(d)


@functools.cache
def _origins_struct(n: int) -> struct.Struct:
    return struct.Struct(f"<{2 * n}q")


_PAD = [b"\0" * i for i in range(8)]


def _header(
    stream: int,
    seq: int,
    tick: int,
    flags: int,
    end: float | None,
    origins: dict[int, int] | None,
    data: np.ndarray,
) -> bytes:
    desc, ndim, dlen = _describe(data.dtype.str, data.shape[1:])
    n = len(origins) if origins else 0
    fixed = _FIXED.pack(MAGIC, flags, ndim, n, dlen, stream, seq, tick, _NAN if end is None else end)
    if n:
        pairs = [v for item in origins.items() for v in item]  # type: ignore[union-attr]
        body = desc + _origins_struct(n).pack(*pairs)
    else:
        body = desc
    return fixed + body + _PAD[-len(body) % 8]


def send_message(
    sock: zmq.Socket,
    stream: int,
    seq: int,
    tick: int,
    chunk: Chunk,
    origins: dict[int, int] | None = None,
    flags: int = 0,
    nowait: bool = False,
) -> bool:
    """Send one chunk; with ``nowait`` return False instead of blocking when the queue is full."""
    data = chunk.data if chunk.data.flags.c_contiguous else np.ascontiguousarray(chunk.data)
    t = chunk.t
    if t.dtype != np.float64 or not t.flags.c_contiguous:
        t = np.ascontiguousarray(t, dtype=np.float64)
    zflags = zmq.NOBLOCK if nowait else 0
    try:
        if data.nbytes >= COPY_THRESHOLD:
            header = _header(stream, seq, tick, flags | _MULTI, chunk.end, origins, data)
            sock.send_multipart([header, t, data], flags=zflags, copy=False)
        else:
            header = _header(stream, seq, tick, flags, chunk.end, origins, data)
            sock.send(b"".join((header, t, data)), flags=zflags)
    except zmq.Again:
        return False
    return True


@functools.cache
def _layout(desc: bytes, ndim: int, dlen: int) -> tuple[np.dtype, tuple[int, ...], int]:
    """dtype, sample shape and bytes per sample (data only) of a header's dtype/shape bytes."""
    try:
        dt = np.dtype(desc[:dlen].decode("ascii"))
    except (TypeError, ValueError, UnicodeDecodeError) as e:
        raise WireError(f"bad dtype {desc[:dlen]!r} in a stream message header") from e
    if dt.hasobject:
        raise WireError(f"object dtype {dt} in a stream message header")
    shape = struct.unpack_from(f"<{ndim}q", desc, dlen)
    if any(s < 0 for s in shape):
        raise WireError(f"negative sample shape {shape} in a stream message header")
    return dt, shape, dt.itemsize * math.prod(shape)


def _parse_header(
    buf: bytes | memoryview,
) -> tuple[int, int, int, int, float | None, dict[int, int], np.dtype, tuple[int, ...], int, int]:
    """stream, seq, tick, flags, end, origins, dtype, shape, bytes per sample, header length."""
    if len(buf) < _FIXED.size:
        raise WireError(f"a {len(buf)}-byte frame is too short for a stream message header")
    magic, fl, ndim, n, dlen, stream, seq, tick, end = _FIXED.unpack_from(buf)
    if magic != MAGIC:
        raise WireError(f"not a flowtact stream message (first byte {magic:#x}, expected {MAGIC:#x})")
    at = _FIXED.size
    body = dlen + 8 * ndim + 16 * n
    hlen = at + body + (-body % 8)
    if len(buf) < hlen:
        raise WireError(f"a {len(buf)}-byte frame is shorter than its {hlen}-byte header")
    dt, shape, width = _layout(bytes(buf[at : at + dlen + 8 * ndim]), ndim, dlen)
    at += dlen + 8 * ndim
    if n == 1:
        s, ns = _origins_struct(1).unpack_from(buf, at)
        origins = {s: ns}
    elif n:
        v = _origins_struct(n).unpack_from(buf, at)
        origins = dict(zip(v[::2], v[1::2], strict=True))
    else:
        origins = {}
    return stream, seq, tick, fl, None if end != end else end, origins, dt, shape, width, hlen


def recv_message(sock: zmq.Socket, flags: int = 0) -> Message:
    """Receive one message (raises ``zmq.Again`` with ``flags=zmq.NOBLOCK`` when none is queued).

    A frame that is not a well-formed stream message raises :class:`WireError`. The chunk's arrays
    are read-only views of the frames: every consumer of the stream may share them.
    """
    buf = sock.recv(flags)
    stream, seq, tick, fl, end, origins, dt, shape, width, hlen = _parse_header(buf)
    if fl & _MULTI:
        try:  # the frames of a multipart message arrive together: they are already here
            t_frame = sock.recv(zmq.NOBLOCK, copy=False)
            d_frame = sock.recv(zmq.NOBLOCK, copy=False)
        except zmq.Again:
            raise WireError("a multipart stream message arrived without its t and data frames") from None
        nt, nd = len(t_frame), len(d_frame)
        count = nt // 8
        if nt % 8 or nd != count * width:
            raise WireError(f"frames of {nt} and {nd} bytes do not hold whole samples of {dt}{list(shape)}")
        t = np.frombuffer(t_frame.buffer, np.float64) if count else _EMPTY_T
        data = np.frombuffer(d_frame.buffer, dt) if nd else np.empty(0, dt)
        t.flags.writeable = data.flags.writeable = False  # as a copied frame's: consumers share it
    else:
        size = len(buf) - hlen
        per = 8 + width
        count = size // per
        if size != count * per:
            raise WireError(f"a {size}-byte payload does not hold whole samples of {dt}{list(shape)}")
        t = np.frombuffer(buf, np.float64, count, hlen)
        data = np.frombuffer(buf, dt, count * width // dt.itemsize if dt.itemsize else 0, hlen + 8 * count)
    return Message(stream, seq, tick, fl & ~_MULTI, origins, Chunk(t, data.reshape((count, *shape)), end))
