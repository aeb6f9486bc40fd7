"""Contact force from SSIM by a per-sensor linear model (White 2023, §4.1.2, Table 4.2), and its fit.

``linear_force`` applies F = intercept + slope·SSIM per sensor; :func:`fit_linear_force` fits
the lines by ordinary least squares on paired (SSIM, force) samples, and
:func:`fit_from_recording` does so from a flowtact recording; :func:`main` is the command
``flowtact fit-force REC.h5 [--ssim ssim.y] [--force sim.force] [--json out.json]``. numpy only.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from flowtact import (
    Block,
    Chunk,
    Config,
    Example,
    Port,
    SpecError,
    StreamSpec,
    nonfinite_counter_docs,
    param,
    screen_nonfinite,
)

from .hand import FINGERS

__all__ = ["LinearForce", "LinearForceConfig", "fit_from_recording", "fit_linear_force", "main"]

#: Default lines (N per unit SSIM, N): F = 0 at SSIM 0.85 (an undeformed TacTip against its own
#: start-up reference is ≈ 0.85–1) rising to ≈ 3 N at SSIM 0.70, the spans of Table 3.2. The
#: thesis does not print its fitted coefficients (Fig. 4.2 only plots them); fit your own with
#: ``flowtact fit-force`` (:func:`fit_from_recording`).
DEFAULT_SLOPE_N = (-20.0, -20.0, -20.0)
DEFAULT_INTERCEPT_N = (17.0, 17.0, 17.0)


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
    from flowtact.record import read_recording, stream_specs

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


# -- linear_force ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class LinearForceConfig(Config):
    """Parameters of :class:`LinearForce`."""

    slope_n: tuple[float, ...] = param(
        DEFAULT_SLOPE_N, doc="slope per sensor in N per unit SSIM (one per sensor, or one for all)", min_len=1
    )
    intercept_n: tuple[float, ...] = param(
        DEFAULT_INTERCEPT_N, doc="force at SSIM 0 per sensor in N (one per sensor, or one for all)", min_len=1
    )
    clip_negative: bool = param(True, doc="clip negative forces to 0 (a contact force cannot pull)")
    on_bad_data: Literal["raise", "drop", "hold"] = param(
        "raise", doc="non-finite SSIM samples: raise, drop them, or hold the last good value"
    )

    def check(self) -> None:
        if len(self.slope_n) != len(self.intercept_n) and 1 not in (len(self.slope_n), len(self.intercept_n)):
            raise self.error(
                "intercept_n",
                f"must have as many values as slope_n ({len(self.slope_n)}), or one; got {len(self.intercept_n)}",
            )


class LinearForce(Block):
    """Contact force from SSIM per sensor: F = intercept + slope·SSIM (White 2023, Table 4.2's model).

    Ports
    -----
    x : float64, shape (n,) or (), units "1" — SSIM per sensor (``ssim.y``)
    y : float64, same shape, units "N" — estimated contact force F_T per sensor

    Config
    ------
    See :class:`LinearForceConfig`. The defaults are a placeholder line (F = 17 − 20·SSIM N,
    0 N at SSIM 0.85, 3 N at 0.70): the thesis does not print its coefficients, so fit them
    on your sensor or on ``tactip_sim`` data with ``flowtact fit-force REC.h5``
    (:func:`fit_from_recording`) and paste the result into the graph.

    Notes
    -----
    The thesis fits one ordinary least-squares line per sensor on (SSIM, F/T-sensor force)
    pairs; test MAE 0.14–0.42 N (Table 4.2), worse than the CNN but fast and valid over the
    whole force range, which is why the live system used it. Lower SSIM means more
    deformation, so slopes are negative. ``clip_negative`` (default) clips forces below 0 to 0:
    a line extrapolated past the undeformed SSIM would otherwise report pulling forces.
    Stateless (except the last good sample for ``hold``), latency 0; ``y.end = x.end``.

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.force_linear import LinearForce
    >>> from flowtact.testing import run_offline
    >>> ssim = np.array([[0.85, 0.70, 0.90]])
    >>> run_offline(LinearForce(), x=ssim, rate_hz=40.0)["y"].data.round(9).tolist()
    [[0.0, 3.0, 0.0]]
    """

    name = "linear_force"
    config_cls = LinearForceConfig
    inputs = {"x": Port(dtype="float64", units="1", doc="SSIM per sensor")}
    outputs = {"y": Port(dtype="float64", units="N", doc="estimated contact force per sensor")}
    counter_docs = nonfinite_counter_docs("SSIM samples on 'x'")

    def specs(self, inputs: Mapping[str, StreamSpec]) -> dict[str, StreamSpec]:
        if "x" not in inputs:
            raise SpecError("x", "input 'x' must be connected")
        x = inputs["x"]
        if x.events or x.rate_hz is None or x.dtype != "float64" or len(x.shape) > 1:
            raise SpecError(
                "x", f"input 'x' must be a float64 stream of shape () or (sensors,), got {x.describe()}"
            )
        if x.units != "1":
            raise SpecError("x", f"input 'x' must be SSIM (units '1'), got '{x.units}'")
        n = x.shape[0] if x.shape else 1
        for field in ("slope_n", "intercept_n"):
            k = len(getattr(self.config, field))
            if k not in (1, n):
                raise SpecError("x", f"'{field}' has {k} values but the SSIM stream has {n} sensors")
        return {"y": x.with_(units="N")}

    def reset(self) -> None:
        x = self.input_specs["x"]
        n = x.shape[0] if x.shape else 1
        slope = np.broadcast_to(np.array(self.config.slope_n, np.float64), (n,)).copy()
        intercept = np.broadcast_to(np.array(self.config.intercept_n, np.float64), (n,)).copy()
        self._slope = slope.reshape(x.shape)
        self._intercept = intercept.reshape(x.shape)
        self._last: np.ndarray | None = None

    def step(self, x: Chunk | None = None, **_: Chunk) -> dict[str, Chunk]:
        if x is None:
            return {}
        if len(x):
            x, self._last = screen_nonfinite(self, x, self.config.on_bad_data, "x", self._last)
        f = self._intercept + self._slope * x.data
        if self.config.clip_negative:
            f = np.maximum(f, 0.0)
        return {"y": Chunk(x.t, f, x.end)}

    @classmethod
    def example(cls) -> Example:
        t = np.arange(40) / 40.0
        ssim = np.stack([0.9 - 0.2 * t, 0.88 - 0.15 * t**2, 0.8 + 0.05 * np.sin(6 * t)], 1)
        return Example(
            params={"slope_n": [-20.0, -25.0, -14.0], "intercept_n": [17.5, 21.0, 12.0]},
            inputs={"x": ssim},
            rate_hz=40.0,
            duration_s=1.0,
        )


# -- the command -----------------------------------------------------------------------------------


def main(argv: Sequence[str] | None = None) -> int:
    """``flowtact fit-force REC.h5``: fit the SSIM→force lines of a recording; 0 ok, 1 failed."""
    ap = argparse.ArgumentParser(
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
        "--tol-s", type=float, default=1e-9, help="time stamps closer than this pair (default 1e-9)"
    )
    ap.add_argument("--json", metavar="OUT", help="also write the fit to this JSON file")
    args = ap.parse_args(list(sys.argv[1:] if argv is None else argv))
    try:
        fit = fit_from_recording(args.recording, args.ssim, args.force, tol_s=args.tol_s)
    except (OSError, KeyError, ValueError) as e:
        msg = e.args[0] if isinstance(e, KeyError) and e.args else e
        print(f"flowtact fit-force: {msg}", file=sys.stderr)
        return 1
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
