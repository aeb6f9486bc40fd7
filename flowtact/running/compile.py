"""Graph -> CompiledGraph: execution order, resolved stream specs, and what the scene actually needs.

Compilation checks what only the whole graph can tell (port dtype/shape/units/rate agreement,
unconnected required inputs, cycles that do not pass through a delay port) and propagates demand
backwards: an output nobody consumes or records is not computed, an input a block's config makes
irrelevant (zero weights) is not demanded, and a node that ends up feeding nothing is not started
(so its optional heavy imports are never loaded).
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from flowtact.block import Block, Source
from flowtact.chunk import StreamSpec
from flowtact.errors import BlockSpecsFailed, ConfigError, GraphFileError, SpecError
from flowtact.graphfile.extras import missing_extras
from flowtact.graphfile.graph import Edge, Graph, Loc
from flowtact.graphfile.located import GraphProblem
from flowtact.graphfile.seeds import node_seed

__all__ = ["CompiledGraph", "compile_graph"]

Stream = tuple[str, str]


@dataclass
class CompiledGraph:
    """A compiled graph: what runs, in which order, on which streams."""

    graph: Graph
    order: list[str]
    """Active nodes in execution (topological) order."""
    specs: dict[Stream, StreamSpec]
    """Resolved spec of every output stream (active or not)."""
    demanded: dict[str, frozenset[str]]
    """Outputs each active node computes."""
    needed: dict[str, frozenset[str]]
    """Inputs each active node is fed."""
    active_edges: list[Edge]
    pruned: list[str]
    seeds: dict[str, int]
    record: list[Stream]
    notes: list[str] = field(default_factory=list)
    """Human-readable reasons for what was pruned (or not recorded)."""
    record_notes: list[str] = field(default_factory=list)
    """The ``record:`` entries left out, and why (a replayed file without that port)."""
    ends: dict[str, float] = field(default_factory=dict)
    """Active sources that end (played-back files): node -> graph time after their last sample."""

    @property
    def requires(self) -> set[str]:
        """Optional heavy modules the active nodes import."""
        return {m for n in self.order for m in self.graph.nodes[n].cls.requires}

    def input_specs(self, node: str) -> dict[str, StreamSpec]:
        """Specs of the streams feeding ``node``'s needed inputs."""
        return {e.dst_port: self.specs[(e.src, e.src_port)] for e in self.active_edges if e.dst == node}

    def bind(self, node: str, block: Block) -> dict[str, StreamSpec]:
        """Bind a block instance of ``node`` with its input specs, seed and demanded outputs."""
        return block.bind(self.input_specs(node), seed=self.seeds[node], demanded=self.demanded[node])


def _essential(spec: StreamSpec) -> tuple[object, ...]:
    """What a delayed stream must agree on: dtype, shape, units, rate, kind."""
    return (spec.dtype, tuple(spec.shape), spec.units, spec.rate_hz, spec.events)


def _topo_order(graph: Graph, errors: list[GraphProblem]) -> list[str]:
    """Kahn's order over non-delay edges; reports a cycle that has no delay port."""
    deps: dict[str, set[str]] = {n: set() for n in graph.nodes}
    for e in graph.edges:
        if not graph.nodes[e.dst].cls.inputs[e.dst_port].delay:
            deps[e.dst].add(e.src)
    order: list[str] = []
    ready = [n for n in graph.nodes if not deps[n]]
    remaining = {n: set(d) for n, d in deps.items()}
    while ready:
        n = ready.pop(0)
        order.append(n)
        for m, d in remaining.items():
            if n in d:
                d.discard(n)
                if not d and m not in order and m not in ready:
                    ready.append(m)
    stuck = [n for n in graph.nodes if n not in order]
    if stuck:
        cycle = _find_cycle(stuck, deps)
        edge = next(e for e in graph.edges if e.src == cycle[-2] and e.dst == cycle[-1])
        errors.append(
            GraphProblem(
                edge.loc,
                f"cycle without a delay: {' -> '.join(cycle)}",
                "a feedback loop must pass through an input declared with a one-step delay (e.g. a `delay` block)",
            )
        )
    return order


def _find_cycle(stuck: list[str], deps: Mapping[str, set[str]]) -> list[str]:
    start = stuck[0]
    path, seen = [start], {start}
    node = start
    while True:
        nxt = next(d for d in deps[node] if d in stuck)
        if nxt in seen:
            cyc = [*path[path.index(nxt) :], nxt]
            return list(reversed(cyc))
        path.append(nxt)
        seen.add(nxt)
        node = nxt


