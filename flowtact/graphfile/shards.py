"""Population shards: ``shards: K`` on a node splits it into K nodes over contiguous unit slices.

Why: one population (the whole hand's 17 000 afferents) is too much for one core; its units are
independent, so K processes can each run a slice. The split is a graph rewrite made when the graph
is loaded, above the runtime (which needs no change): node ``X`` with ``shards: K`` becomes

* ``X__s0 … X__s{K-1}``: the same block over units ``[b_k, b_{k+1})``, parameters sliced by the
  block (:meth:`Block.shard_params`), the unsharded node's seed, each in its own process group
  (``X_s{k}``, or the k-th name of the node's ``process:`` list);
* ``X__in_<port>_k`` (:class:`ShardSlice`): columns ``[b_k, b_{k+1})`` of each input (a scalar
  input passes whole), placed with the input's producer;
* ``X`` itself (:func:`merge_class`: block ``shard_merge[<block>]``): the shards' outputs merged
  back, event streams renumbered (unit + b_k) into one stream sorted by (time, unit) and sample
  streams concatenated column-wise, so consumers and recordings see the unsharded ``X``'s streams.

Two nodes sharded alike (same K and bounds) are joined shard to shard, without a merge and slice
between them. Boundaries are as even as the block's alignment allows (:meth:`Block.shard_align`:
a noisy nlif splits only at its noise streams' boundaries, so each unit draws the same normals
sharded or not and a ``--fast`` recording is bit-identical). docs/touchsim.md.
"""

from __future__ import annotations

import functools
import itertools
import re
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from flowtact.block import Block, Port
from flowtact.catalog.presets import apply_preset
from flowtact.chunk import Chunk, StreamSpec
from flowtact.errors import SpecError
from flowtact.params import Config, param

if TYPE_CHECKING:
    from flowtact.graphfile.located import GraphProblem
    from flowtact.graphfile.nodes import Edge, NodeDef

__all__ = [
    "MAX_SHARDS",
    "MERGE_RE",
    "ShardSlice",
    "expand_shards",
    "merge_class",
    "shard_bounds",
]

MAX_SHARDS = 16
"""Shards of one node at most (each is a process on one host)."""
MERGE_RE = re.compile(r"^shard_merge\[([^\[\]]+)\]$")


