"""Run a Braille reading graph in this process and cut its spikes into character windows.

What ``flowtact train-braille`` and the ``braille`` benchmark share: :func:`read_line` runs the
open-loop graph (or any graph with a ``braille_scan`` node named ``scan``) on a text or on seeded
random letters at a given speed, fast and in process, and returns each population's spikes with
the character windows. The windows come from the finger's position and the known cell pitch
(:func:`position_windows`: ``braille_cell_windows`` and the decoder's own window rule, a maximal
run of one cell index, applied offline), never from the simulator's ``char`` stream, which only
labels them (for training and scoring). :func:`char_windows` is the same rule on ``char``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

import flowtact.api as ft

from .cell_windows import cell_window_values
from .cells import CATEGORIES, LETTERS, PAPER_SCALE, Geometry

__all__ = [
    "GAPS",
    "LAYERS",
    "OPEN_GRAPH",
    "Reading",
    "char_windows",
    "position_windows",
    "prefix_windows",
    "read_line",
]

#: The shipped open-loop graph (graphs/braille_open.yaml, found from any folder).
OPEN_GRAPH = "braille_open"
#: Feature layer → the node whose ``spikes`` it reads in the Braille graphs.
LAYERS: Mapping[str, str] = {"first": "afferents", "second": "cuneate"}
#: ``char`` categories that are not character windows: between cells, and the dot-less space cell.
GAPS: tuple[str, ...] = ("gap", "space")


@dataclass(frozen=True)
class Reading:
    """One scanned line: spikes per layer, the character windows [t0, t1) (from position) and their
    labels (from ``char``: a letter, or ``space`` for a dot-less cell)."""

    spikes: Mapping[str, tuple[np.ndarray, np.ndarray]]
    n_units: Mapping[str, int]
    windows: np.ndarray
    letters: tuple[str, ...]
    duration_s: float
    streams: Mapping[str, Any]
    rate_hz: float = 250.0


def char_windows(
    t: np.ndarray, char: np.ndarray, categories: Sequence[str] = CATEGORIES, gaps: Iterable[str] = GAPS
) -> tuple[np.ndarray, tuple[str, ...]]:
    """Windows ``(n, 2)`` and labels of the maximal runs of one non-gap ``char`` value; a run still
    open at the last sample is left out (as the decoder leaves it)."""
    skip = {i for i, c in enumerate(categories) if c in set(gaps)}
    v = np.asarray(char, np.float64)
    out, labels, start = [], [], None
    for k in range(len(v)):
        val = int(v[k]) if np.isfinite(v[k]) else -1
        gap = val in skip or not 0 <= val < len(categories)
        if start is not None and (gap or val != int(v[start])):
            out.append((t[start], t[k]))
            labels.append(categories[int(v[start])])
            start = None
        if not gap and start is None:
            start = k
    return np.array(out, np.float64).reshape(-1, 2), tuple(labels)


def _runs(t: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Windows ``(n, 2)`` [t of a run's first sample, t of the first sample after it) of the maximal
    runs of one value >= 0 in ``v`` (integers), and each run's first sample index; a run still open
    at the last sample is left out (as ``naive_bayes`` leaves it)."""
    v = np.asarray(v, np.int64)
    if not len(v):
        return np.zeros((0, 2)), np.zeros(0, np.int64)
    change = np.flatnonzero(np.diff(v)) + 1
    starts = np.concatenate([[0], change])
    ends = np.concatenate([change, [len(v)]])
    keep = (v[starts] >= 0) & (ends < len(v))
    starts, ends = starts[keep], ends[keep]
    return np.column_stack([t[starts], t[ends]]).astype(np.float64).reshape(-1, 2), starts


def position_windows(
    t: np.ndarray,
    position: np.ndarray,
    char: np.ndarray | None = None,
    *,
    scale: float = PAPER_SCALE,
    categories: Sequence[str] = CATEGORIES,
) -> tuple[np.ndarray, tuple[str, ...]]:
    """The decoder's windows ``(n, 2)`` from the finger's ``position`` (mm) and the cell pitch
    (``braille_cell_windows`` then the decoder's run rule), and their labels: the ``char`` category
    at each window's first sample (``""`` without ``char``; ``gap`` where no cell lies there)."""
    t = np.asarray(t, np.float64)
    k = cell_window_values(np.asarray(position, np.float64), Geometry(scale=scale))
    windows, starts = _runs(t, k.astype(np.int64))
    if char is None:
        return windows, tuple("" for _ in starts)
    c = np.asarray(char, np.float64)[starts]
    return windows, tuple(categories[int(x)] if np.isfinite(x) else "gap" for x in c)


