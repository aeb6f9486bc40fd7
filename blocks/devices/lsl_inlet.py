"""``lsl_inlet``: a Lab Streaming Layer stream read into the graph, stamped in graph time."""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

import flowtact.api as ft
from flowtact.blocks.devices.lsl_clock import OffsetFit, anchor
from flowtact.blocks.devices.lsl_streams import (
    LslNotFound,
    StreamMeta,
    find_stream,
    forget,
    open_inlet,
    query_text,
    watch,
)

__all__ = ["LslInlet", "LslInletConfig"]

log = logging.getLogger("flowtact.lsl")

#: Graph time may run ahead of the wall clock by this much before the inlet refuses (a --fast run).
FAST_RUN_SLACK_S = 1.0
#: A stamp at or before the previous one is moved this far past it.
NUDGE_S = 1e-6


@dataclass(frozen=True)
class LslInletConfig(ft.BadDataConfig):
    name: str = ft.param("", doc="the stream's name (LSL 'name'); give at least one of name, type, source_id")
    type: str = ft.param("", doc="the stream's content type (LSL 'type', e.g. Force, EEG)")
    source_id: str = ft.param("", doc="the stream's source id (unique per device: survives a restart)")
    resolve_timeout_s: float = ft.param(
        5.0, gt=0, le=600, doc="how long checking or starting the graph waits for the stream to appear"
    )
    clock_probe_s: float = ft.param(
        1.0, gt=0, doc="read LSL's clock offset to the sender this often (it re-measures every few seconds)"
    )
    lost_after_s: float = ft.param(
        2.0,
        ge=0.5,
        le=600,
        doc="a stream that stopped answering LSL discovery this long is lost: the run stops with an error "
        "once every sample received was emitted",
    )
    buffer_s: int = ft.param(
        360, gt=0, le=3600, doc="seconds of samples liblsl keeps while the graph is slow"
    )
    channels: int | None = ft.param(
        None,
        gt=0,
        le=4096,
        doc="declare the stream instead of asking it when the graph is checked: its channel count (with "
        "format, rate_hz, units, labels); the live stream must match when the run opens it. None: ask it",
    )
    format: Literal["float32", "float64", "int8", "int16", "int32", "int64"] = ft.param(
        "float64", doc="with channels: the declared sample format (LSL float32, double64, int8..int64)"
    )
    rate_hz: float = ft.param(
        0.0, ge=0, le=ft.NOMINAL_RATE_HZ, doc="with channels: declared nominal rate (0: irregular)"
    )
    units: str = ft.param("1", doc="with channels: the declared units of every channel")
    labels: tuple[str, ...] = ft.param((), doc="with channels: the declared channel labels (empty: none)")
    sim: bool = ft.param(
        False,
        doc="emulate the stream in this process instead (a sine per channel, a remote clock off by "
        "sim_offset_s and sim_drift_ppm, exponential delays): offline and --fast runs, tests; no pylsl",
    )
    sim_channels: int = ft.param(2, gt=0, le=4096, doc="sim: channel count")
    sim_rate_hz: float = ft.param(100.0, gt=0, le=ft.NOMINAL_RATE_HZ, doc="sim: nominal rate")
    sim_offset_s: float = ft.param(0.5, ge=-1e6, le=1e6, doc="sim: the remote clock's lead on ours")
    sim_drift_ppm: float = ft.param(50.0, ge=-5000, le=5000, doc="sim: the remote clock's rate error")
    sim_latency_s: float = ft.param(0.002, ge=0, le=1, doc="sim: mean transport delay (exponential)")

    def check(self) -> None:
        if not self.sim and not (self.name or self.type or self.source_id):
            raise self.error("name", "give the stream's name, type or source_id (or sim: true)")
        if self.labels and self.channels is not None and len(self.labels) != self.channels:
            raise self.error("labels", f"must name all {self.channels} channels; got {len(self.labels)}")
        for field in ("name", "type", "source_id"):
            if "'" in getattr(self, field):
                raise self.error(field, f"must not contain a quote; got {getattr(self, field)!r}")


