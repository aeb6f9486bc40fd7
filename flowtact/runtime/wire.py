"""The wire format of a stream message: one msgpack header, then the raw numpy buffers.

The header is a msgpack list ``[stream, seq, tick, flags, end, origins, dtype, shape]``;
``origins`` maps a source index to the monotonic time (ns) at which the oldest data behind the
chunk left that source, for latency. A large chunk (data of :data:`COPY_THRESHOLD` bytes or more,
a camera frame) travels as the multipart message ``[header, t, data]``, sent without copying
and received as read-only numpy views of the ZeroMQ frames. A small one travels as a single
frame ``len(header) (4 bytes) + header + t + data``: per-message costs dominate small messages,
and pyzmq advises zero-copy only above ~64 KiB. Never pickle.
"""

from __future__ import annotations

import functools
import math
import struct
from dataclasses import dataclass

import msgpack
import numpy as np
import zmq

from flowtact.chunk import Chunk

__all__ = ["COPY_THRESHOLD", "END", "Message", "recv_message", "send_message"]

END = 1
"""Flag: the producer has finished; this message carries its end-of-stream output."""

COPY_THRESHOLD = 65536
"""Buffers smaller than this are copied into the message (cheaper than zero-copy bookkeeping)."""

_EMPTY_T = np.empty(0, np.float64)
_LEN = struct.Struct("<I")


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
    data = np.ascontiguousarray(chunk.data)
    t = np.ascontiguousarray(chunk.t, dtype=np.float64)
    header = msgpack.packb(
        [
            stream,
            seq,
            tick,
            flags,
            chunk.end,
            list((origins or {}).items()),
            data.dtype.str,
            data.shape[1:],
        ]
    )
    try:
        if data.nbytes >= COPY_THRESHOLD:
            sock.send_multipart([header, t, data], flags=zmq.NOBLOCK if nowait else 0, copy=False)
        else:
            frame = b"".join((_LEN.pack(len(header)), header, t.tobytes(), data.tobytes()))
            sock.send(frame, flags=zmq.NOBLOCK if nowait else 0)
    except zmq.Again:
        return False
    return True


def recv_message(sock: zmq.Socket, flags: int = 0) -> Message:
    """Receive one message (raises ``zmq.Again`` with ``flags=zmq.NOBLOCK`` when none is queued)."""
    buf = sock.recv(flags)
    if not sock.rcvmore:
        (hlen,) = _LEN.unpack_from(buf)
        stream, seq, tick, fl, end, origins, dtype, shape = msgpack.unpackb(buf[4 : 4 + hlen])
        dt = _dtype(dtype)
        width = math.prod(shape)
        count = (len(buf) - 4 - hlen) // (dt.itemsize * width + 8)
        t = np.frombuffer(buf, np.float64, count, 4 + hlen)
        data = np.frombuffer(buf, dt, count * width, 4 + hlen + 8 * count)
    else:
        stream, seq, tick, fl, end, origins, dtype, shape = msgpack.unpackb(buf)
        t_frame = sock.recv(copy=False)
        t = np.frombuffer(t_frame.buffer, np.float64) if len(t_frame) else _EMPTY_T
        data = np.frombuffer(sock.recv(copy=False).buffer, _dtype(dtype))
        count = len(t)
    return Message(stream, seq, tick, fl, dict(origins), Chunk(t, data.reshape((count, *shape)), end))


@functools.cache
def _dtype(text: str) -> np.dtype:
    return np.dtype(text)
