"""``flowtact fit-force REC.h5``: fit ``linear_force``'s per-sensor lines on a recording.

:func:`fit_linear_force` fits F = intercept + slope·SSIM by ordinary least squares on paired
(SSIM, force) samples; :func:`fit_from_recording` pairs them by time stamp in a flowtact
recording; :func:`main` is the command (``--ssim ssim.y --force sim.force --json out.json``).
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from flowtact.commands import Command
from flowtact.console.command import CommandParser, run_command
from flowtact.errors import UsageError
from flowtact.inputs.limits import cli_float

from .hand import FINGERS

__all__ = ["COMMAND", "MAX_TOL_S", "fit_from_recording", "fit_linear_force", "main"]

MAX_TOL_S = 1.0
"""Widest pairing tolerance for ``--tol-s``: samples a second apart are not the same moment."""


# -- fitting ---------------------------------------------------------------------------------------


def fit_linear_force(
    ssim: np.ndarray, force: np.ndarray
) -> tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]:
    """Ordinary least squares F ≈ intercept + slope·SSIM per sensor (column).

    ``ssim`` and ``force`` are (n, k) arrays of paired samples (k sensors; 1-D for one sensor).
    Pairs with a non-finite value in that sensor's column are left out. Returns
    ``(slope, intercept, mae)``, one value per sensor; ``mae`` is the mean absolute error of the
    unclipped line on the samples it was fitted to (the thesis's Table 4.2 metric).
    """
    x = np.asarray(ssim, np.float64)
    y = np.asarray(force, np.float64)
    if x.ndim == 1:
        x = x[:, None]
    if y.ndim == 1:
        y = y[:, None]
    if x.shape != y.shape or x.ndim != 2:
        raise ValueError(f"ssim and force must have the same shape (n, sensors); got {x.shape} and {y.shape}")
    slopes, intercepts, maes = [], [], []
    for s in range(x.shape[1]):
        ok = np.isfinite(x[:, s]) & np.isfinite(y[:, s])
        xs, ys = x[ok, s], y[ok, s]
        if len(xs) < 2:
            raise ValueError(f"sensor {s}: need at least 2 finite (ssim, force) pairs, got {len(xs)}")
        xm, ym = xs.mean(), ys.mean()
        sxx = float(np.sum((xs - xm) ** 2))
        if not sxx > 0:
            raise ValueError(f"sensor {s}: SSIM is constant ({xm:g}) over the data; the slope is undefined")
        slope = float(np.sum((xs - xm) * (ys - ym)) / sxx)
        intercept = float(ym - slope * xm)
        slopes.append(slope)
        intercepts.append(intercept)
        maes.append(float(np.mean(np.abs(ys - (intercept + slope * xs)))))
    return tuple(slopes), tuple(intercepts), tuple(maes)


def fit_from_recording(
    path: str | Path,
    ssim_stream: str = "ssim.y",
    force_stream: str = "sim.force",
    *,
    tol_s: float = 1e-9,
) -> dict[str, Any]:
    """Fit :func:`fit_linear_force` on a flowtact recording's SSIM and true-force streams.

    Samples are paired by equal time stamps (within ``tol_s``); the streams must both have
    shape (k,) with units "1" (SSIM) and "N" (force). Returns a dict: ``slope_n``,
    ``intercept_n`` (lists, ready for ``linear_force``'s parameters), ``mae_n``, ``pairs`` (number
    of paired samples), ``sensors`` (labels), the stream names and the path.
    """
    from flowtact.recording.hdf5 import read_recording, stream_specs

    specs = stream_specs(path)
    for name in (ssim_stream, force_stream):
        if name not in specs:
            raise KeyError(f"{path}: no stream '{name}' (streams: {', '.join(sorted(specs))})")
    rec = read_recording(path, [ssim_stream, force_stream])
    s, f = rec.streams[ssim_stream], rec.streams[force_stream]
    if s.spec.units != "1":
        raise ValueError(f"{path}: '{ssim_stream}' must be SSIM (units '1'), got '{s.spec.units}'")
    if f.spec.units != "N":
        raise ValueError(f"{path}: '{force_stream}' must be a force in 'N', got '{f.spec.units}'")
    if s.data.shape[1:] != f.data.shape[1:]:
        raise ValueError(
            f"{path}: '{ssim_stream}' samples have shape {s.data.shape[1:]} but '{force_stream}' "
            f"{f.data.shape[1:]}"
        )
    i_s, i_f = _pair_by_time(s.t, f.t, tol_s)
    if len(i_s) < 2:
        raise ValueError(
            f"{path}: only {len(i_s)} samples of '{ssim_stream}' and '{force_stream}' share a time stamp"
        )
    x = s.data[i_s].reshape(len(i_s), -1)
    y = f.data[i_f].reshape(len(i_f), -1)
    slope, intercept, mae = fit_linear_force(x, y)
    labels = s.spec.labels or (FINGERS if x.shape[1] == len(FINGERS) else None)
    return {
        "slope_n": list(slope),
        "intercept_n": list(intercept),
        "mae_n": list(mae),
        "pairs": len(i_s),
        "sensors": list(labels) if labels else list(range(x.shape[1])),
        "ssim_stream": ssim_stream,
        "force_stream": force_stream,
        "path": str(path),
    }


def _pair_by_time(ta: np.ndarray, tb: np.ndarray, tol_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Indices (ia, ib) of samples of two sorted time arrays whose times agree within ``tol_s``."""
    if not len(ta) or not len(tb):
        return np.empty(0, np.intp), np.empty(0, np.intp)
    j = np.clip(np.searchsorted(tb, ta), 1, len(tb) - 1) if len(tb) > 1 else np.zeros(len(ta), np.intp)
    prev = np.maximum(j - 1, 0)
    pick = np.where(np.abs(tb[prev] - ta) <= np.abs(tb[j] - ta), prev, j)
    ok = np.abs(tb[pick] - ta) <= tol_s
    ia = np.flatnonzero(ok)
    ib = pick[ok]
    _, first = np.unique(ib, return_index=True)  # one partner each
    return ia[first], ib[first]


# -- the command -----------------------------------------------------------------------------------


def main(argv: Sequence[str] | None = None) -> int:
    """``flowtact fit-force REC.h5``: fit the SSIM→force lines of a recording; its exit status
    (:func:`flowtact.console.command.run_command`: 0 ok, 2 a bad flag or a recording without the streams
    asked for, 1 failed)."""
    return run_command(lambda: _fit(list(sys.argv[1:] if argv is None else argv)), prog="flowtact fit-force")


def _parser() -> CommandParser:
    ap = CommandParser(
        prog="flowtact fit-force",
        description="Fit linear_force's per-sensor lines F = intercept + slope·SSIM on a recording that "
        "holds an SSIM stream and a true-force stream (e.g. tactip_sim's), paired by time stamp.",
    )
    ap.add_argument("recording", help="flowtact recording (.h5)")
    ap.add_argument("--ssim", default="ssim.y", help="SSIM stream '<node>.<port>' (default ssim.y)")
    ap.add_argument(
        "--force", default="sim.force", help="true-force stream '<node>.<port>' (default sim.force)"
    )
    ap.add_argument(
        "--tol-s",
        type=cli_float(0, MAX_TOL_S, "s"),
        default=1e-9,
        help=f"time stamps closer than this pair (default 1e-9, at most {MAX_TOL_S:g})",
    )
    ap.add_argument("--json", metavar="OUT", help="also write the fit to this JSON file")
    return ap


def _fit(argv: list[str]) -> int:
    args = _parser().parse_args(argv)
    if args.json and Path(args.json).is_dir():  # found before the fit, not after it was printed
        raise UsageError(f"--json {args.json}: is a folder; give the file to write")
    try:
        fit = fit_from_recording(args.recording, args.ssim, args.force, tol_s=args.tol_s)
    except (KeyError, ValueError) as e:  # the recording lacks what the flags ask for
        raise UsageError(str(e.args[0] if isinstance(e, KeyError) and e.args else e)) from e
    print(f"{fit['pairs']} (SSIM, force) pairs from {args.recording}: {args.ssim} vs {args.force}")
    print(f"{'sensor':>8} {'slope N':>10} {'intercept N':>12} {'MAE N':>8}")
    for name, a, b, m in zip(fit["sensors"], fit["slope_n"], fit["intercept_n"], fit["mae_n"], strict=True):
        print(f"{name!s:>8} {a:10.4f} {b:12.4f} {m:8.4f}")
    print("linear_force parameters for the graph:")
    print(f"  slope_n: [{', '.join(f'{v:.6g}' for v in fit['slope_n'])}]")
    print(f"  intercept_n: [{', '.join(f'{v:.6g}' for v in fit['intercept_n'])}]")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(fit, fh, indent=1)
    return 0


COMMAND = Command(main=main)
"""``flowtact fit-force``: parses its own arguments (entry-point group ``flowtact.commands``)."""
