"""Part e of the transport suite: tick x samples per message against latency p50/p99 and CPU per process.

The 3-process source -> stage -> sink of bench/graphs/fast.yaml runs in real time (not --fast) at
``--tick T`` with its source at ``chunk / T`` samples per second, so each tick carries ``chunk``
samples in one message per hop; raw pyzmq (bench/peers/raw.py, same framing and socket settings)
sends the same ``chunk`` samples every ``T`` in the same run. Latency is the source's stamp to the
arrival of the stage's output in the sink process; CPU is % of one core per process.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from flowtact.bench.peers import raw

__all__ = [
    "DEFAULT_TICK_S",
    "RAW_CPU_WINDOW",
    "ROLES",
    "draw_cpu",
    "draw_latency",
    "flowtact_point",
    "raw_cpu_step_pct",
    "raw_point",
    "settings",
    "source_rate_hz",
    "sweep_rows",
]

DEFAULT_TICK_S = 0.005
"""flowtact run's shipped real-time tick (flowtact/cli.py --tick)."""
RAW_CPU_WINDOW = (0.5, 0.25)
"""Raw pyzmq's CPU window (s after the start, s before the end): it starts when its latency count does
(no JIT to wait for), so a short run still spans many clock ticks."""
ROLES = ("source", "stage", "sink")
"""The processes of both pipelines (fast.yaml's process names are the raw pipeline's roles)."""


def settings(quick: bool) -> list[tuple[float, int]]:
    """(tick s, samples per message) of the sweep: the full grid, or with --quick 1 sample at 1 and 5 ms
    and 10 samples at 5 ms (the shipped tick), to keep the quick suite short."""
    if quick:
        return [(0.001, 1), (0.005, 1), (0.005, 10)]
    return [(t, c) for c in (1, 10, 100) for t in (0.001, 0.002, 0.005, 0.01)]


def seconds(quick: bool) -> float:
    """Length of each run of the sweep (flowtact drops its first second's data, raw its first 0.5 s)."""
    return 2.0 if quick else 4.0


def source_rate_hz(tick_s: float, chunk: int) -> float:
    """The source rate that puts ``chunk`` samples in each tick's message."""
    return chunk / tick_s


def flowtact_point(
    run: Callable[..., dict[str, Any]], graph: Any, stream: str, tick_s: float, chunk: int, secs: float
) -> dict[str, Any]:
    """One real-time flowtact run of ``graph`` (through ``run``, transport.flowtact_run) at one setting."""
    sets = ("source.payload=small", f"source.rate_hz={source_rate_hz(tick_s, chunk):g}")
    s = run(graph, secs, tick_s, fast=False, sets=sets, timeout_s=secs + 120)
    st = s["streams"][stream]
    return {
        "tick_s": tick_s,
        "chunk": chunk,
        "latency_us": {k: st["latency_us"][k] for k in ("p50", "p99", "max", "n")},
        "samples_per_message": st["samples"] / max(st["messages"], 1),
        "dropped": sum(v["dropped"] for v in s["streams"].values()),
        "cpu_pct": {name: p["cpu_pct"] for name, p in s["processes"].items()},
    }


def raw_point(tick_s: float, chunk: int, secs: float) -> dict[str, Any]:
    """The raw pyzmq pipeline at one setting; CPU over ``RAW_CPU_WINDOW``."""
    r = raw.run_pipeline(
        "small", secs, source_rate_hz(tick_s, chunk), per_message=chunk, cpu_window=RAW_CPU_WINDOW
    )
    return {
        "tick_s": tick_s,
        "chunk": chunk,
        "latency_us": {k: r["latency_us"][k] for k in ("p50", "p99", "max", "n")},
        "samples_per_message": chunk,
        "loss_pct": r["loss_pct"],
        "payload_ok": r.get("payload_ok"),
        "cpu_pct": r["cpu_pct"],
    }


