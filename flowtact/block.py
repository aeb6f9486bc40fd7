"""The block model: a frozen config, declared ports, state rebuilt by ``reset``, work in ``step``.

A block is a pure streaming transform. It never touches sockets, threads, sleeps or the wall
clock, and never mutates its inputs, so the same class runs offline on arrays, in-process in a
graph, or in a worker process, unchanged. The runtime owns the loop and the clock.
"""

from __future__ import annotations

import atexit
import dataclasses
import functools
import math
import os
import re
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, Literal

import numpy as np

from flowtact.catalog.presets import apply_preset
from flowtact.chunk import Chunk, StreamSpec
from flowtact.errors import BadDataError, SpecError
from flowtact.finite import all_finite
from flowtact.params import Config, param

if TYPE_CHECKING:
    from flowtact.runtime.rundir import RunFolder

__all__ = [
    "BadDataConfig",
    "BadDataPolicy",
    "Block",
    "Example",
    "Port",
    "Source",
    "example_folder",
    "nonfinite_counter_docs",
    "screen_nonfinite",
]

BadDataPolicy = Literal["raise", "drop", "hold"]


@dataclass(frozen=True)
class Port:
    """A declared input or output: the one place a port is described (``flowtact blocks`` renders it).

    ``None`` fields accept (inputs) or inherit (outputs) anything. ``events`` marks an event stream
    (spike times + unit index); ``optional`` an input that may be left unconnected; ``delay`` an
    input that receives data one tick late, which is what lets a feedback loop through it. On
    inputs, ``ndim`` lists the sample ranks accepted where ``shape`` is left open (``(0, 1)``: a
    value or a vector of channels), ``require_rate`` asks for a sample stream with a nominal rate
    and ``same_rate`` names another input whose rate this one must have (two streams read
    together). The framework checks inputs against these declarations on every path (graph
    compile, in-process, worker, offline), so a block never re-checks them.

    On outputs the declaration also derives the stream's spec, so most blocks need no ``specs``:
    a ``shape`` entry (outputs only) may name an integer parameter (``shape=("n",)``: ``config.n`` channels);
    ``rate`` names the input whose rate the output has, or a parameter holding it in Hz (a
    source's ``"rate_hz"``), default the first connected input's; ``labels`` (channel names) and
    ``categories`` (a categorical stream: value ``i`` means ``categories[i]``) are given as names,
    or as the name of a parameter holding them, ``()`` for none; ``n_units`` (an event stream's
    unit count) is a number or a parameter's name. Left open, ``labels`` and ``n_units`` follow the
    first connected input when the shape does.
    """

    dtype: str | None = "float64"
    shape: tuple[int | str, ...] | None = None
    units: str | None = None
    events: bool = False
    optional: bool = False
    delay: bool = False
    doc: str = ""
    ndim: tuple[int, ...] | None = None
    require_rate: bool = False
    categories: tuple[str, ...] | str | None = None
    rate: str | None = None
    labels: tuple[str, ...] | str | None = None
    n_units: int | str | None = None
    same_rate: str | None = None

    def mismatch(self, spec: StreamSpec) -> str | None:
        """Why a stream cannot feed this input port (``"expects …, gets …"``), or None."""
        if self.events != spec.events:
            want = "an event stream" if self.events else "a sample stream"
            return f"expects {want} but gets {spec.describe()}"
        if self.require_rate and not spec.events and spec.rate_hz is None:
            return f"expects a sample stream with a nominal rate but gets {spec.describe()}"
        if self.dtype is not None and self.dtype != spec.dtype:
            return f"expects dtype {self.dtype} but gets {spec.dtype}"
        if self.shape is not None and tuple(self.shape) != tuple(spec.shape):
            return f"expects sample shape {tuple(self.shape)} but gets {tuple(spec.shape)}"
        if self.ndim is not None and len(spec.shape) not in self.ndim:
            ranks = " or ".join({0: "()", 1: "(channels,)"}.get(n, f"{n} dimensions") for n in self.ndim)
            return f"expects sample shape {ranks} but gets {tuple(spec.shape)}"
        if self.units is not None and self.units != spec.units:
            return f"expects units '{self.units}' but gets '{spec.units}'"
        return None

    def derive(
        self, config: Config, inputs: Mapping[str, StreamSpec], declared: Collection[str] = ()
    ) -> StreamSpec:
        """This output's spec for a block with ``config`` fed ``inputs`` (the declaration resolved);
        ``declared`` names the block's input ports (a ``rate`` naming one left unconnected: no rate)."""
        first = next(iter(inputs.values()), StreamSpec())
        shape = None if self.shape is None else tuple(_value(config, s) for s in self.shape)
        if self.events:
            rate = None
        elif self.rate is None:
            rate = first.rate_hz
        elif self.rate in inputs or self.rate in declared:
            rate = inputs[self.rate].rate_hz if self.rate in inputs else None
        else:
            rate = _param(config, self.rate, "rate")
        if self.labels is not None:
            labels = _names(config, self.labels)
        else:
            labels = first.labels if shape is None else None
        if not self.events:
            n_units = None
        elif self.n_units is not None:
            n_units = int(_value(config, self.n_units))
        else:
            n_units = first.n_units
        return StreamSpec(
            dtype=self.dtype or first.dtype,
            shape=shape if shape is not None else first.shape,
            units=self.units if self.units is not None else first.units,
            rate_hz=rate,
            events=self.events,
            n_units=n_units,
            labels=labels,
            categories=None if self.categories is None else _names(config, self.categories),
        )


