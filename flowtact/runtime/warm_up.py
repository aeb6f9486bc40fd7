"""Warm blocks up before the clock starts: every kernel a run calls is loaded or compiled first.

A block's first step loads its numba kernels from the cache, or compiles them on the first run
after an install (seconds to tens of seconds); on the real-time clock that is a stall a loop
through several processes never catches up. So each block's throwaway copy steps on synthetic
input shaped like the real run's: the declared dtype and sample shape, chunks of one tick and of
several, zeros and a ramp (a ramp drives neurons over threshold: spike paths run too), read-only
arrays (what blocks are given; numba compiles read-only arrays apart) both aligned and not (as
small wire messages arrive), every needed input present. A block whose kernels a synthetic
step cannot reach defines ``warm_up()`` (docs/writing-a-block.md). :class:`CompileWatch` counts
what numba actually compiles (cache misses, not cache loads), names the kernel under way and
counts numba's compiler passes: a compile advances pass by pass, which the supervisor's start-up
window sees as progress (a long compile is never a stall).
"""

from __future__ import annotations

import contextlib
import gc
import os
import sys
import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from flowtact.block import Block, Source
from flowtact.chunk import Chunk, StreamSpec

__all__ = [
    "CompileWatch",
    "WarmUpReport",
    "load_shared_kernels",
    "settle_heap",
    "synthetic_inputs",
    "warm_shared_kernels",
    "warm_up",
    "warm_up_here",
]

VARIANTS = (
    (1, "zeros", True, ""),
    (1, "ramp", False, ""),
    (1, "ramp", True, "rest"),
    (1, "ramp", False, ""),
    (1, "ramp", True, "first"),
    (4, "ramp", False, ""),
)
"""Warm-up steps in order: (ticks of data, values, aligned arrays, inputs that lag). One copy steps
through all, so state built by one step (spikes in a history) is there for the next. Inputs from
other processes arrive unevenly: in a step where ``first`` or the ``rest`` of the needed inputs
(sorted by name) lag, they get nothing, and catch up in the next step; a block that holds one
input back waiting for another then runs that path too."""
WARM_STEPS = len(VARIANTS) + 3
"""Steps of one node's warm-up, as reported: build the copy, each variant, its ``warm_up()``, its flush."""
MAX_TICK_S = 0.005
"""A warm-up tick covers at most this much graph time (5 samples at 1 kHz): a ``--fast`` run's
1 s tick would have a 100 000-neuron population step seconds of data just to load its kernels."""
MAX_CHUNK_BYTES = 1 << 20
"""A warm-up chunk holds at most this much data (a few camera frames, not a minute of them)."""


class CompileWatch:
    """Counts numba compilations in this process and names the kernel being compiled.

    Listens to numba's ``numba:compile`` event, which fires on a cache miss only: loading a
    kernel from numba's cache is not counted. Read from other threads (the heartbeat): plain
    attributes only.
    """

    def __init__(self, on_first: Callable[[str], None] | None = None) -> None:
        self.on_first = on_first
        """Called once, with the kernel's name, when the first compilation begins."""
        self.count = 0
        """Kernels compiled (outermost compilations) since :meth:`install`."""
        self.current: str | None = None
        """The kernel being compiled now, or None."""
        self.passes = 0
        """Compiler passes run (numba's ``numba:run_pass`` events): progress inside one compile."""
        self.seconds = 0.0
        self._depth = 0
        self._t0 = 0.0
        self._listener: Any = None

    def install(self) -> CompileWatch:
        """Start listening, if numba is loaded (a process whose blocks never imported it compiles nothing)."""
        if self._listener is not None or "numba" not in sys.modules:
            return self
        from numba.core import event

        watch = self

        class _Listener(event.Listener):
            def on_start(self, ev: Any) -> None:
                watch._started(ev.data["dispatcher"])

            def on_end(self, ev: Any) -> None:  # noqa: ARG002 — numba's Listener signature
                watch._ended()

        class _Passes(event.Listener):
            def on_start(self, ev: Any) -> None:  # noqa: ARG002 — numba's Listener signature
                watch.passes += 1

            def on_end(self, ev: Any) -> None:
                pass

        self._listener = (_Listener(), _Passes())
        event.register("numba:compile", self._listener[0])
        event.register("numba:run_pass", self._listener[1])
        return self

    def uninstall(self) -> None:
        """Stop listening."""
        if self._listener is not None:
            from numba.core import event

            event.unregister("numba:compile", self._listener[0])
            event.unregister("numba:run_pass", self._listener[1])
            self._listener = None

    def _started(self, dispatcher: Any) -> None:
        self._depth += 1
        if self._depth == 1:
            self._t0 = time.perf_counter()
            self.current = _kernel_name(dispatcher)
            if self.on_first is not None:
                self.on_first, say = None, self.on_first
                say(self.current)

    def _ended(self) -> None:
        self._depth = max(self._depth - 1, 0)
        if self._depth == 0:
            self.count += 1
            self.seconds += time.perf_counter() - self._t0
            self.current = None


