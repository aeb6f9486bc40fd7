"""The supervisor's statistics: what workers report, the live view's snapshot, the run summary.

Part of :class:`flowtact.runtime.supervisor.ProcessExecutor` (which holds the state these methods share).
"""

from __future__ import annotations

import time
from typing import Any

from flowtact.runtime.clock import LAG_WARN_S
from flowtact.runtime.inproc import explain_counters
from flowtact.runtime.protocol import Stats
from flowtact.runtime.stats import LatencyHistogram
from flowtact.runtime.summary import RunSummary
from flowtact.runtime.supervisor_procs import (
    DEADLINE_WARN_EVERY_S,
    WARMUP_S,
    Proc,
)

__all__ = ["SupervisorStats"]


class SupervisorStats:
    """Statistics of a :class:`~flowtact.runtime.supervisor.ProcessExecutor`'s run."""

    def _on_stats(self, proc: Proc, msg: Stats) -> None:
        proc.stats = msg
        proc.last_k = max(proc.last_k, msg.k)
        wall = msg.wall_ns
        if proc.warm is None and time.monotonic() - self.t_run >= WARMUP_S:
            proc.warm = (msg.cpu_s, wall)
            if self.self_warm is None:
                self.self_warm = (time.process_time(), time.monotonic())
        if proc.warm is not None and wall > proc.warm[1]:
            proc.cpu_pct = 100.0 * (msg.cpu_s - proc.warm[0]) / ((wall - proc.warm[1]) / 1e9)
        self.max_lag_s = max(self.max_lag_s, msg.max_lag_s)
        if self.fast:  # deadlines are wall-clock budgets: a virtual clock cannot miss them
            return
        now = time.monotonic()
        for name, p in msg.paths.items():
            seen = proc.violations.get(name, 0)
            if p.violations > seen and now >= self.deadline_quiet.get(name, 0.0):
                budget = next(
                    (d.budget_s for d in self.plan.graph.deployment.deadlines if d.name == name), None
                )
                if budget is None:
                    continue  # no such path in this graph: nothing to warn about
                self.warn(
                    f"deadline {name} ({budget * 1e3:g} ms) missed {p.violations - seen}x "
                    f"(worst {p.worst_ns / 1e6:.2f} ms so far)"
                )
                proc.violations[name] = p.violations
                self.deadline_quiet[name] = now + DEADLINE_WARN_EVERY_S

    def snapshot(self) -> dict[str, Any]:
        """The live view's data: processes, streams, deadline paths."""
        streams, paths = self._stream_stats(), self._path_stats()
        return {
            "graph": self.plan.graph.name,
            "mode": "fast" if self.fast else "realtime",
            "now": self._graph_now(),
            "duration": self.duration_s,
            "wall": time.monotonic() - (self.launched_at or self.t_start),
            "running": max(time.monotonic_ns() - self.go_ns, 0) / 1e9 if self.t0_ns else None,
            "startup": self.go_ns / 1e9 - (self.launched_at or self.t_start) if self.t0_ns else None,
            "processes": self._process_table(),
            "streams": {
                name: {
                    "rate_hz": s["messages"] / max(self._graph_now(), 1e-9),
                    "samples_hz": s["samples"] / max(self._graph_now(), 1e-9),
                    "p50_us": s["latency_us"]["p50"],
                    "p99_us": s["latency_us"]["p99"],
                    "dropped": s["dropped"],
                    "policy": s["policy"],
                }
                for name, s in streams.items()
            },
            "paths": {
                name: {
                    "p50_us": p["p50_us"],
                    "p99_us": p["p99_us"],
                    "budget_us": p["budget_us"],
                    "violations": p["violations"],
                }
                for name, p in paths.items()
                if not self.fast  # wall-clock budgets: nothing to show on a virtual clock
            },
        }

    def _own_cpu_pct(self) -> float | None:
        """The supervisor's CPU (its every thread: control, recording, live view) in % of one core,
        over the workers' window (after the warm-up), so the two add up; None before any warm-up."""
        if self.self_warm is None:
            return None
        cpu0, t0 = self.self_warm
        wall = time.monotonic() - t0
        return 100.0 * (time.process_time() - cpu0) / wall if wall > 0 else None

    def _process_table(self) -> dict[str, dict[str, Any]]:
        return {
            p.name: {
                "pid": p.pid,
                "host": p.host or "local",
                "nodes": p.nodes,
                "cpu_pct": p.cpu_pct,
                "restarts": p.restarts,
                "state": p.state,
            }
            for p in self.procs.values()
        }

    def _stream_stats(self) -> dict[str, dict[str, Any]]:
        out: dict[str, dict[str, Any]] = {}
        sent_dropped: dict[int, int] = {}  # drops at the sending end ('latest' queue full)
        for q in self.procs.values():
            for sid, n in q.stats.sent_dropped.items():
                sent_dropped[sid] = sent_dropped.get(sid, 0) + n
        for p in self.procs.values():
            for sid, s in p.stats.inbound.items():
                crossing = self.placement.crossings.get((sid, p.name))
                if crossing is None:
                    continue  # not a stream this process receives: nothing to report
                name = self.placement.stream_name(sid)
                key = name if len(self.placement.consumers(sid)) == 1 else f"{name}@{p.name}"
                out[key] = {
                    "to": p.name,
                    "policy": crossing.policy,
                    "messages": s.messages,
                    "samples": s.samples,
                    "dropped": s.dropped + sent_dropped.get(sid, 0),
                    "gaps": s.gaps,
                    "latency_us": s.lat.summary(),
                }
        return out

    def _path_stats(self) -> dict[str, dict[str, Any]]:
        out = {}
        for d in self.plan.graph.deployment.deadlines:
            h = LatencyHistogram()
            violations = 0
            for p in self.procs.values():
                ps = p.stats.paths.get(d.name)
                if ps:
                    h.merge(ps.lat)
                    violations += ps.violations
            s = h.summary()
            out[d.name] = {
                "p50_us": s["p50"],
                "p99_us": s["p99"],
                "max_us": s["max"],
                "n": s["n"],
                "budget_us": d.budget_s * 1e6,
                "violations": violations,
            }
        return out

    def _startup_parts(self) -> dict[str, float]:
        """Where the start-up went (see :attr:`RunSummary.startup_parts`)."""
        go = self.go_ns / 1e9
        began = self.launched_at or self.t_start
        parts: dict[str, float] = {}
        if self.launched_at is not None:
            parts["launch"] = self.t_start - self.launched_at
        if "kernels" in self.parts:
            parts["kernels"] = self.parts["kernels"]
        ready = [p for p in self.procs.values() if 0 < p.ready_at <= go and p.spawned_at]
        if ready:
            last = max(ready, key=lambda p: p.ready_at)
            parts["start"] = last.hello_at - last.spawned_at
            parts |= {k: float(last.setup[k]) for k in ("build", "warm_up", "bind") if k in last.setup}
            parts["wiring"] = go - last.ready_at
        parts["other"] = max(go - began - sum(parts.values()), 0.0)
        return parts

    def _summary(self, stopped_by: str) -> RunSummary:
        plan = self.plan
        events: dict[str, int] = {}
        samples: dict[str, int] = {}
        for n, p in plan.record:
            name = f"{n}.{p}"
            if n in plan.demanded:
                (events if plan.specs[(n, p)].events else samples)[name] = self.samples.get(name, 0)
        for proc in self.procs.values():
            for name, count in proc.stats.counts.items():
                n, _, p = name.partition(".")
                spec = plan.specs.get((n, p))
                if spec is not None and spec.events and name not in events:
                    events[name] = count
        now = max((p.stats.now for p in self.procs.values()), default=0.0)
        counters = {n: c for p in self.procs.values() for n, c in p.counters.items()}
        return RunSummary(
            graph=plan.graph.name,
            duration_s=now,
            wall_s=time.monotonic() - (self.launched_at or self.t_start),
            running_s=(self.last_done_ns - self.go_ns) / 1e9 if self.t0_ns and self.last_done_ns else None,
            startup_s=self.go_ns / 1e9 - (self.launched_at or self.t_start) if self.t0_ns else None,
            startup_parts=self._startup_parts() if self.t0_ns else {},
            stopped_by=stopped_by,
            samples=samples,
            events=events,
            event_units={k: plan.specs[tuple(k.split(".", 1))].n_units or 1 for k in events},  # type: ignore[index]
            counters=counters,
            pruned=list(plan.pruned),
            ticks=max((p.last_k for p in self.procs.values()), default=0),
            processes=self._process_table(),
            supervisor_cpu_pct=self._own_cpu_pct(),
            streams=self._stream_stats(),
            paths=self._path_stats(),
            counter_docs=explain_counters(plan, counters),
            realtime=None if self.fast else self.max_lag_s < LAG_WARN_S,
            max_lag_s=self.max_lag_s,
            late_nodes=list(self.late),
            block_summaries={
                n: t for n in plan.order for p in self.procs.values() if (t := p.summaries.get(n))
            },
        )