def _param(config: Config, name: str, what: str) -> Any:
    """The value of the parameter a port declaration names (a block author's typo: a clear error)."""
    if name not in {f.name for f in dataclasses.fields(config)}:
        raise TypeError(
            f"a port's {what} names '{name}', which is no parameter of {type(config).__name__} "
            "(nor, for a rate, an input)"
        )
    return getattr(config, name)


def _value(config: Config, v: int | str) -> int:
    """A shape entry or unit count: a number, or the integer parameter it names."""
    return int(_param(config, v, "shape or n_units")) if isinstance(v, str) else v


def _hz(rate: float | None) -> str:
    return "unrated" if rate is None else f"{rate:g} Hz"


def _names(config: Config, v: tuple[str, ...] | str) -> tuple[str, ...] | None:
    """Labels or categories: given, or read from the parameter named (``()``: none)."""
    names = tuple(_param(config, v, "labels or categories")) if isinstance(v, str) else tuple(v)
    return names or None


@dataclass(frozen=True)
class BadDataConfig(Config):
    """Base of the config of a block that screens its input for NaN/inf: the one policy field.

    The block applies it with :func:`screen_nonfinite` and documents what it counts with
    :func:`nonfinite_counter_docs`.
    """

    on_bad_data: Literal["raise", "drop", "hold"] = param(
        "raise",
        doc="non-finite (NaN/inf) input samples: raise (stop, naming node and port), drop them, or hold "
        "the last finite value",
        kw_only=True,
    )


@dataclass(frozen=True)
class Example:
    """Small valid inputs for a block: used by its docs and by the conformance suite."""

    params: Mapping[str, Any] = field(default_factory=dict)
    inputs: Mapping[str, np.ndarray] = field(default_factory=dict)
    rate_hz: float = 1000.0
    units: Mapping[str, str] = field(default_factory=dict)
    duration_s: float = 1.0


def example_folder() -> Path:
    """This process's private folder for the files a block's ``example()`` writes (a replay's
    file, a camera's frames). Made by :func:`flowtact.runtime.rundir.make_run_folder`: 0700 under a
    random name, so no name another local user could plant in the shared temp directory (a symlink
    to a file of ours) is ever written through; removed at exit, swept by a later run after a kill."""
    return Path(_example_run_folder(os.getpid()).path)


@functools.cache
def _example_run_folder(pid: int) -> RunFolder:
    """One folder per process (``pid`` keys the cache: a forked child makes its own)."""
    from flowtact.runtime.rundir import make_run_folder

    folder = make_run_folder("example")
    atexit.register(_remove_example_folder, folder, pid)
    return folder