def graph_text(
    graph: str | Path,
    *,
    seed: int,
    speed_mm_s: float | None = None,
    text: str | None = None,
    letters: int | None = None,
    params: Mapping[str, Mapping[str, Any]] | None = None,
    tick_s: float | None = None,
    record: Sequence[str] | None = None,
) -> tuple[Path, str]:
    """The graph file's path and its YAML with the seed, the scan's text and speed, node
    parameters (node → {param: value}), the tick and the recorded streams replaced."""
    from flowtact.errors import SafeYamlError
    from flowtact.graphfile.graph import resolve_graph_path
    from flowtact.graphfile.safe_yaml import load_value, read_graph_text
    from flowtact.inputs.safe_text import shown

    path = resolve_graph_path(graph)
    if not path.exists():
        raise ValueError(f"{shown(graph)}: no such graph file")
    try:  # bounded like any graph file: a regular file of at most 1 MiB, YAML within the loader's limits
        doc = load_value(read_graph_text(path))
    except SafeYamlError as e:
        raise ValueError(f"{shown(path)}:{e}") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("nodes"), dict) or "scan" not in doc["nodes"]:
        raise ValueError(f"{shown(path)}: not a Braille reading graph (no 'scan' node)")
    doc["seed"] = int(seed)
    if tick_s is not None:
        doc["tick_s"] = tick_s
    scan = doc["nodes"]["scan"].setdefault("params", {})
    if text is not None:
        scan.update(text=text, random_letters=0)
    if letters is not None:
        scan.update(text="", random_letters=int(letters))
    if speed_mm_s is not None:
        scan["speed_mm_s"] = float(speed_mm_s)
    for node, values in (params or {}).items():
        if node not in doc["nodes"]:
            raise ValueError(f"{graph}: no node {node!r} (nodes: {', '.join(doc['nodes'])})")
        doc["nodes"][node].setdefault("params", {}).update(values)
    if record is not None:
        doc["record"] = list(record)
    return path, yaml.safe_dump(doc, sort_keys=False)


def read_line(
    graph: str | Path = OPEN_GRAPH,
    *,
    seed: int,
    speed_mm_s: float | None = None,
    text: str | None = None,
    letters: int | None = None,
    params: Mapping[str, Mapping[str, Any]] | None = None,
    layers: Sequence[str] = ("first", "second"),
    extra: Sequence[str] = (),
    tick_s: float = 0.2,
    duration_s: float | None = None,
    progress: Callable[[float, float | None], None] | None = None,
) -> Reading:
    """Run ``graph`` in process, fast, and return what a decoder sees: the windows of the cells that
    hold a letter (from position; a space cell's window is left out). An open-loop graph keeps
    nothing of its tick (its blocks are chunking-invariant), so a long ``tick_s`` only saves
    time; a closed loop must keep its own (pass ``tick_s=0`` to keep the graph's)."""
    from flowtact.graphfile.graph import load_graph
    from flowtact.running.compile import compile_graph
    from flowtact.running.source_ends import default_duration
    from flowtact.runtime.inproc import InprocExecutor
    from flowtact.testing import MemoryRecorder

    streams = ["scan.char", "scan.position", *(f"{LAYERS[k]}.spikes" for k in layers), *extra]
    streams = list(dict.fromkeys(streams))
    path, yml = graph_text(
        graph, seed=seed, speed_mm_s=speed_mm_s, text=text, letters=letters, params=params,
        tick_s=tick_s or None, record=streams,
    )  # fmt: skip
    plan = compile_graph(load_graph(path, text=yml))
    memory = MemoryRecorder()
    duration = default_duration(plan, duration_s)
    InprocExecutor(
        plan, fast=True, tick_s=tick_s or plan.graph.tick_s, recorder=memory, progress=progress
    ).run(duration)
    got = {s: ft.concat(memory.chunks.get(s, []), plan.specs[tuple(s.split("."))]) for s in streams}  # type: ignore[index]
    char, pos = got["scan.char"], got["scan.position"]
    scale = float(yaml.safe_load(yml)["nodes"]["scan"].get("params", {}).get("scale", PAPER_SCALE))
    windows, labels = position_windows(pos.t, pos.data, char.data, scale=scale)
    letter = np.array([c in LETTERS for c in labels], bool)  # a space cell's window: not a letter
    windows, labels = windows[letter], tuple(c for c, ok in zip(labels, letter, strict=True) if ok)
    spikes = {
        k: (got[f"{LAYERS[k]}.spikes"].t, np.asarray(got[f"{LAYERS[k]}.spikes"].data, np.int64))
        for k in layers
    }
    n_units = {k: int(plan.specs[(LAYERS[k], "spikes")].n_units or 0) for k in layers}
    rate = float(plan.specs[("scan", "char")].rate_hz or 1.0)
    end = float(char.t[-1]) + 1.0 / rate if len(char) else 0.0
    return Reading(spikes, n_units, windows, labels, end, got, rate)


def prefix_windows(windows: np.ndarray, rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """The partial windows the decoder's ``running`` output scores: for each window [t0, t1) and
    each of its samples t_k = t0 + k/rate, [t0, t_k + 1/rate); returns them and their window index."""
    out, owner = [], []
    for w, (t0, t1) in enumerate(np.asarray(windows, np.float64).reshape(-1, 2)):
        n = max(round((t1 - t0) * rate_hz), 1)
        ends = t0 + (np.arange(n) + 1) / rate_hz
        out.append(np.column_stack([np.full(n, t0), ends]))
        owner.append(np.full(n, w))
    if not out:
        return np.zeros((0, 2)), np.zeros(0, np.int64)
    return np.vstack(out), np.concatenate(owner)
