"""Train the Braille decoder: ``flowtact train-braille``.

Runs the open-loop graph (in process, fast) over seeded random letters at one or several constant
speeds, cuts the first- or second-order spikes into character windows (the ``char`` stream, as
the ``naive_bayes`` block does online), computes each window's features (spike counts in
time-normalised sub-bins, or first-spike latencies), fits a naive Bayes model over the 26 letters
and saves it with its provenance. A counts model also gets the temperature of its running
posterior, fitted on every prefix of the training windows (``nb_model.fit_temperature``). Run ``k`` (speed ``k`` of ``--speeds``, repetition ``r``) uses
graph seed ``--seed + k + r·len(speeds)``: its letters and its noise come from that seed. The
benchmark's held-out text uses seeds from :data:`HELDOUT_SEED` up, which this command refuses.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

import flowtact.api as ft
from flowtact.blocks.spiking.nb_model import (
    ModelError,
    NaiveBayesModel,
    fit_gaussian,
    fit_multinomial,
    fit_temperature,
    save_model,
)
from flowtact.blocks.spiking.window_features import window_features
from flowtact.commands import Command
from flowtact.console.command import CommandParser, run_command
from flowtact.console.terminal_bar import TerminalBar
from flowtact.errors import UsageError
from flowtact.inputs.limits import cli_float, cli_int

from .cells import LETTERS
from .reading import LAYERS, OPEN_GRAPH, graph_text, prefix_windows, read_line

__all__ = ["COMMAND", "HELDOUT_SEED", "build_parser", "main", "train_braille", "train_layers"]

#: Graph seeds from here up are the benchmark's held-out text; training never uses them.
HELDOUT_SEED = 100_000

# The documented bounds of a training set, checked before anything is simulated or allocated.
MAX_LETTERS = 10_000
"""Most letters in one run (``--letters``): 10 000 letters at 15 mm/s are about 70 min of reading
simulated in one process, whose spikes (about 77 MB) are held in memory until the run ends."""
MAX_WINDOWS = 30_000
"""Most character windows over all runs (letters × speeds × repeats): about 40 times the shipped
model's 780; each window also gets about 40 partial windows for the running posterior's
calibration (25 MB per 1 000 windows on the first layer's 24 units)."""
MAX_BINS = 100
"""Most time-normalised sub-bins per window (``--bins``; the shipped model uses 2)."""
MAX_SMOOTHING = 1e6
"""Largest ``--alpha`` or ``--var-smoothing`` (past this the data no longer matters)."""
FEATURE_BUDGET_BYTES = 256 << 20
"""Most memory (256 MiB) the feature matrix may take: windows × units × sub-bins × 8 bytes."""


def _speeds(text: str) -> tuple[float, ...]:
    try:
        v = tuple(float(s) for s in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected speeds in mm/s separated by commas, got {text!r}"
        ) from None
    if not v or any(not 0 < s <= 1000 for s in v):
        raise argparse.ArgumentTypeError(f"speeds must be in (0, 1000] mm/s; got {text!r}")
    return v


def train_braille(
    *,
    graph: str | Path = OPEN_GRAPH,
    speeds: Sequence[float] = (15.0, 30.0, 60.0),
    letters: int = 260,
    repeats: int = 1,
    layer: str = "first",
    features: str = "counts",
    n_bins: int = 2,
    alpha: float = 1.0,
    var_smoothing: float = 1e-3,
    seed: int = 1,
    progress: Callable[[str, float, float], None] | None = None,
) -> tuple[NaiveBayesModel, dict[str, Any]]:
    """Simulate, extract features and fit; returns the model and its provenance."""
    return train_layers(
        graph=graph, speeds=speeds, letters=letters, repeats=repeats, layers=(layer,), features=features,
        n_bins=n_bins, alpha=alpha, var_smoothing=var_smoothing, seed=seed, progress=progress,
    )[layer]  # fmt: skip


def train_layers(
    *,
    graph: str | Path = OPEN_GRAPH,
    speeds: Sequence[float] = (15.0, 30.0, 60.0),
    letters: int = 260,
    repeats: int = 1,
    layers: Sequence[str] = ("first",),
    features: str = "counts",
    n_bins: int = 2,
    alpha: float = 1.0,
    var_smoothing: float = 1e-3,
    seed: int = 1,
    progress: Callable[[str, float, float], None] | None = None,
) -> dict[str, tuple[NaiveBayesModel, dict[str, Any]]]:
    """:func:`train_braille` for several layers from the same simulated runs: layer → (model, provenance)."""
    bad = [k for k in layers if k not in LAYERS]
    if bad or not layers:
        raise ValueError(f"layer must be one of {', '.join(LAYERS)}; got {', '.join(bad) or 'none'}")
    if features not in ("counts", "latency"):
        raise ValueError(f"features must be counts or latency; got {features!r}")
    n_runs = repeats * len(speeds)
    if seed < 0 or seed + n_runs > HELDOUT_SEED:  # before the list of runs: --repeats 1e9 is refused here
        raise ValueError(
            f"seed must be in [0, {HELDOUT_SEED - n_runs}]: seeds from {HELDOUT_SEED} are held out"
        )
    bins = n_bins if features == "counts" else 1
    _check_size(graph, speeds, letters, n_runs, layers, bins)
    runs = [(s, r) for r in range(repeats) for s in speeds]
    data: dict[str, dict[str, list[Any]]] = {k: {"x": [], "prefix": []} for k in layers}
    ys: list[str] = []
    prefix_labels: list[str] = []
    per_run, n_units = [], {}
    for k, (speed, _) in enumerate(runs):

        def tick(now: float, dur: float | None, k: int = k, speed: float = speed) -> None:
            if progress is not None:
                done = k + (now / dur if dur else 0.0)
                progress(f"run {k + 1}/{len(runs)} at {speed:g} mm/s", done, len(runs))

        r = read_line(
            graph, seed=seed + k, speed_mm_s=speed, letters=letters, layers=tuple(layers), progress=tick
        )
        pw, owner = prefix_windows(r.windows, r.rate_hz)
        for layer in layers:
            n_units[layer] = r.n_units[layer]
            t, u = r.spikes[layer]
            d = data[layer]
            d["x"].append(
                window_features(t, u, r.windows, n_units=n_units[layer], n_bins=bins, kind=features)
            )  # type: ignore[arg-type]
            if features == "counts":  # the partial windows the running posterior scores: its calibration
                d["prefix"].append(window_features(t, u, pw, n_units=n_units[layer]))
        ys.extend(r.letters)
        prefix_labels.extend(r.letters[i] for i in owner)
        per_run.append({"seed": seed + k, "speed_mm_s": speed, "windows": len(r.letters)})
    missing = sorted(set(LETTERS) - set(ys))
    if missing:
        raise ValueError(f"letters {''.join(missing)} never came up in the training text: raise --letters")
    from flowtact.graphfile.graph import resolve_graph_path
    from flowtact.running.launch import versions

    common = {
        "graph": str(graph),
        "graph_sha256": hashlib.sha256(resolve_graph_path(graph).read_bytes()).hexdigest(),
        "features": features,
        "n_bins": bins,
        "alpha": alpha if features == "counts" else None,
        "var_smoothing": var_smoothing if features == "latency" else None,
        "seed": seed,
        "seeds": [p["seed"] for p in per_run],
        "speeds_mm_s": list(speeds),
        "letters_per_run": letters,
        "runs": per_run,
        "windows": len(ys),
        "flowtact_version": versions().get("flowtact", "?"),
    }
    out = {}
    for layer in layers:
        x = np.vstack(data[layer]["x"])
        if features == "counts":
            model = fit_multinomial(x, ys, tuple(LETTERS), n_units=n_units[layer], n_bins=bins, alpha=alpha)
            tau = fit_temperature(model, np.vstack(data[layer]["prefix"]), prefix_labels)
            model = dataclasses.replace(model, running_temperature=tau)
        else:
            model = fit_gaussian(x, ys, tuple(LETTERS), n_units=n_units[layer], var_smoothing=var_smoothing)
        pred = np.array(list(LETTERS))[np.argmax(model.joint_log_likelihood(x), axis=1)]
        out[layer] = (
            model,
            {
                **common,
                "layer": layer,
                "spikes_stream": f"{LAYERS[layer]}.spikes",
                "training_accuracy": float(np.mean(pred == np.array(ys))),
                "running_temperature": model.running_temperature,
            },
        )
    return out


def _check_size(
    graph: str | Path, speeds: Sequence[float], letters: int, n_runs: int, layers: Sequence[str], bins: int
) -> None:
    """Refuse (ValueError naming the flags) a training set over :data:`MAX_LETTERS`,
    :data:`MAX_WINDOWS`, :data:`MAX_BINS` or :data:`FEATURE_BUDGET_BYTES`, before any run: the
    units per layer come from the compiled graph, nothing is simulated."""
    if not (1 <= letters <= MAX_LETTERS and 1 <= bins <= MAX_BINS and n_runs >= 1):
        raise ValueError(
            f"--letters must be in [1, {MAX_LETTERS}], --bins in [1, {MAX_BINS}], --repeats >= 1; "
            f"got {letters}, {bins}, {n_runs // max(len(speeds), 1)}"
        )
    windows = letters * n_runs
    if windows > MAX_WINDOWS:
        raise ValueError(
            f"--letters {letters} × {n_runs} runs (--speeds × --repeats) is {windows} letters; "
            f"at most {MAX_WINDOWS} in all"
        )
    from flowtact.graphfile.graph import load_graph
    from flowtact.running.compile import compile_graph

    path, yml = graph_text(graph, seed=0, speed_mm_s=speeds[0], letters=letters, record=[])
    plan = compile_graph(load_graph(path, text=yml))
    units = max(int(plan.specs[(LAYERS[k], "spikes")].n_units or 0) for k in layers)
    need = windows * units * bins * 8
    if need > FEATURE_BUDGET_BYTES:
        raise ValueError(
            f"{windows} windows × {units} units × --bins {bins} need {ft.format_bytes(need)} of features; "
            f"at most {ft.format_bytes(FEATURE_BUDGET_BYTES)} (fewer --letters, --repeats or --bins)"
        )


def _bar_callback(bar: TerminalBar) -> Callable[[str, float, float], None]:
    """The trainer's ``progress(text, done, total)`` drawn on a terminal bar."""
    return lambda text, done, total: bar.update(completed=done / total, description=text)


def build_parser() -> argparse.ArgumentParser:
    p = CommandParser(
        prog="flowtact train-braille",
        description="Train the naive Bayes Braille decoder on simulated reading (graphs/braille_open.yaml).",
    )
    p.add_argument(
        "--out", default="braille_model.npz", help="model file to write (default braille_model.npz)"
    )
    p.add_argument(
        "--graph", default=OPEN_GRAPH, help=f"open-loop graph with a 'scan' node (default {OPEN_GRAPH})"
    )
    p.add_argument(
        "--speeds",
        type=_speeds,
        default=(15.0, 30.0, 60.0),
        help="constant speeds in mm/s (default 15,30,60)",
    )
    p.add_argument(
        "--letters",
        type=cli_int(1, MAX_LETTERS),
        default=260,
        help=f"random letters per run (default 260, at most {MAX_LETTERS})",
    )
    p.add_argument(
        "--repeats",
        type=cli_int(1, HELDOUT_SEED),
        default=1,
        help=f"runs per speed, each its own seed (default 1; at most {MAX_WINDOWS} letters in all)",
    )
    p.add_argument(
        "--layer",
        choices=tuple(LAYERS),
        default="first",
        help="first- or second-order spikes (default first)",
    )
    p.add_argument(
        "--features", choices=("counts", "latency"), default="counts", help="window features (default counts)"
    )
    p.add_argument(
        "--bins",
        type=cli_int(1, MAX_BINS),
        default=2,
        help=f"time-normalised sub-bins per window, counts (default 2, at most {MAX_BINS})",
    )
    p.add_argument(
        "--alpha",
        type=cli_float(0, MAX_SMOOTHING, lo_open=True),
        default=1.0,
        help="additive smoothing of counts (default 1)",
    )
    p.add_argument(
        "--var-smoothing",
        type=cli_float(0, MAX_SMOOTHING, lo_open=True),
        default=1e-3,
        help="variance smoothing of latencies (default 1e-3)",
    )
    p.add_argument(
        "--seed",
        type=cli_int(0, ft.MAX_SEED),
        default=1,
        help=f"first graph seed (default 1; < {HELDOUT_SEED})",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--json", action="store_true", help="print the provenance as JSON")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """``flowtact train-braille``: returns the exit status (:func:`flowtact.console.command.run_command`:
    0 ok, 2 a bad flag or a training set over its bounds, 1 failed)."""
    return run_command(
        lambda: _train(list(sys.argv[1:] if argv is None else argv)), prog="flowtact train-braille"
    )


def _train(argv: list[str]) -> int:
    args = build_parser().parse_args(argv)
    bar = TerminalBar("train-braille", 1.0, show=not args.no_progress, count=False, description="simulating")
    t0 = time.perf_counter()
    try:
        model, prov = train_braille(
            graph=args.graph,
            speeds=args.speeds,
            letters=args.letters,
            repeats=args.repeats,
            layer=args.layer,
            features=args.features,
            n_bins=args.bins,
            alpha=args.alpha,
            var_smoothing=args.var_smoothing,
            seed=args.seed,
            progress=_bar_callback(bar),
        )
        prov["command"] = "flowtact train-braille " + " ".join(argv)
        path = save_model(args.out, model, prov)
    except ValueError as e:  # bad arguments found while training (seed range, too few letters, size)
        if isinstance(e, ModelError):
            raise
        raise UsageError(str(e)) from e
    except KeyboardInterrupt:
        bar.close()
        print("flowtact train-braille: interrupted; nothing saved", file=sys.stderr)
        return 130
    finally:
        bar.close()
    if args.json:
        print(json.dumps(prov, indent=1))
    else:
        print(
            f"{path}: {args.features} of {prov['spikes_stream']} ({model.n_units} units, "
            f"{prov['n_bins']} sub-bins), {prov['windows']} windows at {','.join(f'{s:g}' for s in args.speeds)} mm/s; "
            f"training accuracy {prov['training_accuracy']:.1%}; {time.perf_counter() - t0:.0f} s"
        )
    return 0


COMMAND = Command(main=main)
"""``flowtact train-braille``: parses its own arguments (entry-point group ``flowtact.commands``)."""