def _remove_example_folder(folder: RunFolder, pid: int) -> None:
    if os.getpid() == pid:  # not from a forked child: the folder is its parent's
        folder.close()


def _snake(name: str) -> str:
    return re.sub(r"(?<!^)(?=[A-Z])", "_", name).lower()


class Block:
    """Base class of every block; see the module docstring for the contract.

    Subclasses set ``config_cls`` (a frozen :class:`~flowtact.params.Config` dataclass),
    ``inputs`` / ``outputs`` (port name -> :class:`Port`), implement ``reset`` and ``step``, and
    may override ``specs`` (output specs from input specs), ``needs`` (inputs the config makes
    relevant), ``flush`` (emit what is held back at end of stream) and ``open``/``close``. A block
    that counts things (``count``) explains each counter name in ``counter_docs``.
    """

    config_cls: ClassVar[type[Config]] = Config
    inputs: ClassVar[Mapping[str, Port]] = {}
    outputs: ClassVar[Mapping[str, Port]] = {}
    #: Optional heavy modules this block imports in ``open``/``reset`` (never at module import):
    #: import name -> the pip extra that installs it (``{"serial": "serial"}``); a plain tuple of
    #: names when no extra provides them. ``validate`` and ``run`` refuse a graph whose active
    #: blocks need one that is missing (:mod:`flowtact.graphfile.extras`).
    requires: ClassVar[Mapping[str, str] | tuple[str, ...]] = ()
    #: Registry name; defaults to the snake_case class name.
    name: ClassVar[str] = ""
    #: A sink acts on the world (a stimulator, a serial device): it runs even if nothing consumes it.
    sink: ClassVar[bool] = False
    #: What each counter the block keeps (``count``) means, in plain words: name -> one line saying
    #: what happened and whether it is harmless or a problem. The run summary and ``flowtact blocks
    #: NAME`` print it; every name counted must be here or in a base class's (a test reads the code).
    counter_docs: ClassVar[Mapping[str, str]] = {}
    #: Its units (channels, neurons) are independent, so ``shards: K`` may split them across
    #: processes (flowtact.graphfile.shards); such a block says how many (:meth:`shard_units`) and how to
    #: slice its parameters (:meth:`shard_params`, default: the ``per_unit_params`` of length n).
    shardable: ClassVar[bool] = False
    #: Parameters holding one value per unit (a list of length n is sliced with the units).
    per_unit_params: ClassVar[tuple[str, ...]] = ()

    def __init_subclass__(cls, **kw: Any) -> None:
        super().__init_subclass__(**kw)
        if not cls.__dict__.get("name"):
            cls.name = _snake(cls.__name__)

    def __init__(self, config: Config | None = None, /, *, node: str | None = None, **params: Any) -> None:
        self.node = node or self.name
        owner = f"{self.node} ({self.name})" if node else self.name
        if config is not None and params:
            raise TypeError("give either a config object or keyword parameters, not both")
        self.config: Any = config if config is not None else self.configure(params, owner=owner)
        self.seed: int = 0
        self.demanded: frozenset[str] = frozenset(self.outputs)
        self.needed: frozenset[str] = frozenset()
        self.input_specs: dict[str, StreamSpec] = {}
        self.output_specs: dict[str, StreamSpec] = {}
        self.counters: dict[str, int] = {}
        self.rng: np.random.Generator = np.random.default_rng(0)
        self._bound = False
        self._empty_inputs: dict[str, Chunk | None] = {}  # needed port -> its empty chunk, set by bind

    @classmethod
    def configure(cls, params: Mapping[str, Any], owner: str | None = None) -> Config:
        """A validated config from plain values; a ``preset: DOMAIN.NAME`` entry is expanded first."""
        owner = owner or cls.name
        return cls.config_cls.build(apply_preset(cls.name, params, owner), owner=owner)

    @classmethod
    def required_modules(cls, config: Config) -> dict[str, str]:  # noqa: ARG003 - subclasses use it
        """The optional modules a block with this config imports: name -> pip extra ("" if none).
        Override it when the config decides (a serial block in its in-process simulation needs
        no serial library)."""
        req = cls.requires
        return dict(req) if isinstance(req, Mapping) else dict.fromkeys(req, "")

    @classmethod
    def shard_units(cls, config: Config) -> int | None:  # noqa: ARG003 - shardable blocks override
        """The number of independent units a node with this config has (None: not known)."""
        return None

    @classmethod
    def shard_align(cls, config: Config) -> int:  # noqa: ARG003 - a noisy block overrides it
        """Shard boundaries fall on multiples of this (a block whose random streams cover groups
        of units aligns to the groups, so every unit draws the same numbers sharded or not)."""
        return 1

    @classmethod
    def shard_params(cls, params: dict[str, Any], lo: int, hi: int, n: int) -> dict[str, Any]:
        """The parameters of the shard running units ``[lo, hi)`` of ``n``."""
        out = dict(params)
        for k in cls.per_unit_params:
            v = out.get(k)
            if isinstance(v, (list, tuple)) and len(v) == n and n > 1:
                out[k] = list(v[lo:hi])
        if "n" in out:
            out["n"] = hi - lo
        return out

    # -- compile-time contract ---------------------------------------------------------------
    def specs(self, inputs: Mapping[str, StreamSpec]) -> dict[str, StreamSpec]:
        """Output specs for these connected inputs; raise :class:`SpecError` on a mismatch.

        The default derives each output from its declaration (:meth:`Port.derive`: declared
        dtype/shape/units/labels, parameters named there, the rest and the rate inherited from an
        input). Override it only when the derivation is genuinely custom, and keep it pure: it is
        called at compile time, possibly more than once, and must not change the block.
        """
        return {name: port.derive(self.config, inputs, self.inputs) for name, port in self.outputs.items()}

    def needs(self, connected: frozenset[str]) -> frozenset[str]:
        """The connected inputs this config actually uses (e.g. not those with zero weights)."""
        return connected

    # -- lifecycle ----------------------------------------------------------------------------
    def open(self) -> None:
        """Acquire real resources (a port, a camera, model weights) in the hosting process."""

    def close(self) -> None:
        """Release what ``open`` acquired."""

    def reset(self) -> None:
        """Build state from ``self.config``, ``self.input_specs`` and ``self.rng``."""

    def step(self, *args: Any, **inputs: Any) -> dict[str, Chunk]:
        """Turn this step's input chunks into output chunks (port name -> chunk).

        The one convention: inputs come as keyword arguments named after the ports, exactly the
        needed ones (connected, and relevant to the config), each a chunk, empty when nothing
        came; so a block writes ``def step(self, x: Chunk, gain: Chunk | None = None)`` (or
        ``**inputs: Chunk`` when its inputs are interchangeable). A :class:`Source` takes the
        graph time ``now`` first.
        """
        raise NotImplementedError

    def flush(self) -> dict[str, Chunk]:
        """At end of stream: emit what the block holds back (e.g. a centred filter's tail)."""
        return {}

    # -- driving (used by executors and by flowtact.testing) ----------------------------------
    def bind(
        self,
        inputs: Mapping[str, StreamSpec],
        *,
        seed: int = 0,
        demanded: frozenset[str] | None = None,
    ) -> dict[str, StreamSpec]:
        """Check the inputs against the declared ports, resolve specs, seed, then reset.

        Raises :class:`SpecError` naming the port when an input is unknown, missing or does not
        fit its declaration.
        """
        self.check_inputs(inputs)
        self.input_specs = dict(inputs)
        self.needed = self.needs(frozenset(self.input_specs))
        self._empty_inputs = {
            p: Chunk.empty(self.input_specs[p]).readonly() if p in self.input_specs else None
            for p in sorted(self.needed)
        }
        self.output_specs = self.specs(self.input_specs)
        self.seed = int(seed)
        if demanded is not None:
            self.demanded = frozenset(demanded)
        self.restart()
        return self.output_specs

    def check_inputs(self, inputs: Mapping[str, StreamSpec]) -> None:
        """Raise :class:`SpecError` for an unknown, missing or mismatched input (the declared ports)."""
        for name, spec in inputs.items():
            port = self.inputs.get(name)
            if port is None:
                raise SpecError(name, f"{self.name} has no input '{name}' (inputs: {', '.join(self.inputs)})")
            why = port.mismatch(spec)
            if why:
                what = f" ({port.doc})" if port.doc else ""
                raise SpecError(name, f"input '{name}'{what} {why}")
        for name, port in self.inputs.items():
            if not port.optional and name not in inputs:
                raise SpecError(name, f"input '{name}' must be connected ({port.doc or 'required'})")
        self.check_rates(inputs)

    def check_rates(self, inputs: Mapping[str, StreamSpec]) -> None:
        """Raise :class:`SpecError` when an input declared ``same_rate`` as another has a different rate."""
        for name, port in self.inputs.items():
            other = port.same_rate
            if other is None or name not in inputs or other not in inputs:
                continue
            mine, theirs = inputs[name].rate_hz, inputs[other].rate_hz
            if not math.isclose(mine or 0.0, theirs or 0.0, rel_tol=1e-9):
                raise SpecError(
                    name, f"'{name}' is {_hz(mine)} but '{other}' is {_hz(theirs)} (read together)"
                )

    def restart(self) -> None:
        """Rebuild state from scratch (same config, same seed): a fresh, deterministic start."""
        self.rng = np.random.default_rng(self.seed)
        self.counters = {}
        self.reset()
        self._bound = True

    def __call__(self, **chunks: Chunk) -> dict[str, Chunk]:
        """Run one step: ``step`` gets every needed input, read-only, empty where nothing came."""
        if not self._bound:
            raise RuntimeError(f"{self.node}: bind() the block to its input specs before stepping it")
        return self.step(**self._inputs(chunks))

    def _inputs(self, chunks: Mapping[str, Chunk]) -> dict[str, Chunk]:
        """The needed inputs as read-only chunks (an empty chunk for each that got nothing).

        A chunk already read-only is passed as it is; the empty chunks are made once, by ``bind``
        (zero-sample and read-only, so every step can share them).
        """
        got = {}
        for p, empty in self._empty_inputs.items():
            c = chunks.get(p)
            if c is not None:
                got[p] = c.readonly()
            elif empty is not None:
                got[p] = empty
            else:  # a port ``needs`` named that is not connected: fails as it always did
                got[p] = Chunk.empty(self.input_specs[p])
        return got

    def count(self, what: str, n: int = 1) -> None:
        """Add ``n`` to a named counter (reported in the run summary and recording)."""
        if n:
            self.counters[what] = self.counters.get(what, 0) + int(n)

    def summary(self) -> str | None:
        """One line on what this block did in the run, or None (the default) to say nothing.

        The run summary prints it under the node's name (``decoder: read 26 letters, 26 right``),
        in process or from any worker: it is asked once, after the final ``flush`` and before
        ``close``. Say results a user wants to read (what was decoded, what was replayed); counts
        of routine work belong in :meth:`count`. Keep it short and cheap: no I/O.
        """
        return None

    @classmethod
    def documented_counters(cls) -> dict[str, str]:
        """Every counter this class documents, its own ``counter_docs`` over its bases'."""
        docs: dict[str, str] = {}
        for klass in reversed(cls.__mro__):
            docs.update(klass.__dict__.get("counter_docs", {}))
        return docs

    @classmethod
    def example(cls) -> Example:
        """Small valid inputs; every registered block provides one."""
        raise NotImplementedError(f"{cls.__name__} has no example()")

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.node!r} {self.config}>"


