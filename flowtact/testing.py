"""Run one block (or one graph) offline on numpy arrays, and the conformance suite for blocks.

``run_offline(block, chunk=7, x=signal)`` splits the inputs into chunks, steps the block chunk by
chunk, flushes it, and joins each output port into one :class:`~flowtact.chunk.Chunk`. No
transport, process or clock is involved.
"""

from __future__ import annotations

import itertools
import tempfile
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from flowtact.block import Block, Source
from flowtact.chunk import Chunk, StreamSpec, concat
from flowtact.params import ConfigError

__all__ = [
    "CHECKS",
    "assert_same",
    "infer_specs",
    "run_block_example",
    "run_graph",
    "run_offline",
    "run_source",
]


def infer_specs(
    block: Block,
    arrays: Mapping[str, np.ndarray | Chunk],
    rate_hz: float,
    units: Mapping[str, str] | None = None,
) -> dict[str, StreamSpec]:
    """Stream specs for offline inputs: dtype/shape from the arrays, rate and units as given."""
    units = units or {}
    specs = {}
    for name, a in arrays.items():
        port = block.inputs.get(name)
        if port is None:
            raise ValueError(f"{block.name} has no input '{name}' (inputs: {', '.join(block.inputs)})")
        if port.events:
            c = a if isinstance(a, Chunk) else _events_chunk(a)
            n_units = int(c.data.max()) + 1 if len(c) else 1
            specs[name] = StreamSpec(
                dtype=str(c.data.dtype),
                shape=c.data.shape[1:],
                units=units.get(name, "1"),
                events=True,
                n_units=n_units,
            )
        else:
            arr = np.asarray(a.data if isinstance(a, Chunk) else a)
            specs[name] = StreamSpec(
                dtype=str(arr.dtype),
                shape=arr.shape[1:],
                units=units.get(name, port.units or "1"),
                rate_hz=rate_hz,
            )
    return specs


def _events_chunk(a: Any) -> Chunk:
    t, idx = a
    return Chunk(np.asarray(t, np.float64), np.asarray(idx))


def _chunk_sizes(chunk: int | Sequence[int] | None, n: int) -> Iterator[int]:
    if chunk is None:
        yield n
        return
    sizes = itertools.cycle([chunk] if isinstance(chunk, int) else list(chunk))
    done = 0
    while done < n:
        k = min(next(sizes), n - done)
        yield k
        done += k


def run_offline(
    block: Block,
    *,
    chunk: int | Sequence[int] | None = None,
    rate_hz: float = 1000.0,
    units: Mapping[str, str] | None = None,
    seed: int = 0,
    t: np.ndarray | None = None,
    empty_between: bool = False,
    flush: bool = True,
    specs: Mapping[str, StreamSpec] | None = None,
    **inputs: np.ndarray | Chunk | tuple[np.ndarray, np.ndarray],
) -> dict[str, Chunk]:
    """Run ``block`` on whole input arrays fed ``chunk`` samples at a time; join each output.

    Sample inputs are arrays of shape (n, ...) stamped ``t`` (default ``i / rate_hz``); event
    inputs are ``(times, unit_indices)`` pairs or Chunks, split on the same time boundaries as the
    samples (or on ``chunk / rate_hz`` windows when the block has only event inputs).
    ``chunk`` may be a list of sizes used in turn; ``empty_between`` feeds an empty chunk on every
    port between real ones.
    """
    specs = dict(specs) if specs is not None else infer_specs(block, inputs, rate_hz, units)
    out_specs = block.bind(specs, seed=seed)
    sample_ports = {k: np.asarray(v) for k, v in inputs.items() if not specs[k].events}
    event_ports = {
        k: (v if isinstance(v, Chunk) else _events_chunk(v)) for k, v in inputs.items() if specs[k].events
    }
    lengths = {len(v) for v in sample_ports.values()}
    if len(lengths) > 1:
        raise ValueError(f"sample inputs differ in length: { {k: len(v) for k, v in sample_ports.items()} }")
    if sample_ports:
        n = lengths.pop()
        tt = np.arange(n) / rate_hz if t is None else np.asarray(t, np.float64)
    else:
        last = max((float(c.t[-1]) for c in event_ports.values() if len(c)), default=0.0)
        n = int(np.floor(last * rate_hz)) + 1
        tt = np.arange(n) / rate_hz
    outs: dict[str, list[Chunk]] = {k: [] for k in out_specs}
    start = 0
    for k in _chunk_sizes(chunk, n):
        stop = start + k
        t0 = float(tt[start]) if start < n else float("inf")
        t1 = float(tt[stop]) if stop < n else (float(tt[-1]) + 1.0 / rate_hz if n else 0.0)
        feed = {p: Chunk(tt[start:stop], a[start:stop]) for p, a in sample_ports.items()}
        for p, c in event_ports.items():
            sel = (c.t >= (t0 if start else -np.inf)) & (c.t < t1)
            feed[p] = Chunk(c.t[sel], c.data[sel], t1)
        _collect(outs, block(**feed))
        if empty_between:
            _collect(outs, block(**{p: Chunk.empty(specs[p]) for p in inputs}))
        start = stop
    if flush:
        _collect(outs, block.flush())
    return {p: concat(cs, out_specs[p]) for p, cs in outs.items()}