def shard_bounds(n: int, k: int, align: int) -> list[int] | str:
    """``k + 1`` unit boundaries splitting ``n`` units as evenly as multiples of ``align`` allow,
    or why it cannot be done."""
    if k > n:
        return f"shards: {k} is more than its {n} units"
    blocks = -(-n // align)  # alignment blocks (the last may be short)
    if k > blocks:
        return (
            f"shards: {k} needs at least {k} blocks of {align} units (its noise streams) but it has "
            f"{n} units; use at most {blocks} shards or no noise"
        )
    cuts = [round(i * blocks / k) * align for i in range(k)]
    return [*cuts, n]


# -- the slice ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class ShardSliceConfig(Config):
    """Which columns a shard takes."""

    lo: int = param(0, doc="first column taken", ge=0)
    hi: int = param(1, doc="one past the last column taken", ge=1)

    def check(self) -> None:
        if self.hi <= self.lo:
            raise self.error("hi", f"must be > lo ({self.lo})")


class ShardSlice(Block):
    """Columns ``[lo, hi)`` of a stream of channel vectors (a scalar stream passes whole): a shard's input.

    Notes
    -----
    Inserted by ``shards: K`` (flowtact.graphfile.shards); usable alone. Samples are copied, never altered;
    labels are sliced with the columns.

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.graphfile.shards import ShardSlice
    >>> from flowtact.testing import run_offline
    >>> run_offline(ShardSlice(lo=1, hi=3), x=np.arange(8.0).reshape(2, 4))["y"].data.tolist()
    [[1.0, 2.0], [5.0, 6.0]]
    """

    name = "shard_slice"
    config_cls = ShardSliceConfig
    inputs = {"x": Port(dtype=None, ndim=(0, 1), doc="channel vectors (n,) or a scalar")}
    outputs = {"y": Port(dtype=None, doc="columns lo:hi, shape (hi - lo,); a scalar input passes whole")}

    def specs(self, inputs: Mapping[str, StreamSpec]) -> dict[str, StreamSpec]:
        x, c = inputs["x"], self.config
        if x.shape == ():
            return {"y": x}
        if c.hi > x.shape[0]:
            raise SpecError("x", f"{self.node}: columns {c.lo}:{c.hi} of a stream of {x.shape[0]} channels")
        labels = x.labels[c.lo : c.hi] if x.labels is not None else None
        return {"y": x.with_(shape=(c.hi - c.lo,), labels=labels)}

    def reset(self) -> None:
        self._whole = self.input_specs["x"].shape == ()

    def step(self, x: Chunk) -> dict[str, Chunk]:
        if self._whole:
            return {"y": x}
        return {"y": Chunk(x.t, np.ascontiguousarray(x.data[:, self.config.lo : self.config.hi]), x.end)}

    @classmethod
    def example(cls) -> Any:
        from flowtact.block import Example

        return Example(params={"lo": 1, "hi": 3}, inputs={"x": np.arange(40.0).reshape(10, 4)}, rate_hz=100.0)


# -- the merge ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class ShardMergeConfig(Config):
    """Where each shard's units start in the whole population."""

    bounds: tuple[int, ...] = param((0, 1), doc="unit boundaries b_0 = 0 < b_1 < … < b_K = n", min_len=2)

    def check(self) -> None:
        b = self.bounds
        if b[0] != 0 or any(x >= y for x, y in itertools.pairwise(b)):
            raise self.error("bounds", f"must start at 0 and increase; got {list(b)}")


class _Events:
    """One shard's events not yet released, and how far in time that shard is known."""

    def __init__(self) -> None:
        self.t: list[np.ndarray] = []
        self.d: list[np.ndarray] = []
        self.end = -np.inf


class ShardMerge(Block):
    """The shards' outputs as the unsharded node's: events renumbered and merged, samples joined.

    Notes
    -----
    Input ``<port>_<k>`` is shard k's output ``<port>``. Events (unit index, or rows whose first
    column is the unit) get ``+ b_k`` and are released once every shard's watermark has passed
    them, sorted by (time, unit): the unsharded population's order, whatever the chunking.
    Sample streams are joined column-wise once every shard has delivered the sample (their
    time stamps must agree). The watermark is the least of the shards'.
    """

    config_cls = ShardMergeConfig
    base: type[Block] = Block

    def specs(self, inputs: Mapping[str, StreamSpec]) -> dict[str, StreamSpec]:
        out = {}
        k = len(self.config.bounds) - 1
        for port in self.outputs:
            got = [inputs.get(f"{port}_{i}") for i in range(k)]
            if all(g is None for g in got):
                continue
            if any(g is None for g in got):
                raise SpecError(port, f"{self.node}: output '{port}' is fed by some shards, not all")
            specs: list[StreamSpec] = got  # type: ignore[assignment]
            first = specs[0]
            if first.events:
                out[port] = first.with_(n_units=self.config.bounds[-1])
            else:
                cols = sum(s.shape[0] if s.shape else 1 for s in specs)
                labels = None
                if all(s.labels is not None for s in specs):
                    labels = tuple(lab for s in specs for lab in s.labels)  # type: ignore[union-attr]
                out[port] = first.with_(shape=(cols,), labels=labels)
        return out

    def reset(self) -> None:
        b = self.config.bounds
        self._k = len(b) - 1
        self._ports = {p: self.input_specs[f"{p}_0"] for p in self.outputs if f"{p}_0" in self.input_specs}
        self._ev = {p: [_Events() for _ in range(self._k)] for p, s in self._ports.items() if s.events}
        self._smp: dict[str, list[list[Chunk]]] = {
            p: [[] for _ in range(self._k)] for p, s in self._ports.items() if not s.events
        }

    def step(self, **inputs: Chunk) -> dict[str, Chunk]:
        out = {}
        for p in self._ports:
            chunks = [inputs.get(f"{p}_{i}") for i in range(self._k)]
            out[p] = self._events(p, chunks, False) if p in self._ev else self._samples(p, chunks, False)
        return out

    def flush(self) -> dict[str, Chunk]:
        none: list[Chunk | None] = [None] * self._k
        return {
            p: self._events(p, none, True) if p in self._ev else self._samples(p, none, True)
            for p in self._ports
        }

    def _events(self, port: str, chunks: list[Chunk | None], last: bool) -> Chunk:
        held, b = self._ev[port], self.config.bounds
        for i, c in enumerate(chunks):
            if c is None:
                continue
            h = held[i]
            if len(c):
                d = np.array(c.data, copy=True)
                if d.ndim == 1:
                    d += b[i]
                else:
                    d[:, 0] += b[i]
                h.t.append(np.asarray(c.t, np.float64))
                h.d.append(d)
            if c.end is not None:
                h.end = max(h.end, float(c.end))
        until = np.inf if last else min(h.end for h in held)
        ts, ds = [], []
        for h in held:
            if not h.t:
                continue
            t, d = np.concatenate(h.t), np.concatenate(h.d)
            n = int(np.searchsorted(t, until, side="left"))
            ts.append(t[:n])
            ds.append(d[:n])
            h.t, h.d = ([t[n:]], [d[n:]]) if n < len(t) else ([], [])
        spec = self._ports[port]
        end = None if not np.isfinite(until) else until
        if last:
            ends = [h.end for h in held if np.isfinite(h.end)]
            end = min(ends) if ends else None
        if not ts:
            return Chunk.empty(spec, end=end)
        t, d = np.concatenate(ts), np.concatenate(ds)
        unit = d if d.ndim == 1 else d[:, 0]
        order = np.lexsort((unit, t))
        return Chunk(t[order], d[order], end)

    def _samples(self, port: str, chunks: list[Chunk | None], last: bool) -> Chunk:
        held = self._smp[port]
        for i, c in enumerate(chunks):
            if c is not None and len(c):
                held[i].append(c)
        have = [sum(len(c) for c in h) for h in held]
        m = min(have)
        if last and max(have) != m:
            self.count("unpaired_at_end", max(have) - m)
        spec = self._ports[port]
        if m == 0:
            return Chunk.empty(self.output_specs[port])
        parts = []
        for i, h in enumerate(held):
            t = np.concatenate([c.t for c in h])
            d = np.concatenate([np.asarray(c.data).reshape(len(c), -1) for c in h])
            parts.append((t[:m], d[:m]))
            held[i] = [Chunk(t[m:], d[m:].reshape(-1, *spec.shape))] if len(t) > m else []
        t0 = parts[0][0]
        if any(not np.array_equal(t0, t) for t, _ in parts[1:]):
            raise ValueError(f"{self.node}: the shards' '{port}' samples carry different time stamps")
        return Chunk(t0, np.concatenate([d for _, d in parts], axis=1))

    counter_docs = {
        "unpaired_at_end": "samples some shards delivered and others did not when the stream ended: "
        "not emitted (a shard stopped early)"
    }


@functools.cache
def merge_class(base: type[Block]) -> type[ShardMerge]:
    """The merge block for shards of ``base`` (registry name ``shard_merge[<base name>]``): inputs
    ``<port>_<k>`` for every output port and shard, outputs named as ``base``'s."""
    inputs = {
        f"{p}_{k}": Port(dtype=None, events=port.events, optional=True, doc=f"shard {k}'s '{p}'")
        for p, port in base.outputs.items()
        for k in range(MAX_SHARDS)
    }
    outputs = {p: replace(port, optional=False) for p, port in base.outputs.items()}
    return type(
        f"ShardMerge_{base.name}",
        (ShardMerge,),
        {"name": f"shard_merge[{base.name}]", "inputs": inputs, "outputs": outputs, "base": base},
    )


# -- the rewrite -------------------------------------------------------------------------------


def shard_groups(node: NodeDef, k: int) -> list[str]:
    """The process group of each shard: the node's ``process:`` list, else ``<node>_s<k>``."""
    if isinstance(node.process, list):
        return list(node.process)
    return [f"{node.name}_s{i}" for i in range(k)]


def check_shards(
    node: NodeDef, shards: Any, loc: Any
) -> tuple[tuple[int, int, int] | None, list[GraphProblem]]:
    """``(units, shards, alignment)`` of a node's ``shards:``, or the located errors that forbid it."""
    from flowtact.graphfile.located import GraphProblem

    where = f"node '{node.name}'"
    if isinstance(shards, bool) or not isinstance(shards, int) or not 1 <= shards <= MAX_SHARDS:
        return None, [
            GraphProblem(loc, f"{where}: 'shards' must be an integer from 1 to {MAX_SHARDS}; got {shards!r}")
        ]
    cls = node.cls
    if not getattr(cls, "shardable", False):
        return None, [
            GraphProblem(
                loc,
                f"{where}: block '{cls.name}' cannot be sharded (its units are not declared independent)",
                "shardable blocks: nlif, rectified_gain, iir, touchsim_probe, shard_slice",
            )
        ]
    n = cls.shard_units(node.config)
    if n is None:
        return None, [
            GraphProblem(
                loc, f"{where}: shards need the unit count in its parameters (n, models or per-unit lists)"
            )
        ]
    procs = node.process
    if isinstance(procs, list) and len(procs) != shards:
        return None, [GraphProblem(loc, f"{where}: 'process' lists {len(procs)} groups for {shards} shards")]
    return (n, shards, cls.shard_align(node.config)), []


def plan_bounds(
    split: Mapping[str, tuple[int, int, int]], edges: list[Edge]
) -> tuple[dict[str, list[int]], dict[str, str]]:
    """Unit bounds of every node in ``split`` (name -> (units, shards, alignment)), and why a node
    cannot be split. Nodes joined by an edge with the same units and shards are cut alike, at the
    coarsest alignment among them, so they connect shard to shard."""
    root = {n: n for n in split}

    def find(n: str) -> str:
        while root[n] != n:
            n = root[n]
        return n

    for e in edges:
        a, b = split.get(e.src), split.get(e.dst)
        if a is not None and b is not None and a[:2] == b[:2]:
            root[find(e.src)] = find(e.dst)
    align: dict[str, int] = {}
    for n, (_, _, al) in split.items():
        align[find(n)] = max(align.get(find(n), 1), al)
    bounds, why = {}, {}
    for n, (units, k, _) in split.items():
        b = shard_bounds(units, k, align[find(n)])
        if isinstance(b, str):
            why[n] = b
        elif k > 1:
            bounds[n] = b
    return bounds, why


def expand_shards(
    nodes: dict[str, NodeDef],
    edges: list[Edge],
    recorded: set[tuple[str, str]],
    bounds: Mapping[str, list[int]],
    node_seed: Any,
) -> tuple[dict[str, NodeDef], list[Edge]]:
    """Nodes and edges with every sharded node split (see the module's docstring); ``bounds`` maps
    each sharded node to its unit boundaries, ``recorded`` holds the recorded (node, port) streams
    and ``node_seed(name)`` is a node's seed."""
    if not bounds:
        return nodes, edges
    out: dict[str, NodeDef] = {}
    new_edges: list[Edge] = []
    for name, node in nodes.items():
        b = bounds.get(name)
        if b is None:
            out[name] = node
            continue
        n, k = b[-1], len(b) - 1
        seed = node.seed if node.seed is not None else node_seed(name)
        groups = shard_groups(node, k)
        for i in range(k):
            owner = f"{name}__s{i} ({node.cls.name})"
            params = node.cls.shard_params(apply_preset(node.cls.name, node.params, owner), b[i], b[i + 1], n)
            sname = f"{name}__s{i}"
            out[sname] = replace(
                node,
                name=sname,
                params=params,
                config=node.cls.configure(params, owner=f"{sname} ({node.cls.name})"),
                process=groups[i],
                seed=seed,
            )
        merge = merge_class(node.cls)
        mparams = {"bounds": list(b)}
        proc = node.process if isinstance(node.process, str) else None
        out[name] = replace(
            node, block=merge.name, cls=merge, params=mparams, config=merge.configure(mparams), process=proc
        )
    merged = {(n, p) for n, p in recorded if n in bounds}
    for e in edges:
        bs, bd = bounds.get(e.src), bounds.get(e.dst)
        if bs is not None and bs != bd:
            merged.add((e.src, e.src_port))  # read from the merge, named as the node
        if bd is None:
            new_edges.append(e)
            continue
        k = len(bd) - 1
        if bs is not None and bs == bd:  # sharded alike: shard to shard
            new_edges += [replace(e, src=f"{e.src}__s{i}", dst=f"{e.dst}__s{i}") for i in range(k)]
            continue
        for i in range(k):
            sl = f"{e.dst}__in_{e.dst_port}_{i}"
            out[sl] = _slice_node(nodes[e.dst], sl, bd[i], bd[i + 1])
            new_edges.append(replace(e, dst=sl, dst_port="x"))
            new_edges.append(replace(e, src=sl, src_port="y", dst=f"{e.dst}__s{i}"))
    for e in new_edges:  # fed shard to shard: run with that shard unless the node names groups
        if e.src.rpartition("__s")[0] in bounds and not isinstance(
            nodes[e.dst.rpartition("__s")[0]].process, list
        ):
            out[e.dst] = replace(out[e.dst], process=None)
    for name in bounds:  # a merge nothing reads: not made
        if not any(n == name for n, _ in merged):
            del out[name]
    return out, new_edges + _merge_edges(nodes, bounds, merged)


def _slice_node(node: NodeDef, name: str, lo: int, hi: int) -> NodeDef:
    params = {"lo": lo, "hi": hi}
    return replace(
        node,
        name=name,
        block=ShardSlice.name,
        cls=ShardSlice,
        params=params,
        config=ShardSlice.configure(params),
        process=None,
        seed=None,
        param_locs={},
    )


def _merge_edges(
    nodes: Mapping[str, NodeDef], bounds: Mapping[str, list[int]], used: set[tuple[str, str]]
) -> list[Edge]:
    """Shard k's output ``p`` -> merge input ``p_k`` for each port ``used`` (read from the merge by
    an edge that is not shard to shard, or recorded)."""
    from flowtact.graphfile.nodes import Edge

    out = []
    for name, b in bounds.items():
        loc = nodes[name].loc
        for p in nodes[name].cls.outputs:
            if (name, p) not in used:
                continue
            out += [Edge(f"{name}__s{i}", p, name, f"{p}_{i}", loc) for i in range(len(b) - 1)]
    return out


def shard_deadlines(deadlines: list[Any], nodes: Mapping[str, NodeDef]) -> list[Any]:
    """Deadlines with a sharded source split: ``from: X`` becomes one deadline from each shard
    ``X__s{i}`` (the sources the runtime stamps; ``X`` itself is then a merge, or gone)."""
    out = []
    for d in deadlines:
        shards = [n for n in nodes if n.rpartition("__s")[0] == d.src and n.rpartition("__s")[2].isdigit()]
        if d.src in nodes and not shards:
            out.append(d)
            continue
        out += [replace(d, src=n) for n in shards] or [d]
    return out
