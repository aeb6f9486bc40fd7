"""What a run did (:class:`RunSummary`): what every executor returns, in process or across processes."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from flowtact.runtime.stats import format_factor

__all__ = ["RunSummary"]


@dataclass
class RunSummary:
    """What a run did: samples, spikes per population, wall time, real-time factor, counters."""

    graph: str
    duration_s: float
    wall_s: float
    stopped_by: str
    running_s: float | None = None
    """Seconds from graph time 0 (the first tick's clock start) to the end of the last tick
    (multi-process: the last worker's end), without the start-up that ``wall_s`` includes."""
    startup_s: float | None = None
    """Seconds from launch to graph time 0: making and opening blocks, compiling or loading kernels
    (warming up), and (multi-process) spawning and wiring the workers. Shown apart from the
    real-time factor. An in-process --fast executor made without ``warm_up`` loads its kernels in
    its blocks' first steps, inside the running time (``flowtact run`` and sweeps warm up)."""
    startup_parts: dict[str, float] = field(default_factory=dict)
    """Multi-process runs: where ``startup_s`` went (s), in order: ``launch`` (interpreter, imports,
    reading and checking the graph), ``kernels`` (numba set up before workers are forked), then
    for the last process to be ready ``start`` (its interpreter and imports; ~0 when forked),
    ``build``, ``warm_up`` (loading or compiling kernels), ``bind``, and ``wiring`` (until graph
    time 0: outputs connected, devices opened); ``other`` is the rest (handshakes, waiting)."""
    samples: dict[str, int] = field(default_factory=dict)
    events: dict[str, int] = field(default_factory=dict)
    event_units: dict[str, int] = field(default_factory=dict)
    counters: dict[str, dict[str, int]] = field(default_factory=dict)
    pruned: list[str] = field(default_factory=list)
    ticks: int = 0
    processes: dict[str, dict[str, Any]] = field(default_factory=dict)
    """Multi-process runs: per process group, pid, host, nodes, CPU % of one core, restarts."""
    supervisor_cpu_pct: float | None = None
    """Multi-process runs: the supervisor's own CPU (% of one core) over the workers' window."""
    streams: dict[str, dict[str, Any]] = field(default_factory=dict)
    """Multi-process runs: per cross-process stream, messages, samples, drops, latency (µs)."""
    paths: dict[str, dict[str, Any]] = field(default_factory=dict)
    """Declared deadlines: latency p50/p99/max (µs), budget and violations per path."""
    counter_docs: dict[str, dict[str, str]] = field(default_factory=dict)
    """What each reported counter means, per node (its block's ``counter_docs``; see explain_counters)."""
    realtime: bool | None = None
    """Real-time runs: did every tick run within :data:`~flowtact.runtime.clock.LAG_WARN_S` of the wall clock? None: --fast."""
    max_lag_s: float = 0.0
    """Real-time runs: the furthest any tick ran behind the wall clock (s)."""
    late_nodes: list[str] = field(default_factory=list)
    """Real-time runs that fell behind: the nodes that took most of the wall time then."""
    notes: list[str] = field(default_factory=list)
    """Things the run should tell (a played-back file that ended before the run did)."""
    block_summaries: dict[str, str] = field(default_factory=dict)
    """What blocks said of their run (:meth:`flowtact.block.Block.summary`), per node: ``read 26
    letters, 26 right``; printed under the counters."""

    @property
    def realtime_factor(self) -> float:
        """Graph seconds per *running* second (from graph time 0; start-up is ``startup_s``, apart):
        1.0 for a real-time run that kept up. ``wall_s`` stands in when no running span is known."""
        span = self.running_s if self.running_s is not None else self.wall_s
        return self.duration_s / span if span > 0 else math.inf

    @property
    def shown_paths(self) -> dict[str, dict[str, Any]]:
        """Deadline paths worth telling: none on the virtual clock (``--fast``), whose wall-clock
        latencies say nothing about the budgets a deadline declares."""
        return {} if self.realtime is None else self.paths

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "graph": self.graph,
            "duration_s": self.duration_s,
            "wall_s": self.wall_s,
            "running_s": self.running_s,
            "startup_s": self.startup_s,
            "startup_parts": self.startup_parts,
            "realtime_factor": self.realtime_factor,
            "stopped_by": self.stopped_by,
            "realtime": self.realtime,
            "max_lag_s": self.max_lag_s,
            "late_nodes": self.late_nodes,
            "ticks": self.ticks,
            "samples": self.samples,
            "events": self.events,
            "event_rate_hz_per_unit": {k: self.rate(k) for k in self.events},
            "counters": self.counters,
            "counter_docs": self.counter_docs,
            "pruned": self.pruned,
            "processes": self.processes,
            "supervisor": {"cpu_pct": self.supervisor_cpu_pct},
            "streams": self.streams,
            "paths": self.shown_paths,
            "notes": self.notes,
            "block_summaries": self.block_summaries,
        }

    def rate(self, stream: str) -> float:
        """Mean events per second per unit on an event stream."""
        units = max(self.event_units.get(stream, 1), 1)
        return self.events[stream] / units / self.duration_s if self.duration_s > 0 else 0.0

    def _headline(self) -> str:
        """``touch: 3.000 s of graph time in 3.002 s (1.0× real time, duration); start-up 9.8 s``:
        the factor over the running span, the start-up apart (see :attr:`realtime_factor`)."""
        running = self.running_s if self.running_s is not None else self.wall_s
        startup = f"; start-up {self.startup_s:.1f} s" if self.startup_s is not None else ""
        return (
            f"{self.graph}: {self.duration_s:.3f} s of graph time in {running:.3f} s "
            f"({format_factor(self.realtime_factor)} real time, {self.stopped_by}){startup}"
        )

    def format(self) -> str:
        """A short human summary."""
        lines = [self._headline()]
        if self.startup_parts:
            parts = ", ".join(f"{k.replace('_', '-')} {v:.2f}" for k, v in self.startup_parts.items())
            lines.append(f"  start-up parts (s): {parts}")
        if self.realtime is False:
            busiest = f"; busiest nodes: {', '.join(self.late_nodes)}" if self.late_nodes else ""
            lines.append(
                f"  NOT real time: ticks ran up to {self.max_lag_s:.2f} s behind the wall clock{busiest} "
                "(late ticks were merged: same outputs, later)"
            )
        for k, n in self.samples.items():
            lines.append(f"  {k:<28} {n:>10,} samples")
        for k, n in self.events.items():
            lines.append(
                f"  {k:<28} {n:>10,} events  ({self.rate(k):.1f}/s per unit, {self.event_units.get(k, 1)} units)"
            )
        counted = [
            (f"{node}: {k}={v}", self.counter_docs.get(node, {}).get(k))
            for node, cs in self.counters.items()
            for k, v in sorted(cs.items())
        ]
        width = max((len(c) for c, _ in counted), default=0)
        lines += [f"  {c:<{width}}  {doc}" if doc else f"  {c}" for c, doc in counted]
        lines += [f"  {node}: {text}" for node, text in self.block_summaries.items()]
        for name, p in self.processes.items():
            cpu = f"{p['cpu_pct']:.1f}% CPU" if p.get("cpu_pct") is not None else "CPU n/a"
            restarts = f", {p['restarts']} restart(s)" if p.get("restarts") else ""
            lines.append(f"  process {name:<20} {cpu}{restarts}  [{', '.join(p['nodes'])}]")
        if self.supervisor_cpu_pct is not None:
            lines.append(f"  supervisor {'':<17} {self.supervisor_cpu_pct:.1f}% CPU  [control, recording]")
        for name, st in self.streams.items():
            lat = st["latency_us"]
            latency = (
                f"latency p50 {lat['p50']:.0f} µs p99 {lat['p99']:.0f} µs" if lat.get("n") else "no latency"
            )
            dropped = f", {st['dropped']} dropped" if st["dropped"] else ""
            lines.append(
                f"  stream {name:<21} {st['messages']:>8,} msgs ({st['policy']}), {latency}{dropped}"
            )
        for name, pa in self.shown_paths.items():
            if pa.get("n"):
                lines.append(
                    f"  deadline {name}: p50 {pa['p50_us']:.0f} µs, p99 {pa['p99_us']:.0f} µs "
                    f"(budget {pa['budget_us']:.0f} µs, {pa['violations']} missed)"
                )
        if self.pruned:
            lines.append(f"  not started: {', '.join(self.pruned)}")
        lines += [f"  note: {n}" for n in self.notes]
        return "\n".join(lines)
