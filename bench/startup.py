"""Suite ``startup``: the first seconds of a first real-time run after a fresh install, against the steady state.

A fresh install is emulated by an empty numba cache: ``NUMBA_CACHE_DIR`` set to a new temporary
folder in the run's processes (numba then neither reads nor writes the caches next to the source,
so every kernel compiles, as from a wheel just installed). Each round runs bench/graphs/chain.yaml
in real time at 1 kHz twice, with the same cache folder: first empty (its latencies counted from
the start: ``FLOWTACT_LATENCY_FROM_S=0``), then warm (counted after the usual first second, as the
transport suite does): the steady state. The figure is the 2-hop stream's p99 latency of each.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
from typing import Any

from flowtact.bench.transport import CHAIN, CHAIN_STREAM, parse_summary
from flowtact.benchmark import Context, Suite
from flowtact.runtime.forked import NO_FORK_ENV

TOUCH = "touch"
"""The shipped graph whose start-up is timed, by name (installed with flowtact)."""
MAX_RATIO = 2.0
"""The first seconds' p99 may be at most this many times the steady state's (set in issue 14)."""
COMPILED = re.compile(r"(\d+) kernels? compiled in ([\d.]+) s")


def chain_run(seconds: float, cache: str, from_start: bool, timeout_s: float = 600) -> dict[str, Any]:
    """Run the chain in real time with numba's cache in ``cache``: its summary, stderr and compile seconds."""
    cmd = [sys.executable, "-c", "import sys; from flowtact.cli import main; sys.exit(main())", "run"]
    cmd += [str(CHAIN), "--duration", repr(seconds), "--tick", "0.001", "--json", "--quiet"]
    env = dict(os.environ, NUMBA_CACHE_DIR=cache, NUMBA_NUM_THREADS="1")
    if from_start:
        env["FLOWTACT_LATENCY_FROM_S"] = "0"
    else:
        env.pop("FLOWTACT_LATENCY_FROM_S", None)
    try:
        proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        raise RuntimeError(f"flowtact run {CHAIN.name} did not finish within {timeout_s:.0f} s") from None
    if proc.returncode != 0:
        raise RuntimeError(f"flowtact run {CHAIN.name} exited with {proc.returncode}:\n{proc.stderr[-2000:]}")
    compiled = [(int(n), float(s)) for n, s in COMPILED.findall(proc.stderr)]
    return {
        "latency_us": parse_summary(proc.stdout)["streams"][CHAIN_STREAM]["latency_us"],
        "stderr": proc.stderr,
        "kernels": sum(n for n, _ in compiled),
        "compile_s": max((s for _, s in compiled), default=0.0),
    }


def graph_startup(
    graph: str,
    *,
    duration_s: float = 0.5,
    fork: bool | None = None,
    cache: str | None = None,
    timeout_s: float = 1800,
) -> dict[str, Any]:
    """One real-time ``flowtact run GRAPH --json``: launch → graph time 0 (``startup_s``) and its
    ``parts`` (s), as the run's summary gives them. The one start-up measurement of this suite and
    of scripts/startup_table.py.

    ``graph``: a shipped graph's name or a path. ``fork``: True forks the workers from the run,
    False starts them as their own interpreters (``FLOWTACT_NO_FORK=1``), None leaves that to the
    caller's environment. ``cache``: numba's cache folder for the run (a new empty one: the first
    run after an install); None: the usual one.
    """
    env = dict(os.environ)
    if fork is not None:
        env.pop(NO_FORK_ENV, None)
        if not fork:
            env[NO_FORK_ENV] = "1"
    if cache is not None:
        env["NUMBA_CACHE_DIR"] = cache
    cmd = [sys.executable, "-m", "flowtact.cli", "run", graph, "--duration", repr(duration_s)]
    cmd += ["--json", "--quiet"]
    try:
        proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        raise RuntimeError(f"flowtact run {graph} did not finish within {timeout_s:.0f} s") from None
    if proc.returncode != 0:
        raise RuntimeError(f"flowtact run {graph} exited with {proc.returncode}:\n{proc.stderr[-2000:]}")
    s = json.loads(proc.stdout)
    return {"startup_s": s["startup_s"], "parts": s.get("startup_parts", {})}


def touch_startup(fork: bool) -> dict[str, Any]:
    """launch → graph time 0 of graphs/touch.yaml (warm numba cache), its workers forked or not."""
    return graph_startup(TOUCH, duration_s=0.2, fork=fork, timeout_s=600)