def compile_graph(graph: Graph, *, prune: bool = True) -> CompiledGraph:
    """Check the graph's streams and compute its plan; raise :class:`~flowtact.errors.GraphFileError` on problems.

    ``prune=False`` keeps every node, output and connected input (nothing is skipped, ``pruned``
    is empty): the forced-full plan ``flowtact bench skipping`` measures the pruned one against.
    """
    errors: list[GraphProblem] = []
    order = _topo_order(graph, errors)
    if errors:
        raise GraphFileError(errors)
    incoming: dict[str, list[Edge]] = defaultdict(list)
    for e in graph.edges:
        incoming[e.dst].append(e)

    blocks = {n: graph.nodes[n].make() for n in order}
    specs, broken, delayed = _stream_specs(graph, order, blocks, incoming, errors)
    _check_delayed_inputs(graph, delayed, broken, blocks, incoming, specs, errors)
    if errors:
        raise GraphFileError(sorted(errors, key=lambda e: (e.loc.line, e.loc.col)))

    record, notes = _recordable(graph, specs)
    active, demanded, needed, active_edges, pruning = (
        _propagate_demand(graph, order, blocks, incoming, record)
        if prune
        else _everything(graph, order, incoming, specs)
    )
    ends = {
        n: end
        for n in active
        if isinstance(blocks[n], Source)
        and (end := blocks[n].ends_at(_fed(n, active_edges, specs))) is not None  # type: ignore[attr-defined]
    }
    missing = missing_extras(graph, active)  # before anything starts, naming the pip extra
    if missing:
        raise GraphFileError(missing)
    return CompiledGraph(
        graph=graph,
        order=active,
        specs=specs,
        demanded=demanded,
        needed=needed,
        active_edges=active_edges,
        pruned=[n for n in order if n not in active],
        seeds=_node_seeds(graph),
        record=[(n, p) for n, p, _ in record],
        notes=notes + pruning,
        record_notes=notes,
        ends=ends,
    )


def _recordable(
    graph: Graph, specs: Mapping[Stream, StreamSpec]
) -> tuple[list[tuple[str, str, Loc]], list[str]]:
    """The ``record:`` entries whose stream exists, and a note for each that does not: a block may
    leave an output without a stream when it has no data for it (a replayed file without that port)."""
    kept, notes = [], []
    for n, p, loc in graph.record:
        if (n, p) in specs:
            kept.append((n, p, loc))
        else:
            notes.append(f"{n}.{p}: not recorded ({graph.nodes[n].cls.name} '{n}' has no data for it)")
    return kept, notes


def _fed(node: str, edges: Sequence[Edge], specs: Mapping[Stream, StreamSpec]) -> dict[str, StreamSpec]:
    """The specs of the streams feeding ``node`` along these edges (what it will be bound with)."""
    return {e.dst_port: specs[(e.src, e.src_port)] for e in edges if e.dst == node}


def _stream_specs(
    graph: Graph,
    order: list[str],
    blocks: Mapping[str, Block],
    incoming: Mapping[str, list[Edge]],
    errors: list[GraphProblem],
) -> tuple[dict[Stream, StreamSpec], set[str], list[str]]:
    """Every output's spec, node by node in order, with the nodes that failed (or sit downstream of
    a failure) and the nodes with an input fed back through a delay, in order."""
    specs: dict[Stream, StreamSpec] = {}
    broken: set[str] = set()
    delayed: dict[str, None] = {}  # an ordered set
    for n in order:
        inputs = _node_inputs(graph, n, incoming[n], specs, broken, delayed, errors)
        if n in broken:
            continue
        try:
            blocks[n].check_rates(inputs)  # what the ports declare across inputs (same_rate)
            out = blocks[n].specs(inputs)
        except (SpecError, ConfigError) as err:  # a ConfigError here: a file the config names (a replay)
            loc = next(
                (e.loc for e in incoming[n] if e.dst_port == getattr(err, "port", None)), graph.nodes[n].loc
            )
            where = getattr(err, "where", None)
            errors.append(
                GraphProblem(Loc(*where) if where else loc, f"node '{n}' ({graph.nodes[n].cls.name}): {err}")
            )
            broken.add(n)
            continue
        except Exception as err:  # a bug in the block: name its node, keep the traceback (--debug)
            raise BlockSpecsFailed(graph.nodes[n].loc, n, graph.nodes[n].cls.name, err) from err
        for port, spec in out.items():
            specs[(n, port)] = spec
    return specs, broken, list(delayed)


def _node_inputs(
    graph: Graph,
    n: str,
    edges: list[Edge],
    specs: Mapping[Stream, StreamSpec],
    broken: set[str],
    delayed: dict[str, None],
    errors: list[GraphProblem],
) -> dict[str, StreamSpec]:
    """The specs arriving at node ``n``'s inputs. Marks ``n`` broken for a missing or mismatched
    input or a broken upstream node, and delayed for an input fed by a node later in the order."""
    node = graph.nodes[n]
    cls = node.cls
    connected = {e.dst_port for e in edges}
    for pname, port in cls.inputs.items():
        if not port.optional and pname not in connected:
            errors.append(
                GraphProblem(
                    node.loc,
                    f"node '{n}': required input '{pname}' is not connected",
                    f"add an edge 'some_node.port -> {n}.{pname}'",
                )
            )
            broken.add(n)
    inputs: dict[str, StreamSpec] = {}
    for e in edges:
        src = (e.src, e.src_port)
        if e.src in broken:
            broken.add(n)
            continue
        if src not in specs:  # fed through a delay by a node later in the order
            delayed[n] = None
            continue
        port = cls.inputs[e.dst_port]
        why = port.mismatch(specs[src])
        if why:
            what = f": {port.doc}" if port.doc else ""
            errors.append(GraphProblem(e.loc, f"{e}: input '{e.dst_port}' of '{n}' ({cls.name}{what}) {why}"))
            broken.add(n)
        inputs[e.dst_port] = specs[src]
    return inputs