def sweep_rows(points: dict[str, list[dict[str, Any]]]) -> list[list[Any]]:
    """Table rows: one per (stack, tick, chunk), p50/p99 µs, CPU per process, p99 speed-up
    over raw's (raw's p99 ÷ this one's; > 1: better than raw)."""
    raw_p99 = {(p["tick_s"], p["chunk"]): p["latency_us"]["p99"] for p in points.get("raw pyzmq", [])}
    rows = []
    for stack, pts in points.items():
        for p in pts:
            lat, cpu = p["latency_us"], p["cpu_pct"]
            base = raw_p99.get((p["tick_s"], p["chunk"]))
            ratio = base / lat["p99"] if stack != "raw pyzmq" and base and lat["p99"] else None
            rows.append(
                [
                    stack,
                    f"{p['tick_s'] * 1e3:g}",
                    p["chunk"],
                    _fmt(p["samples_per_message"], 3),
                    _fmt(lat["p50"]),
                    _fmt(lat["p99"]),
                    _fmt(ratio, 3),
                    *(_fmt(cpu.get(r), 3) for r in ROLES),
                ]
            )
    return rows


def raw_cpu_step_pct(secs: float) -> float:
    """Resolution of raw pyzmq's CPU figures: one /proc clock tick over the CPU window, in % of a core."""
    return 100.0 / raw.CLK_TCK / (secs - sum(RAW_CPU_WINDOW))


def _fmt(v: float | None, digits: int = 4) -> str:
    return "–" if v is None else f"{v:.{digits}g}"


def _lines(ax: Any, points: dict[str, list[dict[str, Any]]], value: Callable[[dict[str, Any]], Any]) -> None:
    """One line per (stack, chunk) of ``value`` against tick: colour = chunk, solid flowtact, dashed raw."""
    chunks = sorted({p["chunk"] for pts in points.values() for p in pts})
    for stack, style in (("flowtact", "-o"), ("raw pyzmq", "--s")):
        for i, c in enumerate(chunks):
            pts = sorted((p for p in points.get(stack, []) if p["chunk"] == c), key=lambda p: p["tick_s"])
            xy = [(p["tick_s"] * 1e3, value(p)) for p in pts if value(p) is not None]
            if xy:
                ax.plot(*zip(*xy, strict=True), style, color=f"C{i}", ms=4, label=f"{stack}, {c}/msg")
    ax.axvline(DEFAULT_TICK_S * 1e3, color="k", lw=0.8, ls=":")
    ax.annotate("shipped default tick", (DEFAULT_TICK_S * 1e3, 1), xycoords=("data", "axes fraction"),
                fontsize=7, rotation=90, va="top", ha="right")  # fmt: skip
    from matplotlib.ticker import FixedLocator, NullFormatter, NullLocator, ScalarFormatter

    ticks_ms = sorted({p["tick_s"] * 1e3 for pts in points.values() for p in pts} | {DEFAULT_TICK_S * 1e3})
    ax.set_xscale("log")
    ax.set_xlim(ticks_ms[0] / 1.4, ticks_ms[-1] * 1.4)
    ax.xaxis.set_major_locator(FixedLocator(ticks_ms))
    ax.xaxis.set_major_formatter(ScalarFormatter())
    ax.xaxis.set_minor_locator(NullLocator())
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel("tick (ms)")
    ax.grid(True, which="both", alpha=0.3)


def draw_latency(points: dict[str, list[dict[str, Any]]]) -> Callable[[Any], None]:
    """The plot: p50 and p99 latency (µs, log) against tick, one line per chunk size and stack."""

    def draw(fig: Any) -> None:
        axes = fig.subplots(1, 2, sharey=True)
        for ax, q in zip(axes, ("p50", "p99"), strict=True):
            _lines(ax, points, lambda p, q=q: p["latency_us"][q])
            ax.set_yscale("log")
            ax.set_title(f"{q} latency, source stamp → sink process", fontsize=9)
        axes[0].set_ylabel("latency (µs)")
        axes[1].legend(fontsize=6, ncol=2)

    return draw


def draw_cpu(points: dict[str, list[dict[str, Any]]]) -> Callable[[Any], None]:
    """The plot: CPU (% of a core) of each process against tick, one line per chunk size and stack."""

    def draw(fig: Any) -> None:
        axes = fig.subplots(1, len(ROLES), sharey=True)
        for ax, role in zip(axes, ROLES, strict=True):
            _lines(ax, points, lambda p, role=role: p["cpu_pct"].get(role))
            ax.set_title(f"{role} process", fontsize=9)
        axes[0].set_ylabel("CPU (% of one core)")
        axes[0].set_ylim(bottom=0)
        axes[-1].legend(fontsize=6)

    return draw