@dataclass
class WarmUpReport:
    """What a warm-up did: seconds and kernels compiled per node, and which nodes could not step."""

    seconds: dict[str, float] = field(default_factory=dict)
    compiled: dict[str, int] = field(default_factory=dict)
    skipped: dict[str, str] = field(default_factory=dict)
    """Node -> why its synthetic step raised (a block that needs ``open()``, or refuses zeros)."""

    @property
    def total_compiled(self) -> int:
        """Kernels compiled over all nodes."""
        return sum(self.compiled.values())


def warm_up(
    blocks: Mapping[str, Block],
    tick_s: float,
    *,
    watch: CompileWatch | None = None,
    on_node: Callable[[str], None] | None = None,
    on_step: Callable[[str, int, int], None] | None = None,
) -> WarmUpReport:
    """Step a throwaway copy of every block through :data:`VARIANTS`, then its ``warm_up()``.

    The copies share nothing with the real blocks but the process' caches; errors are recorded in
    the report, never raised (the real step will raise them, with the node named). ``on_node`` is
    called with each node's name before it is warmed (the worker's heartbeat names it), and
    ``on_step`` with (node, step, steps) before each of its :data:`WARM_STEPS` steps: the worker
    reports them to the supervisor as start-up progress.
    """
    watch = watch or CompileWatch()
    report = WarmUpReport()
    for name, real in blocks.items():
        if on_node is not None:
            on_node(name)
        watch.install()  # a block built earlier may have imported numba since
        before, t0 = watch.count, time.perf_counter()
        try:
            _warm_one(name, real, tick_s, (lambda i, n=name: on_step(n, i, WARM_STEPS)) if on_step else None)
        except Exception as e:  # noqa: BLE001 — a warm-up is best effort; the real step reports errors
            report.skipped[name] = f"{type(e).__name__}: {e}"
        report.seconds[name] = time.perf_counter() - t0
        report.compiled[name] = watch.count - before
    return report


def warm_shared_kernels(specs: Iterable[StreamSpec], say: Callable[[str], None] | None = None) -> int:
    """Load or compile, in this process, the framework's kernels every worker calls: the bad-data
    screen's finite test, on each float stream's sample shape as the workers get it (read-only,
    aligned and not). Numba caches them on disk, so workers started next load them instead of each
    compiling the same signatures at once. Returns how many were compiled.

    Only on a cold cache: when numba's cache already holds the kernel (its index file exists), the
    workers load it themselves, and loading it here first cost 0.8 s of every cached start-up
    (measured at load 8.6 on 2 cores); a signature missing from a warm cache is compiled by the
    worker that needs it, as before."""
    from flowtact.finite import all_finite, all_finite_kernel, all_finite_wide

    if _in_cache(all_finite_kernel) and _in_cache(all_finite_wide):
        return 0
    watch = CompileWatch(
        on_first=lambda _k: (
            say
            and say("compiling the kernels every process shares (first run after an install or upgrade)...")
        )
    )
    watch.install()
    t0 = time.perf_counter()
    _screen_shapes(all_finite, specs)
    watch.uninstall()
    if watch.count and say:
        say(
            f"{watch.count} shared kernel{'s' if watch.count > 1 else ''} compiled in {time.perf_counter() - t0:.1f} s"
        )
    return watch.count


