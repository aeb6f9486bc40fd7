"""The view's web server: one page and one websocket on 127.0.0.1, in a thread of its own.

aiohttp serves both (one well-kept library, no separate ASGI server; its ``AppRunner`` starts and
stops on an event loop we own, in our thread, without touching signal handlers). Every request
must carry the run's token (``?token=``, :func:`secrets.token_urlsafe`), else 403. A frame is made
:data:`FPS` times a second from the buffers and put in each browser's queue of
:data:`CLIENT_QUEUE` frames; a full queue drops its oldest frame, so a browser that reads slowly
(or not at all) only loses frames: the graph side never waits for it.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import secrets
import socket
import sys
import threading
from collections import deque
from dataclasses import dataclass, field
from importlib.resources import files

from aiohttp import WSMsgType, web

from flowtact.view.buffers import ViewBuffers
from flowtact.view.frames import FrameMaker

__all__ = ["CLIENT_QUEUE", "FPS", "ViewServer", "listen"]

FPS = 20.0
"""Frames a second sent to each browser (at most)."""
CLIENT_QUEUE = 4
"""Frames a browser may fall behind by before its oldest are dropped."""
CLOSE_S = 2.0
"""How long the end of a run waits for a browser to take its last message."""


def listen(port: int) -> socket.socket:
    """A listening socket on 127.0.0.1 (``port`` 0: a free one); OSError when it cannot be had."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(("127.0.0.1", port))
        sock.listen(16)
        sock.setblocking(False)
    except BaseException:
        sock.close()
        raise
    return sock


@dataclass(eq=False)
class _Client:
    ws: web.WebSocketResponse
    transport: asyncio.BaseTransport | None
    queue: deque[str] = field(default_factory=lambda: deque(maxlen=CLIENT_QUEUE))
    wake: asyncio.Event = field(default_factory=asyncio.Event)
    dropped: int = 0

    def put(self, text: str) -> None:
        if len(self.queue) == self.queue.maxlen:
            self.dropped += 1
        self.queue.append(text)  # a full deque drops its oldest
        self.wake.set()


