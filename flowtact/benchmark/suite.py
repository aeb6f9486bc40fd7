"""What a benchmark suite is, and the context it records its figures, tables, plots and verdicts in.

A suite is a :class:`Suite`: a name, what it measures, the baseline it is compared with (measured
in the same run), and ``run(ctx)``. ``run`` measures through its :class:`Context`:

* ``ctx.speed(key, fn, work=..., unit="samples/s", baseline=KEY)`` times ``fn`` (warm-up, repeats,
  raw samples) and records ``work / seconds``; ``ctx.duration(...)`` records seconds scaled to a
  unit (µs per call, ...); ``ctx.figure(...)`` records values measured some other way (latencies
  of a subprocess). A figure naming a ``baseline`` (another figure of the suite) also carries the
  ratio to it, oriented so that > 1 means flowtact does better;
* ``ctx.headline(key)`` names the figure whose ratio heads the report's summary;
* ``ctx.table``, ``ctx.note``, ``ctx.check`` (a bar or target, pass/fail), ``ctx.plot`` (a
  matplotlib drawing function) and ``ctx.tradeoff`` (run time against error, one point per
  setting, the shipped default marked).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any, Literal

from flowtact.benchmark.process_rounds import Prior, share
from flowtact.benchmark.timing import spread, time_call, time_paired
from flowtact.errors import SuiteSkipped

__all__ = [
    "MIN_RATIO_SAMPLES",
    "Check",
    "Context",
    "Figure",
    "Plot",
    "Suite",
    "Table",
    "Tradeoff",
    "TradeoffPoint",
]

Better = Literal["higher", "lower"]
MIN_RATIO_SAMPLES = 3
"""Samples a figure and its baseline each need before a ratio between them is recorded: a single
run's ratio has no spread, so a rerun could never be held to it."""


@dataclass(frozen=True)
class Suite:
    """A registered benchmark suite (published under the entry-point group ``flowtact.bench``)."""

    name: str
    title: str
    measures: str
    """What it measures, in a sentence or a short paragraph (Markdown): the report's introduction."""
    baseline: str
    """What every ratio of the suite is relative to, measured in the same run."""
    run: Callable[[Context], None]
    needs: tuple[str, ...] = ()
    """Importable modules the suite needs; without one it is skipped with a line saying so."""
    minutes_quick: float = 0.5
    minutes_full: float = 2.0
    """Budgets on an idle 2-core machine, shown by ``--list`` and summed in the report's summary
    (measured: keep them honest when a suite's settings change)."""
    processes: tuple[int, int] = (2, 3)
    """Fresh processes the figures are measured in, quick and full (:mod:`process_rounds`): a spread
    from one process misses what moves between processes. (1, 1) for a suite whose every sample
    already comes from a fresh process (pipelines of worker processes, subprocess per case)."""

    def parts(self, quick: bool) -> int:
        """How many processes measure this suite's figures."""
        return max(1, self.processes[0 if quick else 1])


@dataclass
class Figure:
    """One measured quantity: its raw samples, median and spread, and its ratio to a baseline."""

    key: str
    unit: str
    better: Better
    samples: list[float]
    median: float
    q1: float
    q3: float
    min: float
    max: float
    params: dict[str, Any] = field(default_factory=dict)
    baseline: str | None = None
    is_baseline: bool = False
    reference: bool = False
    """A baseline from outside flowtact's own settings (another library, a framework-free call): the
    report lists where flowtact is slower than one of these apart from its settings' trade-offs."""
    ratio: float | None = None
    """Baseline-relative performance, > 1: better than the baseline (faster, lower latency)."""
    ratio_range: tuple[float, float] | None = None
    """The spread a rerun's ratio is held to (``flowtact bench --compare``): the extremes of the paired
    ratios when the figure was measured in pairs with its baseline, else the worst to the best
    pairing of the two figures' samples."""
    ratio_samples: list[float] | None = None
    """Per-pair ratios, when each sample was measured alongside one of the baseline's."""
    seconds: list[float] | None = None
    """Raw wall seconds per repeat, when the figure was timed here."""
    processes: int = 1
    """How many processes measured the samples (:mod:`flowtact.benchmark.process_rounds`)."""


@dataclass
class Table:
    title: str
    header: list[str]
    rows: list[list[Any]]
    note: str = ""