def load_shared_kernels(specs: Iterable[StreamSpec]) -> bool:
    """Load, in this process, the kernels every worker calls, when numba's cache holds them: set
    up before workers are forked from this process, they start with numba's first dispatch (its
    target set-up, ~0.4 s of CPU) made. On a cold cache nothing is done (False): compiling here
    would hold every fork back; :func:`warm_shared_kernels` compiles them beside the workers."""
    from flowtact.finite import all_finite, all_finite_kernel, all_finite_wide

    if not (_in_cache(all_finite_kernel) and _in_cache(all_finite_wide)):
        return False
    _screen_shapes(all_finite, specs)
    return True


def _screen_shapes(all_finite: Callable[[np.ndarray], bool], specs: Iterable[StreamSpec]) -> None:
    """Call the bad-data screen on each float stream's sample shape as workers get it: one tick
    and several, read-only, aligned and not (numba types each apart); and on a float64 block too
    large for the compiled loop (a wide population's tick), which takes the vectorised test."""
    from flowtact.finite import COMPILED_MAX

    shapes = {(np.dtype(s.dtype or "float64"), s.shape) for s in specs if not s.events}
    wide = any(dtype == np.float64 for dtype, _ in shapes)
    for dtype, shape in sorted(shapes, key=str):
        if dtype.kind != "f":
            continue
        for n in (1, 4):
            a = np.zeros((n, *shape), dtype)
            a.setflags(write=False)
            all_finite(a)
            all_finite(_unaligned(a))
    if wide:
        a = np.zeros(COMPILED_MAX + 1)
        all_finite(a)
        a.setflags(write=False)
        all_finite(a)
        all_finite(_unaligned(a))


def _in_cache(dispatcher: Any) -> bool:
    """Whether numba's on-disk cache holds some compiled signature of ``dispatcher``: an index file
    (``finite.all_finite_kernel-22.py311.nbi``) in its cache folder. True where that cannot be
    told (another numba, an unreadable folder): then nothing is done twice."""
    try:
        folder, f = dispatcher.stats.cache_path, dispatcher.py_func
        prefix = f"{f.__module__.rsplit('.', 1)[-1]}.{f.__qualname__}-"
        return any(n.startswith(prefix) and n.endswith(".nbi") for n in os.listdir(folder))
    except FileNotFoundError:
        return False  # no cache folder yet: a fresh install
    except (AttributeError, TypeError, OSError):
        return True


def warm_up_here(
    blocks: Mapping[str, Block], tick_s: float, say: Callable[[str], None] | None = None
) -> WarmUpReport:
    """The in-process executor's warm-up: as a worker's, saying so itself when kernels compile."""
    say = say or (lambda text: print(f"flowtact: {text}", file=sys.stderr, flush=True))
    node: list[str] = [""]
    watch = CompileWatch(
        on_first=lambda _k: say(
            f"compiling kernels for {node[0]} (first run after an install or upgrade; numba caches them "
            "for the next runs)..."
        )
    )
    report = warm_up(blocks, tick_s, watch=watch, on_node=lambda n: node.__setitem__(0, n))
    watch.uninstall()
    if watch.count:
        say(f"{watch.count} kernel{'s' if watch.count > 1 else ''} compiled in {watch.seconds:.1f} s")
    settle_heap(freeze=False)
    return report


def settle_heap(*, freeze: bool = True) -> None:
    """Collect garbage now, before the clock starts, and (``freeze``) set aside what survives.

    Compiling leaves ~10^5 objects behind; a full collection walking them during the run paused
    a real-time worker for 0.1-0.4 s (measured). Frozen objects are skipped by later collections:
    right for a worker, which exits after its run; a caller's own process (the in-process
    executor) only collects, so cycles it drops later are still freed.
    """
    gc.collect()
    if freeze:
        gc.freeze()