class ViewServer:
    """Serves the page of one run; :meth:`start` after the workers are forked, :meth:`stop` at the end."""

    def __init__(self, buffers: ViewBuffers, graph: str, sock: socket.socket, fps: float = FPS) -> None:
        self.buffers = buffers
        self.graph = graph
        self.sock = sock
        self.fps = fps
        self.token = secrets.token_urlsafe(24)
        self.frames = FrameMaker({n: b.spec for n, b in buffers.streams.items()})
        self.clients: set[_Client] = set()
        self.sent = 0
        self.errors = 0
        """Frames made (each sent to every browser connected then)."""
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self._ready = threading.Event()
        self._ended = "the run ended"
        self._page = _page()

    @property
    def port(self) -> int:
        return int(self.sock.getsockname()[1])

    @property
    def url(self) -> str:
        """The page's address, token included."""
        return f"http://127.0.0.1:{self.port}/?token={self.token}"

    def start(self) -> None:
        """Serve from a daemon thread (returns once it accepts connections)."""
        self._thread = threading.Thread(target=self._main, name="flowtact-view", daemon=True)
        self._thread.start()
        self._ready.wait(10.0)

    def stop(self, reason: str = "the run ended") -> None:
        """Tell every browser the run ended (``reason``), close and join the thread."""
        self._ended = reason
        loop, stop = self._loop, self._stop
        if loop is not None and stop is not None and self._thread is not None:
            with contextlib.suppress(RuntimeError):  # the loop is closed already
                loop.call_soon_threadsafe(stop.set)
            self._thread.join(CLOSE_S + 3.0)
        self.sock.close()

    # -- the server thread ----------------------------------------------------------------------
    def _main(self) -> None:
        loop = asyncio.new_event_loop()
        self._loop = loop
        try:
            loop.run_until_complete(self._serve())
        finally:
            loop.close()
            self._ready.set()

    async def _serve(self) -> None:
        self._stop = asyncio.Event()
        app = web.Application()
        app.router.add_get("/", self._index)
        app.router.add_get("/ws", self._ws)
        runner = web.AppRunner(app, handle_signals=False, access_log=None, shutdown_timeout=CLOSE_S)
        await runner.setup()
        await web.SockSite(runner, self.sock).start()
        self._ready.set()
        pump = asyncio.ensure_future(self._pump())
        try:
            await self._stop.wait()
        finally:
            pump.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await pump
            self._frame()  # what came after the last frame
            end = json.dumps({"type": "end", "reason": self._ended, "frames": self.sent})
            for c in list(self.clients):
                c.put(end)
            await asyncio.gather(*(self._close(c) for c in list(self.clients)))
            await runner.cleanup()

    async def _close(self, c: _Client) -> None:
        """Give a browser its last messages and close its socket; one that does not read them
        within CLOSE_S (a paused browser) has its connection cut."""
        try:
            async with asyncio.timeout(CLOSE_S):
                while c.queue:
                    await c.ws.send_str(c.queue.popleft())
                await c.ws.close()
        except (TimeoutError, ConnectionError, RuntimeError):
            if c.transport is not None:
                c.transport.abort()

    async def _pump(self) -> None:
        period = 1.0 / self.fps
        loop = asyncio.get_running_loop()
        next_at = loop.time()
        while True:
            next_at += period
            await asyncio.sleep(max(0.0, next_at - loop.time()))
            if next_at < loop.time() - period:  # fell behind (a busy machine): no catching up
                next_at = loop.time()
            self._frame()

    def _frame(self) -> None:
        """Make and queue one frame; a failure is said once and the view goes on (the graph too)."""
        try:
            self._make_frame()
        except Exception as e:  # noqa: BLE001 - the view must never take the run down
            self.errors += 1
            if self.errors == 1:
                print(
                    f"flowtact: view: a frame failed ({type(e).__name__}: {e})", file=sys.stderr, flush=True
                )

    def _make_frame(self) -> None:
        pending = self.buffers.take()
        if not self.clients:
            return  # nobody watches: the data was stale anyway
        frame = self.frames.frame(pending)
        if frame is None:
            return
        self.sent += 1
        text = json.dumps(frame, separators=(",", ":"))
        for c in self.clients:
            c.put(text)

    def _allowed(self, request: web.Request) -> bool:
        return secrets.compare_digest(request.query.get("token", ""), self.token)

    async def _index(self, request: web.Request) -> web.StreamResponse:
        if not self._allowed(request):
            return web.Response(status=403, text="403: this page needs the token flowtact printed\n")
        return web.Response(
            text=self._page,
            content_type="text/html",
            headers={"Cache-Control": "no-store", "Referrer-Policy": "no-referrer"},
        )

    async def _ws(self, request: web.Request) -> web.StreamResponse:
        if not self._allowed(request):
            return web.Response(status=403, text="403\n")
        ws = web.WebSocketResponse(max_msg_size=1 << 16)
        await ws.prepare(request)
        client = _Client(ws, request.transport)
        client.put(json.dumps(self.frames.meta(self.graph)))
        self.clients.add(client)
        sender = asyncio.ensure_future(self._send(client))
        try:
            async for msg in ws:  # the page sends nothing; this notices the close
                if msg.type == WSMsgType.ERROR:
                    break
        finally:
            self.clients.discard(client)
            sender.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await sender
        return ws

    async def _send(self, c: _Client) -> None:
        with contextlib.suppress(ConnectionError, RuntimeError):  # the browser went away
            while True:
                await c.wake.wait()
                c.wake.clear()
                while c.queue:
                    await c.ws.send_str(c.queue.popleft())  # waits while the browser does not read


def _page() -> str:
    """The page with uPlot (vendored, MIT) inlined: one request, nothing fetched from elsewhere."""
    here = files("flowtact.view")
    html = (here / "page.html").read_text(encoding="utf-8")
    js = (here / "vendor" / "uPlot.iife.min.js").read_text(encoding="utf-8")
    css = (here / "vendor" / "uPlot.min.css").read_text(encoding="utf-8")
    return html.replace("/*UPLOT_CSS*/", css).replace("/*UPLOT_JS*/", js.replace("</script", "<\\/script"))