@dataclass
class Check:
    """A bar or target with its verdict."""

    name: str
    passed: bool
    detail: str = ""


@dataclass
class Plot:
    name: str
    caption: str
    draw: Callable[[Any], None] | None = None
    """``draw(fig)`` fills a matplotlib Figure; dropped once the PNG is written."""
    path: str | None = None
    error: str | None = None


@dataclass
class TradeoffPoint:
    time: float
    error: float
    setting: str
    default: bool = False
    series: str = "flowtact"


@dataclass
class Tradeoff:
    """A run-time-against-error plot: one point per setting, the shipped default marked."""

    name: str
    title: str
    time_label: str
    error_label: str
    log_time: bool = True
    log_error: bool = True
    points: list[TradeoffPoint] = field(default_factory=list)

    def add(
        self, time: float, error: float, setting: str, default: bool = False, series: str = "flowtact"
    ) -> None:
        """One setting's cost and error; ``default`` marks the shipped default (a star in the plot)."""
        self.points.append(TradeoffPoint(float(time), float(error), setting, default, series))


class Context:
    """What a suite's ``run`` measures through; the runner turns it into JSON, tables and plots."""

    def __init__(
        self,
        suite: Suite,
        quick: bool,
        peers: bool = False,
        on_step: Callable[[str], None] | None = None,
        *,
        part: int = 0,
        parts: int = 1,
        prior: Prior | None = None,
    ):
        self.suite = suite
        self.quick = quick
        self.peers = peers
        self.repeats = 5 if quick else 9
        """Default repeats of a timed figure (after one warm-up call), over all its processes."""
        self.part, self.parts = part, parts
        """This process is part ``part`` of ``parts`` measuring the suite; each times its share of
        every figure's repeats, and the last (the runner's) merges the others' samples (``prior``)."""
        self.partial = part < parts - 1
        self._prior = prior or {}
        self._own: dict[str, list[float]] = {}
        self._own_seconds: dict[str, list[float] | None] = {}
        self._own_pairs: dict[str, list[tuple[float, float]] | None] = {}
        self.figures: dict[str, Figure] = {}
        self.tables: list[Table] = []
        self.notes: list[str] = []
        self.checks: list[Check] = []
        self.plots: list[Plot] = []
        self.tradeoffs: list[Tradeoff] = []
        self.headline_key: str | None = None
        """The figure whose ratio the report's summary shows for this suite (:meth:`headline`)."""
        self.data: dict[str, Any] = {}
        """Anything else worth keeping in results/<suite>.json (raw rows, configurations)."""
        self._on_step = on_step
        self._timers: dict[str, _Timer] = {}

    def share(self, repeats: int) -> int:
        """This process's share of ``repeats`` (for a suite's own rounds; timed figures share
        theirs already): the runner merges every process's samples."""
        return share(repeats, self.part, self.parts)

    # -- progress and verdicts ------------------------------------------------------------------

    def step(self, text: str) -> None:
        """Say what the suite is doing now (the progress line)."""
        if self._on_step:
            self._on_step(text)

    def skip(self, reason: str) -> None:
        raise SuiteSkipped(reason)

    def note(self, text: str) -> None:
        """A plain statement for the report (a limitation, a reading hint, a part not run)."""
        self.notes.append(text)

    def headline(self, key: str) -> None:
        """Show figure ``key``'s ratio as this suite's headline in the report's summary (without
        one, the summary takes the first figure measured against an outside reference)."""
        self.headline_key = key

    def check(self, name: str, passed: bool, detail: str = "") -> None:
        self.checks.append(Check(name, bool(passed), detail))

    def table(self, title: str, header: list[str], rows: list[list[Any]], note: str = "") -> None:
        self.tables.append(Table(title, list(header), [list(r) for r in rows], note))

    def plot(self, name: str, draw: Callable[[Any], None], caption: str) -> None:
        """A PNG made by ``draw(fig)`` on a matplotlib Figure (label the axes with units)."""
        self.plots.append(Plot(name, caption, draw))

    def tradeoff(
        self,
        name: str,
        title: str,
        time_label: str,
        error_label: str,
        log_time: bool = True,
        log_error: bool = True,
    ) -> Tradeoff:
        """A run-time-against-error plot to add points to (``.add(time, error, setting, default)``)."""
        t = Tradeoff(name, title, time_label, error_label, log_time, log_error)
        self.tradeoffs.append(t)
        return t

    # -- figures --------------------------------------------------------------------------------

    def speed(
        self,
        key: str,
        fn: Callable[..., Any],
        work: float,
        unit: str,
        *,
        baseline: str | None = None,
        is_baseline: bool = False,
        reference: bool = False,
        setup: Callable[[], Any] | None = None,
        repeats: int | None = None,
        warmup: int = 1,
        params: dict[str, Any] | None = None,
    ) -> Figure:
        """Time ``fn`` and record ``work / seconds`` in ``unit`` (higher is better).

        ``is_baseline`` makes it a baseline other figures name; ``reference`` marks a baseline from
        outside flowtact (another library, a framework-free call) rather than one of its settings.
        A figure naming a baseline timed here is timed in pairs with it (baseline, then figure), so
        its ratio compares the two under the same load."""
        return self._timed(key, fn, lambda s: work / s, unit, "higher", baseline, is_baseline, reference, setup,
                           repeats, warmup, params)  # fmt: skip

    def duration(
        self,
        key: str,
        fn: Callable[..., Any],
        *,
        scale: float = 1e6,
        unit: str = "µs per call",
        baseline: str | None = None,
        is_baseline: bool = False,
        reference: bool = False,
        setup: Callable[[], Any] | None = None,
        repeats: int | None = None,
        warmup: int = 1,
        params: dict[str, Any] | None = None,
    ) -> Figure:
        """Time ``fn`` and record ``seconds * scale`` in ``unit`` (lower is better); baselines and
        pairing as in :meth:`speed`."""
        return self._timed(key, fn, lambda s: s * scale, unit, "lower", baseline, is_baseline, reference, setup,
                           repeats, warmup, params)  # fmt: skip

    def _timed(
        self,
        key: str,
        fn: Callable[..., Any],
        value: Callable[[float], float],
        unit: str,
        better: Better,
        baseline: str | None,
        is_baseline: bool,
        reference: bool,
        setup: Callable[[], Any] | None,
        repeats: int | None,
        warmup: int,
        params: dict[str, Any] | None,
    ) -> Figure:
        self.step(key)
        n = share(repeats or self.repeats, self.part, self.parts)
        timer = self._timers.get(baseline) if baseline else None
        if timer is None:
            secs = time_call(fn, n, warmup, setup)
            pairs = None
        else:
            secs, base_secs = time_paired(fn, timer.fn, n, warmup, setup, timer.setup)
            pairs = [(value(s), timer.value(b)) for s, b in zip(secs, base_secs, strict=True)]
        fig = self._add(key, unit, better, [value(s) for s in secs], baseline, is_baseline, params, secs, reference,
                        pairs)  # fmt: skip
        if is_baseline:
            self._timers[key] = _Timer(fn, setup, value)
        return fig

    def figure(
        self,
        key: str,
        samples: float | list[float],
        unit: str,
        better: Better,
        *,
        baseline: str | None = None,
        is_baseline: bool = False,
        reference: bool = False,
        paired: bool = False,
        params: dict[str, Any] | None = None,
    ) -> Figure:
        """Record values measured some other way (one value, or every repeat's). ``paired``: sample
        ``i`` was measured alongside the baseline's sample ``i`` (rounds), so ratios pair them."""
        values = [float(samples)] if isinstance(samples, (int, float)) else [float(s) for s in samples]
        pairs = None
        if paired:
            base = self._own.get(baseline or "")
            if base is None or len(base) != len(values):
                raise ValueError(
                    f"suite {self.suite.name!r}: paired figure {key!r} needs a recorded baseline with as many "
                    f"samples ({len(values)}); got {baseline!r} with {len(base) if base else 'none'}"
                )
            pairs = list(zip(values, base, strict=True))
        return self._add(key, unit, better, values, baseline, is_baseline, params, None, reference, pairs)

    def _add(
        self,
        key: str,
        unit: str,
        better: Better,
        samples: list[float],
        baseline: str | None,
        is_baseline: bool,
        params: dict[str, Any] | None,
        seconds: list[float] | None,
        reference: bool = False,
        pairs: list[tuple[float, float]] | None = None,
    ) -> Figure:
        if key in self.figures:
            raise ValueError(f"suite {self.suite.name!r}: figure {key!r} recorded twice")
        self._own[key], self._own_seconds[key], self._own_pairs[key] = list(samples), seconds, pairs
        processes = 1
        prior = self._prior.get(key)
        if prior and prior["samples"]:
            processes += prior["processes"]
            samples = prior["samples"] + samples
            seconds = prior["seconds"] + seconds if seconds is not None and prior["seconds"] else seconds
            pairs = [tuple(p) for p in prior["pairs"]] + pairs if pairs and prior["pairs"] else pairs
        s = spread(samples)
        fig = Figure(key, unit, better, samples, s.median, s.q1, s.q3, s.min, s.max, dict(params or {}),
                     baseline, is_baseline, reference and is_baseline, seconds=seconds,
                     processes=processes)  # fmt: skip
        if baseline is not None:
            base = self.figures.get(baseline)
            if base is None:
                raise ValueError(
                    f"suite {self.suite.name!r}: figure {key!r} names baseline {baseline!r}, which is not "
                    f"(yet) recorded; have {sorted(self.figures)}"
                )
            short = [f.key for f in (base, fig) if len(f.samples) < MIN_RATIO_SAMPLES]
            if short and not self.partial:  # a child's share; the merged figure is held to the rule
                raise ValueError(
                    f"suite {self.suite.name!r}: figure {key!r} has a baseline, so it and its baseline need "
                    f">= {MIN_RATIO_SAMPLES} samples each for the ratio to have a spread; {short} "
                    f"{'has' if len(short) == 1 else 'have'} fewer"
                )
            if base.better != better:
                raise ValueError(
                    f"suite {self.suite.name!r}: {key!r} and its baseline {baseline!r} disagree on 'better'"
                )
            fig.ratio, fig.ratio_range, fig.ratio_samples = _ratio(fig, base, pairs)
        self.figures[key] = fig
        return fig

    def raw_samples(self) -> dict[str, dict[str, Any]]:
        """What this process measured itself, per figure (a child's output to the runner)."""
        return {
            k: {"samples": v, "seconds": self._own_seconds[k], "pairs": self._own_pairs[k]}
            for k, v in self._own.items()
        }

    def to_dict(self) -> dict[str, Any]:
        return {
            "headline": self.headline_key,
            "figures": {k: asdict(f) for k, f in self.figures.items()},
            "tables": [asdict(t) for t in self.tables],
            "notes": list(self.notes),
            "checks": [asdict(c) for c in self.checks],
            "tradeoffs": [asdict(t) for t in self.tradeoffs],
            "data": self.data,
        }


