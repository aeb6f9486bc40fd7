"""The view's server without a browser: the token guards the page and the websocket, a browser
gets the streams' description, frames and the end; a browser that never reads only loses frames
(issue 34, Deliver 2: a slow or paused browser never slows the graph)."""

from __future__ import annotations

import asyncio
import base64
import json
import os
import socket
import threading
import urllib.error
import urllib.request

import numpy as np
import pytest

pytest.importorskip("aiohttp")

import aiohttp

from flowtact.chunk import Chunk, StreamSpec
from flowtact.view.buffers import ViewBuffers
from flowtact.view.server import CLIENT_QUEUE, ViewServer, listen

FORCE = StreamSpec(shape=(3,), units="N", rate_hz=1000.0, labels=("Fx", "Fy", "Fz"))


@pytest.fixture
def server():
    bufs = ViewBuffers({"force.f": FORCE})
    srv = ViewServer(bufs, "touch", listen(0), fps=50.0)
    srv.start()
    yield srv
    srv.stop()


def _get(url: str) -> tuple[int, str]:
    try:
        with urllib.request.urlopen(url, timeout=30) as r:
            return r.status, r.read().decode()
    except urllib.error.HTTPError as e:
        return e.code, ""


def test_the_page_needs_the_token_and_loads_nothing_from_elsewhere(server):
    assert server.url.startswith("http://127.0.0.1:") and len(server.token) >= 32
    assert server.sock.getsockname()[0] == "127.0.0.1"
    base = server.url.split("?")[0]
    assert _get(base)[0] == 403
    assert _get(base + "?token=" + server.token[:-1] + "x")[0] == 403
    status, page = _get(server.url)
    assert status == 200 and "uPlot" in page and "leeoniya/uPlot" in page  # vendored, inlined
    assert "<script src" not in page and '<link rel="stylesheet"' not in page


def test_the_websocket_needs_the_token(server):
    async def go() -> int:
        async with aiohttp.ClientSession() as s:
            try:
                async with s.ws_connect(server.url.replace("http", "ws").replace("/?", "/ws?")[:-2] + "zz"):
                    return 101
            except aiohttp.WSServerHandshakeError as e:
                return e.status

    assert asyncio.run(go()) == 403


def test_a_browser_gets_the_streams_then_frames_then_the_end(server):
    got: list[dict] = []

    async def go() -> None:
        ws_url = server.url.replace("http", "ws").replace("/?", "/ws?")
        async with aiohttp.ClientSession() as s, s.ws_connect(ws_url) as ws:
            got.append(json.loads((await ws.receive()).data))
            k = 0
            while True:
                server.buffers.append("force.f", Chunk(np.array([k / 1000]), np.full((1, 3), float(k))))
                k += 1
                msg = await ws.receive(timeout=60)
                if msg.type != aiohttp.WSMsgType.TEXT:
                    return
                got.append(json.loads(msg.data))
                if len([m for m in got if m["type"] == "frame"]) == 3:
                    threading.Thread(target=server.stop).start()  # as the end of a run does

    asyncio.run(go())
    meta = got[0]
    assert meta["type"] == "meta" and meta["graph"] == "touch"
    assert meta["streams"] == [
        {
            "name": "force.f",
            "kind": "lines",
            "units": "N",
            "rate_hz": 1000.0,
            "shape": [3],
            "dtype": "float64",
            "labels": ["Fx", "Fy", "Fz"],
            "channels": 3,
        }
    ]
    frames = [m for m in got if m["type"] == "frame"]
    assert len(frames) >= 3 and [f["seq"] for f in frames] == sorted({f["seq"] for f in frames})
    assert got[-1] == {"type": "end", "reason": "the run ended", "frames": server.sent}


def _paused_client(url: str) -> socket.socket:
    """A websocket that completes its handshake and then never reads (a paused browser)."""
    host, port = "127.0.0.1", int(url.split(":")[2].split("/")[0])
    sock = socket.create_connection((host, port), timeout=30)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    key = base64.b64encode(os.urandom(16)).decode()
    path = "/ws?" + url.split("?", 1)[1]
    sock.sendall(
        f"GET {path} HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
        f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n".encode()
    )
    head = b""
    while b"\r\n\r\n" not in head:
        head += sock.recv(1)
    assert b" 101 " in head.split(b"\r\n")[0]
    return sock


def test_a_browser_that_never_reads_only_loses_frames():
    spec = StreamSpec(dtype="uint8", shape=(128, 128), units="DN", rate_hz=100.0)
    bufs = ViewBuffers({"cam.y": spec})
    srv = ViewServer(bufs, "cams", listen(0), fps=50.0)
    srv.start()
    sock = _paused_client(srv.url)
    try:
        noise = np.random.default_rng(0).integers(0, 256, (1, 128, 128), dtype=np.uint8)  # ~22 kB a frame
        k = 0
        # the graph side appends on; the browser's queue fills and drops its oldest frames
        while not [c for c in list(srv.clients) if c.dropped >= 3 * CLIENT_QUEUE]:
            bufs.append("cam.y", Chunk(np.array([k / 100]), noise))  # never blocks: a copy under a lock
            k += 1
            threading.Event().wait(0.002)  # the graph's own pace, not a wait for the server
        client = next(iter(srv.clients))
        assert len(client.queue) <= CLIENT_QUEUE
        assert srv.sent > client.dropped  # frames went on being made while it did not read
    finally:
        srv.stop()  # the end of the run still ends (within the close timeout)
        sock.close()
    assert not srv._thread.is_alive()  # noqa: SLF001