def run_source(
    block: Source,
    duration_s: float,
    *,
    tick_s: float | Sequence[float] = 0.1,
    seed: int = 0,
    empty_between: bool = False,
    inputs: Mapping[str, np.ndarray | Chunk] | None = None,
    rate_hz: float = 1000.0,
    units: Mapping[str, str] | None = None,
) -> dict[str, Chunk]:
    """Tick a source from 0 to ``duration_s`` (ticks of ``tick_s``, a list used in turn).

    A source with inputs gets ``inputs`` (arrays stamped ``i / rate_hz``, or Chunks) split on
    the tick boundaries: each tick receives the samples with ``prev <= t < now``, watermarked
    ``end=now``.
    """
    feeds = {
        p: (v if isinstance(v, Chunk) else Chunk(np.arange(len(v)) / rate_hz, np.asarray(v)))
        for p, v in (inputs or {}).items()
    }
    specs = infer_specs(block, feeds, rate_hz, units)
    out_specs = block.bind(specs, seed=seed)
    outs: dict[str, list[Chunk]] = {k: [] for k in out_specs}
    ticks = itertools.cycle([tick_s] if isinstance(tick_s, (int, float)) else list(tick_s))
    now = 0.0
    while now < duration_s - 1e-12:
        prev, now = now, min(now + next(ticks), duration_s)
        feed = {}
        for p, c in feeds.items():
            sel = (c.t >= prev) & (c.t < now)
            feed[p] = Chunk(c.t[sel], c.data[sel], now)
        _collect(outs, block(now, **feed))
        if empty_between:
            _collect(outs, block(now, **{p: Chunk.empty(specs[p]) for p in feeds}))
    _collect(outs, block.flush())
    return {p: concat(cs, out_specs[p]) for p, cs in outs.items()}


class _Memory:
    """An in-memory recorder: keeps every chunk written to each stream."""

    def __init__(self) -> None:
        self.chunks: dict[str, list[Chunk]] = {}

    def write(self, stream: str, chunk: Chunk) -> None:
        self.chunks.setdefault(stream, []).append(chunk)

    def maybe_flush(self) -> None:
        """Nothing to make durable in memory."""