class Source(Block):
    """A block the runtime ticks with the graph time ``now``, whether or not data came in.

    ``step(now)`` emits every sample whose time is before ``now`` that was not emitted yet. A
    source never sleeps or loops; its sample times come from an integer counter, ``i / rate``.
    A source may also declare inputs (a device that takes commands, a simulator driven by a
    feedback loop): ``step(now, **chunks)`` then receives, for each connected input it needs,
    what arrived since the last tick (possibly an empty chunk).
    """

    def step(self, *args: Any, **inputs: Any) -> dict[str, Chunk]:
        """``step(now, **inputs)``: emit every sample due before graph time ``now``."""
        raise NotImplementedError

    def __call__(self, now: float, **chunks: Chunk) -> dict[str, Chunk]:  # type: ignore[override]
        if not self._bound:
            raise RuntimeError(f"{self.node}: bind() the source before ticking it")
        return self.step(now, **self._inputs(chunks))

    def ends_at(self, inputs: Mapping[str, StreamSpec]) -> float | None:  # noqa: ARG002 - sources use it
        """Graph time after which this source emits nothing more (a played-back file's end), or None
        when it never ends. ``inputs`` are the specs of its connected inputs, as ``specs`` gets them
        (a scan steered by a speed input ends later). A run without a duration lasts until its
        sources' ends (:mod:`flowtact.running.source_ends`); called after ``specs``."""
        return None

    @staticmethod
    def due(now: float, rate_hz: float) -> int:
        """Number of samples with ``i / rate_hz < now`` (robust to float rounding of ``now``)."""
        x = now * rate_hz
        n = math.ceil(x - 1e-9 * max(1.0, abs(x)))  # math, not numpy: 0.3 µs against 0.9 per tick
        return max(n, 0)


