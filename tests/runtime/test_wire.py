"""The stream wire format: what is sent is what is received, and a malformed frame is refused by name."""

from __future__ import annotations

import struct

import numpy as np
import pytest
import zmq

from flowtact.chunk import Chunk
from flowtact.runtime.links.zeromq.wire import COPY_THRESHOLD, END, WireError, recv_message, send_message


@pytest.fixture
def pair():
    ctx = zmq.Context()
    a, b = ctx.socket(zmq.PAIR), ctx.socket(zmq.PAIR)
    a.bind("inproc://wire-test")
    b.connect("inproc://wire-test")
    yield a, b
    a.close(0)
    b.close(0)
    ctx.term()


CHUNKS = {
    "small float": (Chunk(np.arange(3.0) / 1e3, np.arange(12.0).reshape(3, 4)), {0: 123456789}),
    "events": (Chunk(np.array([0.1, 0.2]), np.array([3, 7], np.int64), end=0.25), {2: 5, 9: 1}),
    "empty watermark": (Chunk(np.empty(0), np.empty((0, 2, 3), np.int32), end=5.0), {}),
    "scalar samples": (Chunk(np.array([1.0]), np.array([2.5], np.float32)), None),
    "frame": (
        Chunk(np.array([0.025]), np.arange(240 * 320, dtype=np.uint8).reshape(1, 240, 320)),
        {1: 2**62},
    ),
    "two frames": (Chunk(np.array([0.0, 0.1]), np.ones((2, 300, 300), np.uint8)), {}),
    "zero-width samples": (Chunk(np.arange(4.0), np.empty((4, 0))), {}),
}


@pytest.mark.parametrize("name", list(CHUNKS))
def test_round_trip_keeps_every_field(pair, name):
    chunk, origins = CHUNKS[name]
    a, b = pair
    assert send_message(a, 7, 41, 1234, chunk, origins, flags=END if name == "events" else 0)
    m = recv_message(b)
    assert (m.stream, m.seq, m.tick) == (7, 41, 1234)
    assert m.origins == (origins or {})
    assert m.is_end == (name == "events")
    assert m.chunk.end == chunk.end
    assert m.chunk.t.dtype == np.float64 and np.array_equal(m.chunk.t, chunk.t)
    assert m.chunk.data.dtype == chunk.data.dtype and m.chunk.data.shape == chunk.data.shape
    assert np.array_equal(m.chunk.data, chunk.data)


def test_large_chunks_travel_in_frames_and_small_in_one(pair):
    a, b = pair
    big = CHUNKS["frame"][0]
    assert big.data.nbytes >= COPY_THRESHOLD
    send_message(a, 1, 0, 0, big)
    assert len(b.recv_multipart()) == 3
    send_message(a, 1, 0, 0, CHUNKS["small float"][0])
    assert len(b.recv_multipart()) == 1


def test_non_contiguous_data_is_sent_as_its_values(pair):
    a, b = pair
    data = np.arange(24.0).reshape(4, 6)[:, ::2]
    send_message(a, 0, 0, 0, Chunk(np.arange(4.0), data))
    assert np.array_equal(recv_message(b).chunk.data, data)


def test_nowait_reports_a_full_queue_instead_of_blocking():
    ctx = zmq.Context()
    push = ctx.socket(zmq.PUSH)
    push.setsockopt(zmq.SNDHWM, 1)
    push.bind("inproc://wire-full")
    pull = ctx.socket(zmq.PULL)
    pull.setsockopt(zmq.RCVHWM, 1)
    pull.connect("inproc://wire-full")
    chunk = CHUNKS["small float"][0]
    sent = [send_message(push, 0, i, i, chunk, nowait=True) for i in range(20)]
    assert sent[0] and not all(sent)
    push.close(0)
    pull.close(0)
    ctx.term()


def _valid_frame(a, b) -> bytes:
    send_message(a, 3, 1, 2, CHUNKS["small float"][0], {0: 1})
    return b.recv()


@pytest.mark.parametrize(
    ("mangle", "words"),
    [
        (lambda f: f[:0], "too short"),
        (lambda f: f[:20], "too short"),
        (lambda f: b"\x00" + f[1:], "not a flowtact stream message"),
        (lambda f: f[:-3], "whole samples"),
        (lambda f: f[:36] + b"zz9" + f[39:], "bad dtype"),
        (lambda f: f[:4] + bytes([200]) + f[5:], "shorter than its"),  # the dtype string's length
        (lambda f: f[:3] + bytes([255]) + f[4:], "shorter than its"),  # 255 origins announced
        (lambda f: f[:36] + b"|O8" + f[39:], "object dtype"),
        (lambda f: f[:1] + bytes([f[1] | 2]) + f[2:], "without its t and data frames"),
        (lambda f: f[:39] + struct.pack("<q", -4) + f[47:], "negative sample shape"),
    ],
    ids=[
        "empty",
        "truncated",
        "magic",
        "partial sample",
        "dtype",
        "dtype length",
        "origins",
        "object",
        "multipart",
        "shape",
    ],
)
def test_a_malformed_frame_is_refused_with_what_is_wrong(pair, mangle, words):
    a, b = pair
    frame = _valid_frame(a, b)
    b2 = a  # send the mangled frame back the other way
    b.send(mangle(frame))
    with pytest.raises(WireError, match=words):
        recv_message(b2)


def test_random_bytes_never_decode_as_garbage(pair):
    """A frame either decodes to a consistent message or raises WireError: no other exception."""
    a, b = pair
    frame = _valid_frame(a, b)
    rng = np.random.default_rng(0)
    for _ in range(2000):
        f = bytearray(frame)
        for i in rng.integers(0, len(f), 3):
            f[i] = rng.integers(0, 256)
        b.send(bytes(f))
        try:
            m = recv_message(a)
        except WireError:
            continue
        assert len(m.chunk.t) == len(m.chunk.data)


def test_recv_nowait_raises_again_when_nothing_is_queued(pair):
    _, b = pair
    with pytest.raises(zmq.Again):
        recv_message(b, zmq.NOBLOCK)