def run_graph(
    graph: str | Path,
    *,
    duration_s: float | None = None,
    overrides: Sequence[str] = (),
    feed: Mapping[str, Chunk | tuple[np.ndarray, np.ndarray]] | None = None,
    tick_s: float | None = None,
) -> dict[str, Chunk]:
    """Run a whole graph offline (in process, virtual clock) and return its recorded streams.

    ``feed`` replaces source outputs by arrays: ``{"sensor.r": (t, r), "sensor.ref": (t, ref)}``
    swaps node ``sensor`` for a replay of those samples on its own ports, as ``--replay`` does
    (every consumed output of a fed node must be given; a recorded one that is not is left out of
    the result), so a graph can be driven by your own data without touching its file. Without
    ``duration_s`` the run lasts until the fed samples end (one sample period after the last).
    """
    from flowtact.compile import compile_graph
    from flowtact.graph import load_graph, resolve_graph_path
    from flowtact.params import did_you_mean
    from flowtact.runtime.inproc import InprocExecutor
    from flowtact.source_ends import default_duration

    replays: dict[str, str] = {}
    with tempfile.TemporaryDirectory(prefix="flowtact-feed-") as tmp:
        if feed:
            from flowtact.record import Recorder

            base = compile_graph(load_graph(resolve_graph_path(graph), overrides=overrides))
            by_node: dict[str, dict[str, Chunk]] = {}
            for stream, value in feed.items():
                node, _, port = stream.partition(".")
                by_node.setdefault(node, {})[port] = (
                    value
                    if isinstance(value, Chunk)
                    else Chunk(np.asarray(value[0], np.float64), np.asarray(value[1]))
                )
            for node, ports in by_node.items():
                path = str(Path(tmp) / f"{node}.h5")
                specs = {}
                for port, c in ports.items():
                    if (node, port) not in base.specs:
                        known = [f"{n}.{p}" for n, p in base.specs]
                        raise ValueError(
                            f"feed: no output stream '{node}.{port}'{did_you_mean(f'{node}.{port}', known)}"
                        )
                    declared = base.specs[(node, port)]
                    specs[f"{node}.{port}"] = declared.with_(dtype=str(c.data.dtype), shape=c.data.shape[1:])
                with Recorder(path, specs, {"graph_yaml": "", "fed": "flowtact.testing.run_graph"}) as rec:
                    for port, c in ports.items():
                        rec.write(f"{node}.{port}", c)
                replays[node] = path
        plan = compile_graph(load_graph(resolve_graph_path(graph), overrides=overrides, replays=replays))
        memory = _Memory()
        InprocExecutor(plan, fast=True, tick_s=tick_s, recorder=memory).run(
            default_duration(plan, duration_s)
        )
    return {f"{n}.{p}": concat(memory.chunks.get(f"{n}.{p}", []), plan.specs[(n, p)]) for n, p in plan.record}


def _collect(outs: dict[str, list[Chunk]], produced: Mapping[str, Chunk]) -> None:
    for p, c in produced.items():
        if p in outs:
            outs[p].append(c)


def assert_same(a: Mapping[str, Chunk], b: Mapping[str, Chunk], what: str = "") -> None:
    """Bit-for-bit equality of two runs' outputs (NaN equal to NaN)."""
    assert a.keys() == b.keys(), f"{what}: ports differ {sorted(a)} vs {sorted(b)}"
    for p in a:
        for field in ("t", "data"):
            x, y = getattr(a[p], field), getattr(b[p], field)
            assert x.shape == y.shape, f"{what}: {p}.{field} shape {x.shape} vs {y.shape}"
            assert x.dtype == y.dtype, f"{what}: {p}.{field} dtype {x.dtype} vs {y.dtype}"
            assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), f"{what}: {p}.{field} differs"


# -- conformance suite -------------------------------------------------------------------------


def run_block_example(
    cls: type[Block],
    *,
    chunk: int | Sequence[int] | None = None,
    seed: int = 0,
    empty_between: bool = False,
    check_readonly: bool = True,
) -> dict[str, Chunk]:
    """Run ``cls.example()`` with the given chunking (sources: ticks of ``chunk`` samples)."""
    ex = cls.example()
    block = cls(**ex.params)
    if issubclass(cls, Source):
        tick: float | list[float]
        if chunk is None:
            tick = ex.duration_s
        else:
            sizes = [chunk] if isinstance(chunk, int) else list(chunk)
            rate = float(ex.params.get("rate_hz", ex.rate_hz))
            tick = [s / rate for s in sizes]
        return run_source(
            block,
            ex.duration_s,
            tick_s=tick,
            seed=seed,
            empty_between=empty_between,
            inputs=ex.inputs,
            rate_hz=ex.rate_hz,
            units=ex.units,
        )
    inputs = {}
    for k, v in ex.inputs.items():
        if isinstance(v, np.ndarray) and check_readonly:
            v = v.view()
            v.flags.writeable = False
        inputs[k] = v
    return run_offline(
        block,
        chunk=chunk,
        rate_hz=ex.rate_hz,
        units=ex.units,
        seed=seed,
        empty_between=empty_between,
        **inputs,
    )