def nonfinite_counter_docs(what: str) -> dict[str, str]:
    """``counter_docs`` entries for what :func:`screen_nonfinite` counts; ``what`` names the samples."""
    return {
        "nonfinite_drop": f"{what} with NaN/inf, removed (on_bad_data: drop): upstream sent bad data",
        "nonfinite_hold": f"{what} with NaN/inf, held at the last finite value (on_bad_data: hold): "
        "upstream sent bad data",
    }


def screen_nonfinite(
    block: Block, chunk: Chunk, policy: BadDataPolicy, port: str, last: np.ndarray | None
) -> tuple[Chunk, np.ndarray | None]:
    """Apply a block's bad-data policy to non-finite samples of a float chunk.

    ``raise``: stop with a message naming node and port; ``drop``: remove those samples;
    ``hold``: repeat the last finite value (zeros before any). Counts ``nonfinite_drop`` or
    ``nonfinite_hold`` (:func:`nonfinite_counter_docs` words them for the block's ``counter_docs``).
    Returns the cleaned chunk and the updated last good sample.
    """
    d = chunk.data
    if len(chunk) == 0 or d.dtype.kind != "f":
        return chunk, last
    if all_finite(d):  # the common case, one cheap pass
        return chunk, (d[-1].copy() if policy == "hold" else last)
    flat = d.reshape(len(chunk), -1)
    bad = ~np.isfinite(flat).all(axis=1)
    n_bad = int(bad.sum())
    first_bad = float(chunk.t[np.argmax(bad)])
    if policy == "raise":
        raise BadDataError(
            f"{block.node} ({block.name}): {n_bad} non-finite sample(s) on input '{port}', first at "
            f"t={first_bad:.6f} s (set on_bad_data: drop or hold to tolerate them)"
        )
    block.count("nonfinite_drop" if policy == "drop" else "nonfinite_hold", n_bad)
    if policy == "drop":
        keep = ~bad
        cleaned = Chunk(chunk.t[keep], d[keep], chunk.end)
        return cleaned, (cleaned.data[-1].copy() if len(cleaned) else last)
    out = d.copy()
    prev = np.zeros(d.shape[1:], d.dtype) if last is None else last
    for i in range(len(out)):
        if bad[i] and out.ndim == 1:  # scalar samples: a row is a numpy scalar, not a view
            out[i] = prev
        elif bad[i]:
            row = out[i]
            mask = ~np.isfinite(row)
            row[mask] = np.broadcast_to(prev, row.shape)[mask]
        prev = out[i]
    return Chunk(chunk.t, out, chunk.end), out[-1].copy()