def _check_delayed_inputs(
    graph: Graph,
    delayed: list[str],
    broken: set[str],
    blocks: Mapping[str, Block],
    incoming: Mapping[str, list[Edge]],
    specs: Mapping[Stream, StreamSpec],
    errors: list[GraphProblem],
) -> None:
    """Ask the nodes fed back through a delay for their specs again, now that the loop's upstream
    is known: their outputs must not depend on the delayed input."""
    for n in delayed:
        if n in broken:
            continue
        inputs = {e.dst_port: specs[(e.src, e.src_port)] for e in incoming[n] if (e.src, e.src_port) in specs}
        try:
            again = blocks[n].specs(inputs)
        except SpecError as err:
            errors.append(GraphProblem(graph.nodes[n].loc, f"node '{n}': {err}"))
            continue
        if any(_essential(again[p]) != _essential(specs[(n, p)]) for p in again):
            errors.append(
                GraphProblem(
                    graph.nodes[n].loc,
                    f"node '{n}': its output spec depends on its delayed input",
                    "declare the fed-back stream (dtype, shape, units, rate_hz) in the delay block's parameters",
                )
            )


def _node_seeds(graph: Graph) -> dict[str, int]:
    """Each node's seed: its own, else derived from the graph's seed and its name."""
    return {
        n: graph.nodes[n].seed if graph.nodes[n].seed is not None else node_seed(graph.seed, n)
        for n in graph.nodes
    }


def _everything(
    graph: Graph, order: list[str], incoming: Mapping[str, list[Edge]], specs: Mapping[Stream, StreamSpec]
) -> tuple[list[str], dict[str, frozenset[str]], dict[str, frozenset[str]], list[Edge], list[str]]:
    """The unpruned plan: every node active, every output that has a stream computed, every
    connected input fed."""
    demanded = {n: frozenset(p for p in graph.nodes[n].cls.outputs if (n, p) in specs) for n in order}
    needed = {n: frozenset(e.dst_port for e in incoming.get(n, [])) for n in order}
    edges = sorted(
        (e for n in order for e in incoming.get(n, [])), key=lambda e: (order.index(e.dst), e.dst_port)
    )
    return list(order), demanded, needed, edges, []


def _propagate_demand(
    graph: Graph,
    order: list[str],
    blocks: Mapping[str, Block],
    incoming: Mapping[str, list[Edge]],
    record: list[tuple[str, str, Loc]],
) -> tuple[list[str], dict[str, frozenset[str]], dict[str, frozenset[str]], list[Edge], list[str]]:
    """Walk backwards from recorded streams and sinks.

    Returns the active nodes (in order), the outputs each computes, the inputs each is fed, the
    edges that carry data, and a note for everything skipped.
    """
    demanded: dict[str, set[str]] = defaultdict(set)
    for n, p, _ in record:
        demanded[n].add(p)
    # One backward pass misses demand that flows back through a delayed (loop) input: the loop's
    # source is visited before the node it feeds; so pass again until nothing new is demanded.
    while True:
        before = {n: frozenset(d) for n, d in demanded.items()}
        result = _demand_pass(graph, order, blocks, incoming, demanded)
        if {n: frozenset(d) for n, d in demanded.items()} == before:
            return result


def _demand_pass(
    graph: Graph,
    order: list[str],
    blocks: Mapping[str, Block],
    incoming: Mapping[str, list[Edge]],
    demanded: dict[str, set[str]],
) -> tuple[list[str], dict[str, frozenset[str]], dict[str, frozenset[str]], list[Edge], list[str]]:
    """One backward pass of :func:`_propagate_demand`, adding to ``demanded``."""
    active: set[str] = {n for n in order if graph.nodes[n].cls.sink}
    needed: dict[str, frozenset[str]] = {}
    active_edges: list[Edge] = []
    notes: list[str] = []
    for n in reversed(order):
        if demanded[n]:
            active.add(n)
        if n not in active:
            notes.append(f"{n}: not started (nothing consumes or records its outputs)")
            continue
        unused = set(graph.nodes[n].cls.outputs) - demanded[n]
        if unused and any(e.src == n for e in graph.edges):
            notes.append(f"{n}: outputs {', '.join(sorted(unused))} not computed (not consumed)")
        connected = frozenset(e.dst_port for e in incoming.get(n, []))
        need = blocks[n].needs(connected)
        needed[n] = need
        for e in incoming.get(n, []):
            if e.dst_port in need:
                demanded[e.src].add(e.src_port)
                active_edges.append(e)
            else:
                notes.append(f"{n}.{e.dst_port}: not demanded (its parameters make it irrelevant)")
    ordered = [n for n in order if n in active]
    active_edges.sort(key=lambda e: (ordered.index(e.dst), e.dst_port))
    return ordered, {n: frozenset(demanded[n]) for n in ordered}, needed, active_edges, notes