def _ratio(
    fig: Figure, base: Figure, pairs: list[tuple[float, float]] | None = None
) -> tuple[float | None, tuple[float, float] | None, list[float] | None]:
    """fig relative to base, > 1 when fig is better, with its range and per-pair ratios.

    Measured in pairs (``pairs`` of (figure, baseline) values taken together): the median and
    extremes of the per-pair ratios. Otherwise the ratio of medians, and a range spanning every
    pairing of the samples: interquartile ranges of a few repeats understate how far a rerun
    moves (measured: 73 of 172 quick-run ratios fell inside IQR-based ranges, 111 with extremes).
    """

    def div(a: float, b: float) -> float:
        return a / b if b and math.isfinite(a) and math.isfinite(b) else float("nan")

    def oriented(f: float, b: float) -> float:
        return div(f, b) if fig.better == "higher" else div(b, f)

    if pairs:
        rs = [oriented(f, b) for f, b in pairs]
        s = spread(rs)
        if not math.isfinite(s.median):
            return None, None, None
        return s.median, (s.min, s.max), rs
    if fig.better == "higher":
        r, lo, hi = div(fig.median, base.median), div(fig.min, base.max), div(fig.max, base.min)
    else:
        r, lo, hi = div(base.median, fig.median), div(base.min, fig.max), div(base.max, fig.min)
    if not math.isfinite(r):
        return None, None, None
    return r, (lo, hi), None


@dataclass(frozen=True)
class _Timer:
    """How a baseline was timed, so figures naming it can be timed in pairs with it."""

    fn: Callable[..., Any]
    setup: Callable[[], Any] | None
    value: Callable[[float], float]
