"""Run one block (or one graph) offline on numpy arrays, and the conformance suite for blocks.

``run_offline(block, chunk=7, x=signal)`` splits the inputs into chunks, steps the block chunk by
chunk, flushes it, and joins each output port into one :class:`~flowtact.chunk.Chunk`. No
transport, process or clock is involved.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from flowtact.block import Block, Example, Source
from flowtact.chunk import Chunk, StreamSpec, concat
from flowtact.errors import ConfigError, ConformanceError
from flowtact.verify.conformance import differing_rows, example_of, first_difference, value_text

__all__ = [
    "CHECKS",
    "ConformanceError",
    "MemoryRecorder",
    "assert_same",
    "example_of",
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


class MemoryRecorder:
    """An in-memory recorder: keeps every chunk written to each stream (``chunks[stream]``), for
    offline runs that want the streams back rather than a file."""

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
    allow_modules: Sequence[str] = (),
) -> dict[str, Chunk]:
    """Run a whole graph offline (in process, virtual clock) and return its recorded streams.

    ``feed`` replaces source outputs by arrays: ``{"sensor.r": (t, r), "sensor.ref": (t, ref)}``
    swaps node ``sensor`` for a replay of those samples on its own ports, as ``--replay`` does
    (every consumed output of a fed node must be given; a recorded one that is not is left out of
    the result), so a graph can be driven by your own data without touching its file. Without
    ``duration_s`` the run lasts until the fed samples end (one sample period after the last).
    ``allow_modules``: the modules whose ``module:Class`` blocks may be imported (``--allow-module``).
    """
    from flowtact.graphfile.graph import load_graph, resolve_graph_path
    from flowtact.params import did_you_mean
    from flowtact.running.compile import compile_graph
    from flowtact.running.source_ends import default_duration
    from flowtact.runtime.inproc import InprocExecutor
    from flowtact.runtime.rundir import make_run_folder

    replays: dict[str, str] = {}
    with make_run_folder("feed") as folder:  # swept by a later start if this process is killed
        tmp = folder.path
        if feed:
            from flowtact.recording.hdf5 import Recorder

            base = compile_graph(
                load_graph(resolve_graph_path(graph), overrides=overrides, allow_modules=allow_modules)
            )
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
        graph_def = load_graph(
            resolve_graph_path(graph), overrides=overrides, replays=replays, allow_modules=allow_modules
        )
        plan = compile_graph(graph_def)
        memory = MemoryRecorder()
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
# Each check fails with a ConformanceError: "<block>: <check>: expected <what>; <what happened>".


def run_block_example(
    cls: type[Block],
    *,
    chunk: int | Sequence[int] | None = None,
    seed: int = 0,
    empty_between: bool = False,
    check_readonly: bool = True,
    example: Example | None = None,
) -> dict[str, Chunk]:
    """Run ``cls``'s example (or ``example``) with the given chunking (sources: ticks of ``chunk`` samples)."""
    ex = example if example is not None else example_of(cls)
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


def _fed(chunk: int | Sequence[int] | None, empty_between: bool = False) -> str:
    """How a run was fed, in words: ``whole``, ``in chunks of 7``, ``in chunks of 3, 250, 1, 64 in turn``."""
    if chunk is None:
        how = "whole"
    elif isinstance(chunk, int):
        how = f"in chunks of {chunk}"
    else:
        how = f"in chunks of {', '.join(map(str, chunk))} in turn"
    return f"{how} with empty chunks between" if empty_between else how


def _run(cls: type[Block], check: str, expected: str, **how: Any) -> dict[str, Chunk]:
    """Run the example; a block that raises fails ``check`` saying how it was fed and what it raised."""
    try:
        return run_block_example(cls, **how)
    except ConformanceError:
        raise
    except Exception as e:  # whatever the block raised is the finding, reported with its cause
        fed = _fed(how.get("chunk"), how.get("empty_between", False))
        happened = f"running the example fed {fed} raised {type(e).__name__}: {e}"
        if isinstance(e, ValueError) and "read-only" in str(e):
            happened = (
                f"step() tried to change an input in place when fed {fed} ({type(e).__name__}: {e}); inputs "
                "are read-only views: compute into a new array (y = x.data * 2) or copy first (x.data.copy())"
            )
        raise ConformanceError(cls.name, check, expected, happened) from e


def check_config_yaml_roundtrip(cls: type[Block]) -> None:
    """The example config survives YAML dump and load unchanged."""
    check, expected = "config YAML round trip", "the example config to come back unchanged from YAML"
    block = cls(**example_of(cls).params)
    values = block.config.to_dict()
    try:
        text = yaml.safe_dump(values)
        again = cls.config_cls.build(yaml.safe_load(text))
    except Exception as e:
        raise ConformanceError(cls.name, check, expected, f"{type(e).__name__}: {e}") from e
    if again != block.config:
        back = again.to_dict()
        field = next((k for k in values if back.get(k) != values[k]), None)
        what = (
            f"field '{field}' was {values[field]!r}, came back {back.get(field)!r}"
            if field
            else "the configs differ"
        )
        raise ConformanceError(cls.name, check, expected, f"{what} (YAML:\n{text})")