def _spec_of(meta: StreamMeta) -> ft.StreamSpec:
    """The port's spec from the stream's metadata (one unit when every channel shares it; one
    channel: scalar samples, as most blocks take them)."""
    units = set(meta.units) - {""}
    scalar = meta.channel_count == 1
    return ft.StreamSpec(
        dtype=meta.dtype,
        shape=() if scalar else (meta.channel_count,),
        units=units.pop() if len(units) == 1 else "1",
        rate_hz=meta.nominal_srate or None,
        labels=None if scalar else (meta.labels or None),
    )


def _mismatch(live: ft.StreamSpec, want: ft.StreamSpec, declared: bool) -> bool:
    """Whether the live stream differs from the port's spec: everything, or for a declared stream
    what was declared (units and labels only when given)."""
    if not declared:
        return live != want
    same = (live.dtype, live.shape, live.rate_hz) == (want.dtype, want.shape, want.rate_hz)
    if want.units != "1" and live.units != want.units:
        return True
    return not same or (want.labels is not None and live.labels != want.labels)


def _names(spec: ft.StreamSpec) -> str:
    return f" [{', '.join(spec.labels)}]" if spec.labels else ""


class LslInlet(ft.Source):
    """Read an LSL stream (found by name, type and/or source id) as a graph stream in graph time.

    Config
    ------
    See the field docs (``flowtact blocks lsl_inlet``). Docs: ``docs/lsl.md``.

    Notes
    -----
    The port. Unless it is declared (``channels`` with ``format``, ``rate_hz``, ``units``,
    ``labels``: the graph then checks offline, and opening the live stream verifies it), checking or
    starting the graph resolves the stream (waiting up to
    ``resolve_timeout_s``; not found: an error at the node naming the query and the streams seen)
    and its metadata becomes the output's spec: channel count (the sample shape), format (dtype:
    float32, float64, int8..int64; string streams are refused), nominal rate (0, irregular: an
    unrated stream), channel labels and units (``desc/channels/channel/label|unit``; a unit shared by
    every channel becomes the stream's units, else ``1``). A one-channel stream gives scalar samples.

    I/O. ``open`` connects an inlet (liblsl runs its own I/O threads; the block starts none), ``step``
    pulls what arrived without blocking and ``close`` disconnects.

    Time. A sample's LSL stamp (the sender's clock) plus the offset to the sender's clock, fitted
    as a line over LSL's ``time_correction`` readings (offset *and* drift), gives our LSL clock;
    minus the run's anchor (graph time 0 on that clock, shared by this process's LSL blocks) gives
    graph time (:mod:`flowtact.blocks.devices.lsl_clock`). The anchor is the least lateness seen
    over the steps: a late first step does not shift the run; samples still held when it comes
    down move with it, those emitted keep their times. The summary reports offset, drift, how far
    the anchor moved after the first step and a bound on its remaining error. Samples are emitted in increasing time: one stamped at or
    before the previous is moved 1 µs past it (``stamp_nudged``); one stamped at or after ``now``
    is held for a later step. A sample sent before the run started keeps its (negative) graph
    time (``before_start``). A real stream needs a real-time run: graph time more than 1 s ahead of
    the wall clock raises (use ``sim: true`` for fast and offline runs).

    Bad input. NaN/inf samples follow ``on_bad_data``. A stream that disappears (its outlet closed,
    the sender died) raises an error naming the node and the stream once every sample received
    before has been emitted: nothing received is lost. liblsl's own "lost" signal cannot be used
    for that (an inlet without recovery raises before handing out what it had received), so the
    inlet keeps liblsl's recovery on and watches the stream's uid with a continuous resolver
    (non-blocking reads of liblsl's background discovery): gone for ``lost_after_s`` means lost.

    ``sim: true`` emulates a stream in graph time (seeded by the block's rng), through the same
    offset-and-drift fit: deterministic and chunking-invariant.

    Example
    -------
    >>> from flowtact.blocks.devices.lsl_inlet import LslInlet
    >>> from flowtact.testing import run_source
    >>> out = run_source(LslInlet(sim=True, sim_rate_hz=100.0), 1.0, tick_s=0.01)
    >>> out["x"].data.shape[1:], 95 <= len(out["x"]) <= 100
    ((2,), True)
    """

    config_cls = LslInletConfig
    requires = {"pylsl": "lsl"}
    outputs = {
        "x": ft.Port(
            dtype=None,
            doc="the stream's samples (channels,) in graph time; dtype, channel count, rate, labels and "
            "units come from the stream's metadata",
        )
    }
    counter_docs = {
        **ft.nonfinite_counter_docs("samples"),
        "samples": "samples received from the stream",
        "stamp_nudged": "samples stamped at or before the previous one, moved 1 µs after it: jitter of "
        "the sender's clock or of the offset estimate (harmless in small numbers)",
        "before_start": "samples stamped before graph time 0 (sent before the run started): emitted "
        "with their negative times",
        "clock_probes": "readings of the clock offset to the sender (LSL time_correction)",
    }

    def __init__(self, *args: Any, **kw: Any) -> None:
        super().__init__(*args, **kw)
        self._inlet: Any = None
        self._meta: StreamMeta | None = None
        self._watch: Any = None
        self._holding = False

    @classmethod
    def example(cls) -> ft.Example:
        return ft.Example(params={"sim": True, "sim_rate_hz": 100.0}, rate_hz=100.0, duration_s=1.0)

    @classmethod
    def required_modules(cls, config: LslInletConfig) -> dict[str, str]:  # type: ignore[override]
        """pylsl, except in ``sim`` (nothing leaves the process)."""
        return {} if config.sim else super().required_modules(config)

    # -- compile time ---------------------------------------------------------------------------
    def _resolve(self) -> StreamMeta:
        c = self.config
        try:
            meta = find_stream(c.name, c.type, c.source_id, c.resolve_timeout_s)
        except LslNotFound as e:
            raise ft.SpecError(None, str(e)) from None
        if not meta.dtype:
            raise ft.SpecError(
                None,
                f"LSL stream '{meta.name}' carries {meta.channel_format} samples; lsl_inlet reads numbers",
            )
        return meta

    def specs(self, inputs: dict[str, ft.StreamSpec]) -> dict[str, ft.StreamSpec]:  # noqa: ARG002
        c = self.config
        if c.sim:
            labels = tuple(f"ch{i + 1}" for i in range(c.sim_channels))
            spec = ft.StreamSpec("float32", (c.sim_channels,), "1", c.sim_rate_hz, labels=labels)
        elif c.channels is not None:
            scalar = c.channels == 1
            spec = ft.StreamSpec(
                c.format,
                () if scalar else (c.channels,),
                c.units,
                c.rate_hz or None,
                labels=None if scalar else (tuple(c.labels) or None),
            )
        else:
            self._meta = self._resolve()
            spec = _spec_of(self._meta)
        return {"x": spec}

    # -- state ------------------------------------------------------------------------------------
    def reset(self) -> None:
        self._fit = OffsetFit()
        self._ready_t: list[np.ndarray] = []
        self._ready_x: list[np.ndarray] = []
        self._last_t = -math.inf  # the last emitted stamp
        self._queued_t = -math.inf  # the last queued stamp
        self._next_probe = -math.inf
        self._anchor: float | None = 0.0 if self.config.sim else None
        self._lost: str | None = None
        self._last_good: np.ndarray | None = None
        self._opened_at = 0.0  # the LSL clock when open() returned: graph time 0 comes later
        if self.config.sim:
            self._sim_i = 0
            self._sim_arrival = -math.inf
            self._sim_lat: float | None = None  # the next sample's delay, drawn once
            self._sim_probe_i = 0

    # -- lifecycle ------------------------------------------------------------------------------
    def open(self) -> None:
        if self.config.sim:
            return
        import pylsl

        c = self.config
        pred = query_text(c.name, c.type, c.source_id)
        try:
            self._inlet, meta = open_inlet(pred, c.resolve_timeout_s, c.buffer_s)
            self._fit.add(pylsl.local_clock(), self._inlet.time_correction(c.resolve_timeout_s))
        except (LslNotFound, RuntimeError) as e:
            forget(c.name, c.type, c.source_id, c.resolve_timeout_s)
            raise RuntimeError(
                f"{self.node} (lsl_inlet): LSL stream with {pred} did not connect within "
                f"{c.resolve_timeout_s:g} s: {e}"
            ) from None
        live, want = _spec_of(meta), self.output_specs.get("x")
        if want is not None and _mismatch(live, want, declared=c.channels is not None):
            self._inlet.close_stream()
            self._inlet = None
            what = "declared" if c.channels is not None else "when the graph was checked"
            raise RuntimeError(
                f"{self.node} (lsl_inlet): the LSL stream with {pred} is {live.describe()}"
                f"{_names(live)}, not as {what}: {want.describe()}{_names(want)}"
            )
        self._meta = meta
        self._watch = watch(meta.uid, c.lost_after_s)
        self._seen = False  # the watch answered at least once
        self._watch_deadline = pylsl.local_clock() + max(c.lost_after_s, c.resolve_timeout_s)
        self.count("clock_probes")
        anchor.acquire()
        self._holding = True
        self._opened_at = pylsl.local_clock()

    def close(self) -> None:
        if self._inlet is not None:
            self._inlet.close_stream()
            self._inlet = None
        self._watch = None
        if self._holding:
            anchor.release()
            self._holding = False

    # -- the step -------------------------------------------------------------------------------
    def step(self, now: float) -> dict[str, ft.Chunk]:
        if self.config.sim:
            self._pull_sim(now)
        else:
            if self._inlet is None:
                raise RuntimeError(
                    f"{self.node} (lsl_inlet): the LSL stream is not open — open() runs before step() in "
                    "a graph; offline, use sim: true"
                )
            self._settle(anchor.at(now))
            self._check_realtime(now)
            if self._lost is not None and not self._ready_t:
                raise RuntimeError(self._lost)  # after a step that emitted everything received
            if self._lost is None:
                self._pull()
        return self._emit(now)

    def _settle(self, a: float) -> None:
        """Take the anchor after this step; samples still held move with it (those emitted keep
        their times: the move only raises the later ones, so times stay increasing)."""
        if self._anchor is not None and a < self._anchor and self._ready_t:
            d = self._anchor - a
            self._ready_t = [t + d for t in self._ready_t]
            self._queued_t += d
        self._anchor = a

    def _check_realtime(self, now: float) -> None:
        """Refuse a run whose graph time outruns the wall clock (``--fast``). Graph time 0 comes
        after ``open``, and a real-time step never runs before its graph time, so graph time can
        never exceed the wall time since ``open``; measured from the first step instead, a worker
        that started late and catches up (merged ticks) would look ahead by its lateness."""
        import pylsl

        ahead = now - (pylsl.local_clock() - self._opened_at)
        if ahead > FAST_RUN_SLACK_S:
            raise RuntimeError(
                f"{self.node} (lsl_inlet): graph time runs {ahead:.1f} s ahead of the wall clock — a live "
                "LSL stream needs a real-time run (not --fast); use sim: true for fast or offline runs"
            )

    def _pull(self) -> None:
        import pylsl

        c = self.config
        local = pylsl.local_clock()
        probe = local >= self._next_probe
        if probe:
            self._next_probe = local + c.clock_probe_s
            try:
                self._fit.add(local, self._inlet.time_correction(0.0))
                self.count("clock_probes")
            except RuntimeError:  # no fresh estimate (the sender is slow to answer, or gone)
                pass
            visible = bool(self._watch.results())
            # gone: seen, then not; or never seen by the watch (it went before the watch's first look)
            gone = not visible and (self._seen or local > self._watch_deadline)
            self._seen = self._seen or visible
        while True:  # what liblsl received, even from a stream that has gone since
            x, ts = self._inlet.pull_chunk(timeout=0.0, max_samples=4096)
            if not ts:
                break
            self._take(np.asarray(ts, np.float64), np.asarray(x))
        if probe and gone:
            m = self._meta
            what = f"'{m.name}' (source id {m.source_id or '-'}, {m.hostname})" if m else "stream"
            self._lost = (
                f"{self.node} (lsl_inlet): LSL stream {what} was lost after "
                f"{self.counters.get('samples', 0)} samples (gone from discovery for {c.lost_after_s:g} s, "
                "lost_after_s); every sample received was emitted"
            )
            forget(c.name, c.type, c.source_id, c.resolve_timeout_s)

    def _take(self, ts: np.ndarray, x: np.ndarray) -> None:
        """Map a pulled chunk's LSL stamps to graph time (increasing: nudged) and queue it."""
        assert self._anchor is not None
        t = self._fit.to_local(ts) - self._anchor
        self.count("samples", len(t))
        self.count("before_start", int((t < 0).sum()))
        for i in range(len(t)):
            if t[i] <= self._queued_t:
                t[i] = self._queued_t + NUDGE_S
                self.count("stamp_nudged")
            self._queued_t = float(t[i])
        dtype = self.output_specs["x"].dtype if self.output_specs else "float32"
        self._ready_t.append(t)
        self._ready_x.append(x.astype(dtype, copy=False).reshape(len(t), -1))  # shaped when emitted

    def _pull_sim(self, now: float) -> None:
        """The emulated sender: samples at i / rate (graph time = true time) stamped on a remote clock."""
        c = self.config
        d = c.sim_drift_ppm * 1e-6
        while True:
            t_true = self._sim_i / c.sim_rate_hz
            if self._sim_lat is None:  # drawn once per sample, whatever the ticks: chunking-invariant
                lat = self.rng.exponential(c.sim_latency_s) if c.sim_latency_s else 0.0
                self._sim_lat = min(lat, 5.0 * c.sim_latency_s)
            arrival = max(t_true + self._sim_lat, self._sim_arrival)
            if arrival >= now:
                break
            self._sim_arrival, self._sim_lat = arrival, None
            while self._sim_probe_i * c.clock_probe_s <= arrival:  # readings on a fixed schedule
                tp = self._sim_probe_i * c.clock_probe_s
                noise = self.rng.normal(0.0, 20e-6)
                self._fit.add(tp, -(c.sim_offset_s + d * tp) + noise)
                self._sim_probe_i += 1
                self.count("clock_probes")
            stamp = c.sim_offset_s + (1 + d) * t_true
            phase = 2 * np.pi * t_true * np.arange(1, c.sim_channels + 1)
            self._take(np.array([stamp]), np.sin(phase, dtype=np.float64).astype(np.float32)[None])
            self._sim_i += 1

    def _emit(self, now: float) -> dict[str, ft.Chunk]:
        spec = self.output_specs["x"]
        if not self._ready_t:
            return {"x": ft.Chunk.empty(spec)}
        t = np.concatenate(self._ready_t)
        x = np.concatenate(self._ready_x)
        k = int(np.searchsorted(t, now, side="left"))  # what is due; a lost stream's too, then step raises
        self._ready_t = [t[k:]] if k < len(t) else []
        self._ready_x = [x[k:]] if k < len(t) else []
        if k:
            self._last_t = float(t[k - 1])
        chunk = ft.Chunk(t[:k], x[:k].reshape(k, *spec.shape), float(t[k - 1]) if k else None)
        chunk, self._last_good = ft.screen_nonfinite(
            self, chunk, self.config.on_bad_data, "x", self._last_good
        )
        return {"x": chunk}

    def flush(self) -> dict[str, ft.Chunk]:
        """At the end of the run: the samples received but stamped at or after the last ``now``."""
        if not self._ready_t:
            return {}
        t, x = np.concatenate(self._ready_t), np.concatenate(self._ready_x)
        self._ready_t, self._ready_x = [], []
        self._last_t = float(t[-1])
        chunk = ft.Chunk(t, x.reshape(len(t), *self.output_specs["x"].shape), self._last_t)
        chunk, self._last_good = ft.screen_nonfinite(
            self, chunk, self.config.on_bad_data, "x", self._last_good
        )
        return {"x": chunk}

    def summary(self) -> str | None:
        if self.config.sim or self._meta is None:
            return None
        bound = anchor.late_at_most
        late = f"at most {bound * 1e3:.2f} ms late" if math.isfinite(bound) else "late by an unknown amount"
        return (
            f"LSL '{self._meta.name}': {self.counters.get('samples', 0)} samples; clock offset "
            f"{self._fit.offset(self._last_local()) * 1e6:+.0f} µs, drift {self._fit.drift_ppm:+.1f} ppm "
            f"({self._fit.readings} probes); anchor moved {anchor.moved * 1e3:.2f} ms after "
            f"the first step, {late}"
        )

    def _last_local(self) -> float:
        return (self._anchor or 0.0) + (self._last_t if math.isfinite(self._last_t) else 0.0)
