"""What ``--view`` costs the graph: CPU and link latency p99 without the view, with a headless
Chromium watching it, and with a paused browser (a websocket that connects and never reads).

Each condition runs the graph across processes in real time (``flowtact run G --duration D
--json``), interleaved ``--repeats`` times; the graph's CPU is the sum of its workers' and the
supervisor's (the view's server thread runs in the supervisor), the latency the worst link p99.
Prints a table with the medians and the load average (docs/view.md quotes one). Figures, not
assertions: a busy 2-core machine moves them.

    python scripts/view_overhead.py --graph touch --duration 10 --repeats 3
"""

from __future__ import annotations

import argparse
import base64
import json
import os
import re
import socket
import statistics
import subprocess
import sys
import threading
from typing import Any

CHROMIUM, CHROMEDRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"


def browser() -> Any:
    from selenium import webdriver
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    o = Options()
    for a in (
        "--headless=new",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-dev-shm-usage",
        "--window-size=1400,1000",
    ):
        o.add_argument(a)
    o.binary_location = CHROMIUM
    return webdriver.Chrome(service=Service(CHROMEDRIVER), options=o)


def paused_client(url: str) -> socket.socket:
    """A websocket that completes its handshake and never reads again."""
    port = int(url.split(":")[2].split("/")[0])
    sock = socket.create_connection(("127.0.0.1", port), timeout=30)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    key = base64.b64encode(os.urandom(16)).decode()
    sock.sendall(
        f"GET /ws?{url.split('?', 1)[1]} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
        f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n".encode()
    )
    head = b""
    while b"\r\n\r\n" not in head:
        head += sock.recv(1)
    return sock


def run(graph: str, duration: float, mode: str, driver: Any, streams: list[str]) -> dict[str, float]:
    args = [sys.executable, "-m", "flowtact.cli", "run", graph, "--duration", str(duration), "--json"]
    if mode != "off":
        args += ["--view", *streams]
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    url: list[str] = []
    got = threading.Event()

    def read_err() -> None:
        for line in proc.stderr:  # type: ignore[union-attr]
            m = re.search(r"view at (\S+)", line)
            if m:
                url.append(m.group(1))
                got.set()

    reader = threading.Thread(target=read_err, daemon=True)
    reader.start()
    held = None
    if mode != "off":
        got.wait(300)
        if mode == "browser":
            driver.get(url[0])
        else:
            held = paused_client(url[0])
    out, _ = proc.communicate(timeout=600)
    reader.join(30)
    if held is not None:
        held.close()
    if proc.returncode:
        raise SystemExit(f"{mode}: exit {proc.returncode}")
    s = json.loads(out)
    cpu = sum(p["cpu_pct"] for p in s["processes"].values()) + s["supervisor"]["cpu_pct"]
    p99 = max((v["latency_us"]["p99"] for v in s["streams"].values() if v.get("latency_us")), default=0.0)
    return {"cpu_pct": cpu, "p99_ms": p99 / 1000.0, "supervisor_pct": s["supervisor"]["cpu_pct"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--graph", default="touch")
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument(
        "--streams", nargs="*", default=[], help="the streams viewed (default: the recorded ones)"
    )
    a = ap.parse_args()
    driver = browser()
    modes = ("off", "browser", "paused")
    got: dict[str, list[dict[str, float]]] = {m: [] for m in modes}
    load0 = os.getloadavg()
    try:
        for _ in range(a.repeats):
            for m in modes:
                got[m].append(run(a.graph, a.duration, m, driver, a.streams))
    finally:
        driver.quit()
    load1 = os.getloadavg()
    base = statistics.median(r["cpu_pct"] for r in got["off"])
    viewed = " ".join(a.streams) or "the recorded streams"
    print(f"{a.graph} viewing {viewed}, {a.duration:g} s real time across processes, median of "
          f"{a.repeats}; load average {load0[0]:.2f} -> {load1[0]:.2f} (2 cores)")  # fmt: skip
    print("| view | graph CPU % (min–max) | vs off | supervisor CPU % | worst link p99 ms (min–max) |")
    print("|---|---|---|---|---|")
    for m in modes:
        cpus = [r["cpu_pct"] for r in got[m]]
        p99s = [r["p99_ms"] for r in got[m]]
        cpu, p99 = statistics.median(cpus), statistics.median(p99s)
        sup = statistics.median(r["supervisor_pct"] for r in got[m])
        print(
            f"| {m} | {cpu:.1f} ({min(cpus):.1f}–{max(cpus):.1f}) | {cpu / base - 1:+.0%} | {sup:.1f} "
            f"| {p99:.2f} ({min(p99s):.2f}–{max(p99s):.2f}) |"
        )


if __name__ == "__main__":
    main()
