"""The compact live status shown on a terminal during ``flowtact run``.

The supervisor builds a *snapshot* dict a few times a second and hands it to :class:`LiveView`,
which draws it with rich: a title line (graph, clock mode, graph time, real-time factor), then one
row per stream (rate, source-to-arrival latency p50/p99, drops), per process (state, CPU) and per
deadline path (p50/p99 against the budget, violations). Rendering is a pure function of the
snapshot (:func:`render`), so it is tested without a terminal. The view draws nothing when its
console is not a terminal (CI logs, pipes, ``--quiet``), and never starts a refresh thread: it
redraws from ``update()`` at most 4 times a second.

Snapshot keys (any of them may be missing or None early in a run)::

    {"graph": str, "mode": "fast" | "realtime", "now": graph s, "duration": s | None, "wall": s,
     "running": s since graph time 0 | None, "startup": s from launch to graph time 0 | None,
     "processes": {name: {"pid", "host", "state", "cpu_pct", "restarts", "nodes": [str]}},
     "streams": {"node.port": {"rate_hz", "samples_hz", "p50_us", "p99_us", "dropped", "policy"}},
     "paths": {"src -> dst": {"p50_us", "p99_us", "budget_us", "violations"}}}
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from types import TracebackType
from typing import Any

from rich import box
from rich.console import Console, Group, RenderableType
from rich.live import Live
from rich.table import Table
from rich.text import Text

from flowtact.runtime.stats import format_factor

__all__ = ["LiveView", "format_latency", "render"]

_STATE_STYLE = {
    "starting": "cyan",
    "running": "green",
    "done": "dim",
    "failed": "bold red",
    "restarting": "bold yellow",
}
_DASH = "–"


def format_latency(us: float | None) -> str:
    """A latency for display: µs below 10 ms, ms above; a dash when unknown."""
    if us is None:
        return _DASH
    if us < 10_000:
        return f"{us:.0f} µs"
    return f"{us / 1e3:.1f} ms"


def _format_rate(hz: float | None) -> str:
    if hz is None:
        return _DASH
    if hz < 100:
        return f"{hz:.1f}"
    if hz < 100_000:
        return f"{hz:.0f}"
    return f"{hz / 1e3:.0f}k"


def _format_count(n: int | None, alarm_style: str = "bold red") -> Text:
    if n is None:
        return Text(_DASH)
    return Text(str(n), style=alarm_style if n > 0 else "")


def _format_seconds(s: float) -> str:
    return f"{s:.1f}" if s < 100 else f"{s:.0f}"


def _title(snap: Mapping[str, Any]) -> Text:
    title = Text()
    title.append("flowtact ", style="bold")
    title.append(str(snap.get("graph") or "?"), style="bold cyan")
    mode = snap.get("mode")
    if mode:
        title.append(f"  {mode}")
    now, duration, wall = snap.get("now"), snap.get("duration"), snap.get("wall")
    if now is not None:
        title.append(f"  t={_format_seconds(now)}")
        if duration:
            title.append(f"/{_format_seconds(duration)} s ({min(100.0, 100.0 * now / duration):.0f}%)")
        else:
            title.append(" s")
        running = snap.get("running")
        if running:  # from graph time 0: the start-up is shown apart, never in the factor
            title.append(f"  {format_factor(now / running)} real time")
        startup = snap.get("startup")
        if startup is not None:
            title.append(f"  start-up {_format_seconds(startup)} s")
    elif wall is not None:
        title.append(f"  starting {_format_seconds(wall)} s")
    return title


def _table(*columns: str) -> Table:
    table = Table(box=box.SIMPLE_HEAD, padding=(0, 1), pad_edge=False, show_edge=False, expand=False)
    for i, name in enumerate(columns):
        table.add_column(
            name, justify="left" if i == 0 or name in ("policy", "host", "state", "nodes") else "right"
        )
    return table


def _streams(streams: Mapping[str, Any]) -> Table:
    table = _table("stream", "msg/s", "samples/s", "p50", "p99", "drops", "policy")
    for name in sorted(streams):
        s = streams[name] or {}
        table.add_row(
            name,
            _format_rate(s.get("rate_hz")),
            _format_rate(s.get("samples_hz")),
            format_latency(s.get("p50_us")),
            format_latency(s.get("p99_us")),
            _format_count(s.get("dropped")),
            s.get("policy") or "",
        )
    return table


def _processes(processes: Mapping[str, Any]) -> Table:
    remote = any((p or {}).get("host") not in (None, "local") for p in processes.values())
    columns = ["process", "pid", *(["host"] if remote else []), "state", "CPU %", "restarts", "nodes"]
    table = _table(*columns)
    table.columns[-1].overflow = "ellipsis"
    table.columns[-1].no_wrap = True
    table.columns[-1].max_width = 48
    for name in sorted(processes):
        p = processes[name] or {}
        state = p.get("state") or "starting"
        cpu = p.get("cpu_pct")
        row: list[Any] = [name, str(p.get("pid") or _DASH)]
        if remote:
            row.append(p.get("host") or "local")
        row += [
            Text(state, style=_STATE_STYLE.get(state, "")),
            _DASH if cpu is None else f"{cpu:.1f}" if cpu < 10 else f"{cpu:.0f}",
            _format_count(p.get("restarts"), alarm_style="yellow"),
            ", ".join(p.get("nodes") or ()),
        ]
        table.add_row(*row)
    return table


def _paths(paths: Mapping[str, Any]) -> Table:
    table = _table("deadline path", "p50", "p99", "budget", "violations")
    for name in sorted(paths):
        p = paths[name] or {}
        p99, budget = p.get("p99_us"), p.get("budget_us")
        over = p99 is not None and budget is not None and p99 > budget
        table.add_row(
            name,
            format_latency(p.get("p50_us")),
            Text(format_latency(p99), style="bold red" if over else ""),
            format_latency(budget),
            _format_count(p.get("violations")),
        )
    return table


def render(snapshot: Mapping[str, Any] | None) -> RenderableType:
    """The live status for ``snapshot`` as a rich renderable (pure; tolerates missing keys)."""
    snap = snapshot or {}
    parts: list[RenderableType] = [_title(snap)]
    if snap.get("streams"):
        parts.append(_streams(snap["streams"]))
    if snap.get("processes"):
        parts.append(_processes(snap["processes"]))
    if snap.get("paths"):
        parts.append(_paths(snap["paths"]))
    return Group(*parts)


def _isatty(file: Any) -> bool:
    """Whether ``file`` really is a terminal (rich alone also says yes under ``FORCE_COLOR``)."""
    try:
        return bool(file.isatty())
    except (AttributeError, ValueError):
        return False


class LiveView:
    """Redraws :func:`render` of the latest snapshot in place on a terminal; does nothing elsewhere.

    ``enabled=False`` (``--quiet``), or a console whose file is not an interactive terminal (a pipe,
    a CI log, even with ``FORCE_COLOR`` set), turns every call into a no-op. ``update()`` redraws at most once per ``min_interval`` seconds (4 Hz); a snapshot that
    arrives sooner is kept and drawn by the next ``update()`` after the interval or by ``close()``,
    which leaves the final status on screen (or erases it with ``transient=True``). The default
    console writes to stderr, so stdout stays free for ``--json``.
    """

    def __init__(
        self,
        enabled: bool = True,
        console: Console | None = None,
        *,
        transient: bool = False,
        min_interval: float = 0.25,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.console = console if console is not None else Console(stderr=True)
        self.enabled = bool(enabled) and self.console.is_interactive and _isatty(self.console.file)
        self._min_interval = min_interval
        self._clock = clock
        self._transient = transient
        self._live: Live | None = None
        self._last_draw = -float("inf")
        self._pending: Mapping[str, Any] | None = None
        self._closed = False

    def update(self, snapshot: Mapping[str, Any]) -> None:
        """Show ``snapshot`` (now, or at the next redraw when the last one was under 0.25 s ago)."""
        if not self.enabled or self._closed:
            return
        self._pending = snapshot
        now = self._clock()
        if now - self._last_draw < self._min_interval:
            return
        self._draw(now)

    def _draw(self, now: float) -> None:
        if self._pending is None:
            return
        renderable = render(self._pending)
        self._pending = None
        self._last_draw = now
        if self._live is None:
            self._live = Live(renderable, console=self.console, auto_refresh=False, transient=self._transient)
            self._live.start(refresh=True)
        else:
            self._live.update(renderable, refresh=True)

    def close(self) -> None:
        """Draw any snapshot not yet shown, then end the live display (idempotent)."""
        if self._closed:
            return
        self._closed = True
        if not self.enabled:
            return
        try:
            self._draw(self._clock())
        finally:
            if self._live is not None:
                self._live.stop()
                self._live = None

    def __enter__(self) -> LiveView:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
