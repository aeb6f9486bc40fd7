"""Per-run summaries of a sweep: built-in metrics and user metrics named ``module:function``.

Built-ins: ``spikes`` (per event stream — every population, recorded or not — its event count
``spikes:STREAM`` and mean rate per unit ``rate_hz:STREAM``), ``rmse`` (``rmse:STREAM``, the root
mean square difference of a recorded stream from a reference stream, the reference linearly
interpolated at the stream's times; pairs given as ``STREAM=REFERENCE``) and ``runtime`` (the
run's ``wall_s``, its ``startup_s`` (launch to graph time 0: making blocks, compiling or loading
kernels) and its ``realtime_factor``, graph time over the *running* time from graph time 0, so a
worker's warm-up never reads as a slow graph).

A user metric is ``fn(streams) -> dict[str, float]``: ``streams`` maps each recorded stream name
(``"force.f"``) to a :class:`flowtact.recording.hdf5.RecordedStream` (``t``, ``data``, ``spec``), the same
objects :func:`flowtact.recording.hdf5.read_recording` returns, so a metric can be tried on a recording
first. Its values become columns ``function:name``.
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from flowtact.errors import SweepSpecError

__all__ = ["BUILTINS", "MetricSpec", "compute_metrics", "parse_metrics", "resolve_user_metric", "rmse"]

BUILTINS = ("spikes", "rmse", "runtime")
DEFAULT = ("spikes", "runtime")

UserMetric = Callable[[Mapping[str, Any]], Mapping[str, Any]]


@dataclass(frozen=True)
class MetricSpec:
    """Which metrics a sweep computes: built-in names, user ``module:function`` names, RMSE pairs."""

    builtins: tuple[str, ...] = DEFAULT
    user: tuple[str, ...] = ()
    rmse_pairs: tuple[tuple[str, str], ...] = ()


def resolve_user_metric(name: str) -> UserMetric:
    """Import ``module:function``; raise :class:`SweepSpecError` saying what is wrong."""
    module, sep, attr = name.partition(":")
    if not sep or not module or not attr:
        raise SweepSpecError(f"--metrics: unknown metric '{name}' (built-ins: {', '.join(BUILTINS)}; "
                             "or module:function)")  # fmt: skip
    try:
        mod = importlib.import_module(module)
    except ImportError as e:
        raise SweepSpecError(f"--metrics {name}: cannot import module '{module}' ({e})") from None
    fn = getattr(mod, attr, None)
    if not callable(fn):
        raise SweepSpecError(f"--metrics {name}: module '{module}' has no function '{attr}'")
    return fn


def parse_metrics(names: Sequence[str] | str | None, rmse_pairs: Sequence[str] = ()) -> MetricSpec:
    """``"spikes,runtime,mymod:peak"`` and ``["est.f=truth.f"]`` -> a :class:`MetricSpec`; user
    metrics are imported here so an unknown one fails before anything runs."""
    if names is None:
        items: list[str] = list(DEFAULT)
    else:
        parts = names.split(",") if isinstance(names, str) else [p for n in names for p in n.split(",")]
        items = [p.strip() for p in parts if p.strip()]
    pairs = []
    for text in rmse_pairs:
        est, sep, ref = (s.strip() for s in text.partition("="))
        if not sep or not est or not ref:
            raise SweepSpecError(f"--rmse '{text}': expected STREAM=REFERENCE (two recorded streams)")
        pairs.append((est, ref))
    builtins = tuple(dict.fromkeys(i for i in items if i in BUILTINS))
    user = tuple(dict.fromkeys(i for i in items if i not in BUILTINS))
    for name in user:
        resolve_user_metric(name)
    if "rmse" in builtins and not pairs:
        raise SweepSpecError("--metrics rmse needs --rmse STREAM=REFERENCE")
    if pairs and "rmse" not in builtins:
        builtins = (*builtins, "rmse")
    return MetricSpec(builtins, user, tuple(pairs))


def rmse(t: np.ndarray, x: np.ndarray, t_ref: np.ndarray, ref: np.ndarray) -> float:
    """RMS of ``x - ref`` over the samples of ``x`` inside the reference's time span, the
    reference interpolated linearly per channel at ``t``; NaN when they do not overlap."""
    if len(t) == 0 or len(t_ref) == 0:
        return math.nan
    inside = (t >= t_ref[0]) & (t <= t_ref[-1])
    if not inside.any():
        return math.nan
    xs = x[inside].reshape(int(inside.sum()), -1).astype(np.float64)
    rs = ref.reshape(len(t_ref), -1).astype(np.float64)
    if xs.shape[1] != rs.shape[1]:
        raise ValueError(f"rmse: {xs.shape[1]} channel(s) against a reference of {rs.shape[1]}")
    interp = np.column_stack([np.interp(t[inside], t_ref, rs[:, c]) for c in range(rs.shape[1])])
    return float(np.sqrt(np.mean((xs - interp) ** 2)))


def compute_metrics(spec: MetricSpec, streams: Mapping[str, Any], summary: Any) -> dict[str, Any]:
    """Every metric of ``spec`` for one run: its recorded ``streams`` and its RunSummary."""
    out: dict[str, Any] = {}
    if "spikes" in spec.builtins:
        for name in sorted(summary.events):
            out[f"spikes:{name}"] = int(summary.events[name])
            out[f"rate_hz:{name}"] = float(summary.rate(name))
    for est, ref in spec.rmse_pairs:
        for s in (est, ref):
            if s not in streams:
                raise KeyError(f"rmse: stream '{s}' is not recorded (recorded: {', '.join(sorted(streams))})")
        a, b = streams[est], streams[ref]
        out[f"rmse:{est}"] = rmse(a.t, a.data, b.t, b.data)
    if "runtime" in spec.builtins:
        out["wall_s"] = float(summary.wall_s)
        startup = getattr(summary, "startup_s", None)
        out["startup_s"] = float(startup) if startup is not None else math.nan
        out["realtime_factor"] = float(summary.realtime_factor)
    for name in spec.user:
        values = resolve_user_metric(name)(streams)
        if not isinstance(values, Mapping):
            raise TypeError(f"metric {name} returned {type(values).__name__}, not a dict of scalars")
        label = name.partition(":")[2]
        for k, v in values.items():
            if not isinstance(v, (int, float, str, bool, np.generic)) or isinstance(v, np.ndarray):
                raise TypeError(f"metric {name}: '{k}' is {type(v).__name__}, not a scalar")
            out[f"{label}:{k}"] = v.item() if isinstance(v, np.generic) else v
    return out