def _warm_one(name: str, real: Block, tick_s: float, tell: Callable[[int], None] | None = None) -> None:
    tell = tell or (lambda _i: None)
    tell(1)
    copy = type(real)(real.config, node=name)
    copy.bind(real.input_specs, seed=real.seed, demanded=real.demanded)
    ports = sorted(real.needed)
    since = dict.fromkeys(ports, 0.0)  # each input has been fed up to this graph time
    rates = [real.input_specs[p].rate_hz for p in ports if real.input_specs[p].rate_hz]
    dt = max([min(tick_s, MAX_TICK_S)] + [1.0 / r for r in rates])  # every sampled input gets a sample
    now = 0.0
    for i, (ticks, fill, aligned, lagging) in enumerate(VARIANTS, 2):
        tell(i)
        now += ticks * dt
        late = set(ports[:1] if lagging == "first" else ports[1:] if lagging == "rest" else ())
        ins = {}
        for p in ports:
            spec = real.input_specs[p]
            if p in late:
                ins[p] = Chunk.empty(spec)
                continue
            ins |= synthetic_inputs({p: spec}, since[p], now, fill=fill, aligned=aligned)
            since[p] = now
        if isinstance(copy, Source):
            copy(now, **ins)
        else:
            copy(**ins)
    hook = getattr(copy, "warm_up", None)
    if callable(hook):
        tell(WARM_STEPS - 1)
        hook()
    tell(WARM_STEPS)
    copy.flush()  # the end-of-stream kernels too: they run while the run still counts as running


def synthetic_inputs(
    specs: Mapping[str, StreamSpec], start: float, stop: float, *, fill: str = "ramp", aligned: bool = True
) -> dict[str, Chunk]:
    """One chunk per input covering graph time ``(start, stop]`` at the stream's rate, as the run feeds it.

    ``fill`` is ``zeros`` or ``ramp`` (values rising over the chunk: drives neurons over threshold);
    ``aligned=False`` gives read-only arrays at an odd address, as small wire messages arrive.
    """
    out = {}
    for port, spec in specs.items():
        c = _synthetic_chunk(spec, start, stop, fill)
        out[port] = c if aligned else Chunk(_unaligned(c.t), _unaligned(c.data), c.end)
    return out


def _synthetic_chunk(spec: StreamSpec, start: float, stop: float, fill: str) -> Chunk:
    dtype = np.dtype(spec.dtype or "float64")
    sample_bytes = max(dtype.itemsize * spec.size, 1)
    cap = max(1, MAX_CHUNK_BYTES // sample_bytes)
    if spec.events:
        units = max(spec.n_units or 1, 1)
        n = min(units, 8, cap)
        t = start + (stop - start) * np.arange(1, n + 1) / n
        data = np.zeros((n, *spec.shape), dtype)
        data.reshape(n, -1)[:, 0] = np.arange(n) % units  # the unit index is the first column
        return Chunk(t, data, stop)
    rate = spec.rate_hz or 1000.0
    i0, i1 = int(np.floor(start * rate + 1e-9)), int(np.floor(stop * rate + 1e-9))
    n = min(i1 - i0, cap)  # the samples due in (start, stop]: none, for a slow stream in a short step
    t = (i1 - n + 1 + np.arange(n)) / rate
    data = np.zeros((n, *spec.shape), dtype)
    if fill == "ramp":
        ramp = np.linspace(0.0, 1.0, n * spec.size).reshape(data.shape)
        with contextlib.suppress(TypeError, ValueError):
            data[...] = ramp * (255 if dtype.kind in "ui" else 1) if dtype.kind != "b" else ramp > 0.5
    return Chunk(t, data)


def _unaligned(a: np.ndarray) -> np.ndarray:
    """A read-only copy of ``a`` at an odd address (what a small message's buffer gives)."""
    if a.dtype.itemsize == 1:
        return np.frombuffer(a.tobytes(), a.dtype, a.size).reshape(a.shape)
    return np.frombuffer(b"\0" + a.tobytes(), a.dtype, a.size, 1).reshape(a.shape)


def _kernel_name(dispatcher: Any) -> str:
    """``module.function`` of a numba dispatcher (``_lif_kernels.lif_grid``)."""
    f = getattr(dispatcher, "py_func", None)
    if f is None:
        return "a kernel"
    return f"{f.__module__.rsplit('.', 1)[-1]}.{f.__name__}"