def start_up_of_touch(ctx: Context) -> None:
    """Cached start-up of touch.yaml with workers forked from the run against started as their own
    interpreters (``FLOWTACT_NO_FORK=1``, as before forking), alternated so load moves both alike."""
    rounds = 3 if ctx.quick else 7
    touch_startup(True)  # the cache is warm for both from here on
    forked, own = [], []
    for i in range(rounds):
        ctx.step(f"touch.yaml start-up, round {i + 1}/{rounds}: forked workers, then their own interpreters")
        forked.append(touch_startup(True))
        own.append(touch_startup(False))
    key = "touch.yaml launch → graph time 0, workers as their own interpreters (cached)"
    ctx.figure(key, [r["startup_s"] for r in own], "s", "lower", is_baseline=True, reference=True)
    ctx.figure(
        "touch.yaml launch → graph time 0, workers forked from the run (cached)",
        [r["startup_s"] for r in forked],
        "s",
        "lower",
        baseline=key,
        paired=True,
    )
    ctx.data["touch_startup"] = {"forked": forked, "own_interpreters": own}


def run(ctx: Context) -> None:
    start_up_of_touch(ctx)
    seconds = 3.0 if ctx.quick else 10.0
    rounds = 1 if ctx.quick else 3
    first: list[dict[str, Any]] = []
    steady: list[dict[str, Any]] = []
    for i in range(rounds):
        with tempfile.TemporaryDirectory(prefix="flowtact-numba-") as cache:
            ctx.step(f"round {i + 1}/{rounds}: first run, empty numba cache (compiles)")
            first.append(chain_run(seconds, cache, from_start=True))
            ctx.step(f"round {i + 1}/{rounds}: second run, warm cache (steady state)")
            steady.append(chain_run(seconds, cache, from_start=False))
    params = {"graph": "bench/graphs/chain.yaml", "tick_s": 0.001, "seconds": seconds, "stream": CHAIN_STREAM}
    p99_steady = [r["latency_us"]["p99"] for r in steady]
    p99_first = [r["latency_us"]["p99"] for r in first]
    steady_key = "steady state (warm cache), p99 latency"
    paired = (
        {"baseline": steady_key, "paired": True} if rounds >= 3 else {}
    )  # a ratio's spread needs 3 rounds
    ctx.figure(steady_key, p99_steady, "µs", "lower", is_baseline=bool(paired), reference=True, params=params)
    ctx.figure(f"first {seconds:g} s after a fresh install, p99 latency", p99_first, "µs", "lower", params=params,
               **paired)  # fmt: skip
    ctx.figure("first run: kernels compiled before ready", [r["kernels"] for r in first], "kernels", "lower")
    ctx.figure(
        "first run: compiling before ready (slowest worker)", [r["compile_s"] for r in first], "s", "lower"
    )
    ratios = sorted(f / s for f, s in zip(p99_first, p99_steady, strict=True))
    ratio = ratios[len(ratios) // 2]
    ctx.check(
        f"first {seconds:g} s of a first real-time run: p99 speed-up vs the steady state >= {1 / MAX_RATIO:.2f}",
        ratio <= MAX_RATIO,  # the report's convention: the steady p99 over the first run's (> 1: better)
        f"median speed-up {1 / ratio:.2f} (p99 {sorted(p99_first)[len(p99_first) // 2]:.0f} µs against "
        f"{sorted(p99_steady)[len(p99_steady) // 2]:.0f} µs)",
    )
    late = [r["stderr"] for r in first + steady if "after the start" in r["stderr"]]
    ctx.check("no kernel compiled after the start", not late, late[0].strip()[-300:] if late else "")
    ctx.check("the first run said it was compiling", all("compiling kernels" in r["stderr"] for r in first))
    ctx.data["rounds"] = [
        {
            "first": {k: v for k, v in f.items() if k != "stderr"},
            "steady": {k: v for k, v in s.items() if k != "stderr"},
        }
        for f, s in zip(first, steady, strict=True)
    ]
    ctx.note(
        "The machine's other load moves both runs of a round alike; the check is on the median of the rounds' "
        "paired ratios. The first run's latencies count from the start (none dropped); the steady state's drop "
        "the first second, as the transport suite's do."
    )


SUITE = Suite(
    name="startup",
    title="Start-up: the first seconds of a first real-time run after a fresh install",
    measures="launch → graph time 0 of graphs/touch.yaml (cached) with workers forked from the run and as "
    "their own interpreters; p99 latency of bench/graphs/chain.yaml's 2-hop stream at 1 kHz in real time, over the first "
    "seconds of a run whose numba cache is empty (every kernel compiles, as after an install), and the "
    "kernels compiled and seconds spent compiling before the workers said ready.",
    baseline="workers as their own interpreters (FLOWTACT_NO_FORK=1), alternated with forked ones; the chain "
    "graph run right after with the cache warm (the steady state), in the same round",
    run=run,
    minutes_quick=1.0,
    minutes_full=3.0,
    processes=(1, 1),  # every sample already comes from fresh processes
)