def check_invalid_config_rejected(cls: type[Block]) -> None:
    """Values that break each field's type or rules raise a ConfigError naming block and field."""
    check = "invalid config rejected"
    base = dict(example_of(cls).params)
    for field, bad in [*cls.config_cls.invalid_values(), ("no_such_parameter", 1)]:
        expected = f"{cls.__name__}({field}={bad!r}) to raise a ConfigError naming {cls.name} and '{field}'"
        try:
            cls(**{**base, field: bad})
        except ConfigError as e:
            if not (e.field == field or field in str(e)):
                raise ConformanceError(
                    cls.name, check, expected, f"its message names another field: {e}"
                ) from e
            if cls.name not in str(e):
                raise ConformanceError(
                    cls.name, check, expected, f"its message does not name the block: {e}"
                ) from e
            continue
        except Exception as e:
            raise ConformanceError(
                cls.name,
                check,
                expected,
                f"it raised {type(e).__name__}: {e} (check values in the config's fields and check(), "
                "raising self.error(field, rule))",
            ) from e
        raise ConformanceError(cls.name, check, expected, "it was accepted")


def check_deterministic(cls: type[Block]) -> None:
    """Two runs with the same seed give identical outputs."""
    check, expected = "deterministic", "two runs with seed 3 to give identical outputs"
    first = _run(cls, check, expected, seed=3)
    why = first_difference(first, _run(cls, check, expected, seed=3), "on the second run", "first run")
    if why:
        raise ConformanceError(
            cls.name, check, expected, f"{why} (draw random numbers from self.rng, seeded by reset)"
        )


def check_inputs_not_mutated(cls: type[Block]) -> None:
    """Inputs come out of a run exactly as they went in (they are also passed read-only)."""
    check, expected = "inputs not mutated", "the example's inputs to come out of a run unchanged"
    ex = example_of(cls)
    before = {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in ex.inputs.items()}
    _run(cls, check, expected, chunk=7, example=ex)
    for k, v in ex.inputs.items():
        if isinstance(v, np.ndarray):
            rows = differing_rows(before[k], v)
            if rows.size:
                i = int(rows[0])
                raise ConformanceError(
                    cls.name,
                    check,
                    expected,
                    f"input '{k}' was changed at sample {i}: expected {value_text(before[k][i])} (as given), "
                    f"got {value_text(v[i])}",
                )


def check_chunking_invariance(cls: type[Block]) -> None:
    """Feeding 1, 7 or irregular numbers of samples per chunk gives the same output as one chunk."""
    check = "chunking invariance"
    expected = "the same output, bit for bit, whatever the chunk sizes"
    whole = _run(cls, check, expected)
    for chunk in (1, 7, [3, 250, 1, 64]):
        why = first_difference(
            whole, _run(cls, check, expected, chunk=chunk), f"when fed {_fed(chunk)}", "whole"
        )
        if why:
            raise ConformanceError(cls.name, check, expected, why)


def check_empty_chunks(cls: type[Block]) -> None:
    """Empty chunks between real ones leave state and output untouched."""
    check, expected = "empty chunks", "empty chunks between real ones to change nothing"
    plain = _run(cls, check, expected, chunk=13)
    padded = _run(cls, check, expected, chunk=13, empty_between=True)
    why = first_difference(plain, padded, f"when fed {_fed(13, True)}", "without")
    if why:
        raise ConformanceError(cls.name, check, expected, why)


def check_documented(cls: type[Block]) -> None:
    """A summary line, a doc for every field and every port."""
    check = "documented"
    doc = (cls.__doc__ or "").strip()
    if not (doc and doc.splitlines()[0].strip()):
        raise ConformanceError(
            cls.name, check, "a docstring whose first line says what the block does", "it has none"
        )
    for f in cls.config_cls.fields_info():
        if not f.doc:
            raise ConformanceError(
                cls.name,
                check,
                f"a doc for every parameter: param(..., doc=...) on '{f.name}'",
                "it has none",
            )
    for name, port in {**cls.inputs, **cls.outputs}.items():
        if not name.isidentifier():
            raise ConformanceError(
                cls.name, check, "port names that are identifiers", f"port {name!r} is not"
            )
        if not port.doc:
            raise ConformanceError(
                cls.name, check, f"a doc for every port: Port(doc=...) on '{name}'", "it has none"
            )


CHECKS: tuple[Callable[[type[Block]], None], ...] = (
    check_config_yaml_roundtrip,
    check_invalid_config_rejected,
    check_deterministic,
    check_inputs_not_mutated,
    check_chunking_invariance,
    check_empty_chunks,
    check_documented,
)