def check_config_yaml_roundtrip(cls: type[Block]) -> None:
    """The example config survives YAML dump and load unchanged."""
    block = cls(**cls.example().params)
    text = yaml.safe_dump(block.config.to_dict())
    again = cls.config_cls.build(yaml.safe_load(text))
    assert again == block.config, f"{cls.name}: config changed through YAML:\n{text}"


def check_invalid_config_rejected(cls: type[Block]) -> None:
    """Values that break each field's type or rules raise a ConfigError naming block and field."""
    base = dict(cls.example().params)
    for field, bad in cls.config_cls.invalid_values():
        params = {**base, field: bad}
        try:
            cls(**params)
        except ConfigError as e:
            assert e.field == field or field in str(e), (
                f"{cls.name}: error for {field}={bad!r} names another field: {e}"
            )
            assert cls.name in str(e), f"{cls.name}: error does not name the block: {e}"
            continue
        raise AssertionError(f"{cls.name}: {field}={bad!r} was accepted")
    unknown = {**base, "no_such_parameter": 1}
    try:
        cls(**unknown)
    except ConfigError as e:
        assert "no_such_parameter" in str(e)
    else:
        raise AssertionError(f"{cls.name}: unknown parameter accepted")


def check_deterministic(cls: type[Block]) -> None:
    """Two runs with the same seed give identical outputs."""
    assert_same(run_block_example(cls, seed=3), run_block_example(cls, seed=3), f"{cls.name} determinism")


def check_inputs_not_mutated(cls: type[Block]) -> None:
    """Inputs come out of a run exactly as they went in (they are also passed read-only)."""
    ex = cls.example()
    before = {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in ex.inputs.items()}
    run_block_example(cls, chunk=7)
    for k, v in ex.inputs.items():
        if isinstance(v, np.ndarray):
            assert np.array_equal(v, before[k], equal_nan=True), f"{cls.name}: input '{k}' was mutated"


def check_chunking_invariance(cls: type[Block]) -> None:
    """Feeding 1, 7 or irregular numbers of samples per chunk gives the same output as one chunk."""
    whole = run_block_example(cls)
    for chunk in (1, 7, [3, 250, 1, 64]):
        assert_same(run_block_example(cls, chunk=chunk), whole, f"{cls.name} chunk={chunk}")


def check_empty_chunks(cls: type[Block]) -> None:
    """Empty chunks between real ones leave state and output untouched."""
    assert_same(
        run_block_example(cls, chunk=13, empty_between=True),
        run_block_example(cls, chunk=13),
        f"{cls.name} empty chunks",
    )


def check_documented(cls: type[Block]) -> None:
    """A summary line, a doc for every field and every port."""
    doc = (cls.__doc__ or "").strip()
    assert doc and doc.splitlines()[0].strip(), f"{cls.name}: no docstring summary"
    for f in cls.config_cls.fields_info():
        assert f.doc, f"{cls.name}: field '{f.name}' has no doc"
    for name, port in {**cls.inputs, **cls.outputs}.items():
        assert name.isidentifier(), f"{cls.name}: port '{name}' is not an identifier"
        assert port.doc, f"{cls.name}: port '{name}' has no doc"


CHECKS: tuple[Callable[[type[Block]], None], ...] = (
    check_config_yaml_roundtrip,
    check_invalid_config_rejected,
    check_deterministic,
    check_inputs_not_mutated,
    check_chunking_invariance,
    check_empty_chunks,
    check_documented,
)
