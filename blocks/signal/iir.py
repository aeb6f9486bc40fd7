"""A causal IIR filter per channel (Butterworth and friends, designed by scipy.signal, run as sos)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numba import njit

import flowtact.api as ft

__all__ = ["Iir", "IirConfig", "design_sos", "sos_apply", "sos_apply_python"]


@njit(cache=True)
def sos_apply(x: np.ndarray, sos: np.ndarray, zi: np.ndarray) -> np.ndarray:
    """Second-order sections per channel, transposed direct form II (scipy's ``sosfilt``).

    ``x`` (n, C), ``sos`` (S, 6, C) with a0 = 1 (section s of channel c: ``sos[s, :, c]``), ``zi``
    (S, 2, C) the state, updated in place. Returns y (n, C). Channels innermost, so a sample of
    every channel is one vectorised pass over contiguous rows. Strictly sequential in time and
    the same arithmetic per channel whatever the chunking: chunk boundaries never change a bit.
    """
    n, nc = x.shape
    ns = sos.shape[0]
    y = np.empty((n, nc))
    v = np.empty(nc)
    for i in range(n):
        for c in range(nc):
            v[c] = x[i, c]
        for s in range(ns):
            b0, b1, b2, a1, a2 = sos[s, 0], sos[s, 1], sos[s, 2], sos[s, 4], sos[s, 5]
            z0, z1 = zi[s, 0], zi[s, 1]
            for c in range(nc):
                out = b0[c] * v[c] + z0[c]
                z0[c] = b1[c] * v[c] - a1[c] * out + z1[c]
                z1[c] = b2[c] * v[c] - a2[c] * out
                v[c] = out
        for c in range(nc):
            y[i, c] = v[c]
    return y


#: The plain-Python form of :func:`sos_apply` (the same source, interpreted): the test reference.
sos_apply_python = sos_apply.py_func


def design_sos(
    family: str,
    order: int,
    btype: str,
    wn: float | tuple[float, float],
    ripple_db: float = 1.0,
    stop_db: float = 40.0,
) -> np.ndarray:
    """scipy.signal's digital design (``wn`` normalised to Nyquist) as second-order sections (S, 6)."""
    from scipy import signal  # the 'signal' extra: imported only when a filter is designed

    if family == "butter":
        return signal.butter(order, wn, btype, output="sos")
    if family == "bessel":
        return signal.bessel(order, wn, btype, output="sos", norm="phase")
    if family == "cheby1":
        return signal.cheby1(order, ripple_db, wn, btype, output="sos")
    if family == "cheby2":
        return signal.cheby2(order, stop_db, wn, btype, output="sos")
    return signal.ellip(order, ripple_db, stop_db, wn, btype, output="sos")


@dataclass(frozen=True)
class IirConfig(ft.BadDataConfig):
    """Parameters of :class:`Iir`."""

    family: Literal["butter", "bessel", "cheby1", "cheby2", "ellip"] = ft.param(
        "butter", doc="design: butter, bessel (phase-normalised), cheby1, cheby2, ellip"
    )
    order: int = ft.param(3, doc="filter order (a band filter has twice as many poles)", ge=1, le=12)
    btype: Literal["lowpass", "highpass", "bandpass", "bandstop"] = ft.param(
        "lowpass", doc="lowpass, highpass, bandpass or bandstop"
    )
    cutoff_hz: tuple[float, ...] = ft.param(
        (10.0,),
        doc="cut-off (band filters: lower edge) per channel, Hz; one value for every channel",
        min_len=1,
    )
    upper_hz: tuple[float, ...] = ft.param(
        (), doc="upper band edge per channel for bandpass/bandstop, Hz (one value or one per channel)"
    )
    ripple_db: float = ft.param(1.0, doc="pass-band ripple of cheby1/ellip, dB", gt=0)
    stop_db: float = ft.param(40.0, doc="stop-band attenuation of cheby2/ellip, dB", gt=0)

    def check(self) -> None:
        if any(not (f > 0) for f in self.cutoff_hz):
            raise self.error("cutoff_hz", "every cut-off must be > 0 Hz")
        band = self.btype in ("bandpass", "bandstop")
        if band and not self.upper_hz:
            raise self.error("upper_hz", f"is required for btype {self.btype} (the upper band edge)")
        if not band and self.upper_hz:
            raise self.error("upper_hz", f"only applies to bandpass/bandstop, not {self.btype}")


class Iir(ft.Block):
    """Causal IIR filter, one per channel (per-channel cut-offs), designed by scipy.signal.

    Config
    ------
    See :class:`IirConfig`. ``cutoff_hz`` has one value (every channel) or one per channel: each
    column gets its own filter (TouchSim's prefilter: ``butter``, order 3, 10·p0 Hz per afferent).

    Notes
    -----
    The design is scipy.signal's (``butter(order, f/(rate/2), btype, output='sos')`` etc.), run as
    second-order sections in transposed direct form II — the form of ``scipy.signal.sosfilt``,
    better conditioned than the (b, a) polynomial at low cut-offs. Zero initial state (the filter
    starts at rest, like ``lfilter`` without ``zi``); the state (2 values per section and channel)
    carries across chunks, and the recursion is strictly sequential (numba kernel
    :func:`sos_apply`, Python twin :func:`sos_apply_python`): chunk boundaries never change a bit.
    Latency 0 (the filter's group delay is in the values). Edges must lie below half the rate.
    Needs scipy (``pip install 'flowtact[signal]'``) to design; running is numba.

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.signal.iir import Iir
    >>> from flowtact.testing import run_offline
    >>> x = np.ones((2000, 2))                            # unit steps at 5 kHz
    >>> y = run_offline(Iir(cutoff_hz=[50.0, 500.0]), x=x, rate_hz=5000.0)["y"].data
    >>> np.round(y[-1], 6).tolist()                       # a low-pass passes DC
    [1.0, 1.0]
    """

    config_cls = IirConfig
    shardable = True
    per_unit_params = ("cutoff_hz", "upper_hz")

    @classmethod
    def shard_units(cls, config: IirConfig) -> int | None:
        """The channels its per-channel cut-offs give (None with one cut-off for all)."""
        n = max(len(config.cutoff_hz), len(config.upper_hz))
        return n if n > 1 else None

    requires = {"scipy": "signal"}
    inputs = {
        "x": ft.Port(dtype="float64", ndim=(0, 1), require_rate=True, doc="signal, one filter per channel")
    }
    outputs = {"y": ft.Port(dtype="float64", doc="filtered signal, same shape and units")}
    counter_docs = {**ft.nonfinite_counter_docs("samples on 'x'")}

    def _edges(self, nc: int, rate_hz: float) -> list[float | tuple[float, float]]:
        """Normalised edges (to Nyquist) per channel; SpecError naming the bad parameter."""
        cfg = self.config
        per = {}
        for name in ("cutoff_hz", "upper_hz"):
            v = getattr(cfg, name)
            if v and len(v) not in (1, nc):
                raise ft.SpecError(
                    "x", f"{name} has {len(v)} values but input 'x' has {nc} channel(s) (give 1 or {nc})"
                )
            per[name] = [float(v[0] if len(v) == 1 else v[c]) for c in range(nc)] if v else []
            for f in per[name]:
                if f >= 0.5 * rate_hz:
                    raise ft.SpecError(
                        "x", f"{name} {f:g} must be below half the stream's rate ({rate_hz:g} Hz)"
                    )
        nyq = 0.5 * rate_hz
        if per["upper_hz"]:
            out: list[float | tuple[float, float]] = []
            for lo, hi in zip(per["cutoff_hz"], per["upper_hz"], strict=True):
                if not lo < hi:
                    raise ft.SpecError("x", f"upper_hz {hi:g} must be above cutoff_hz {lo:g}")
                out.append((lo / nyq, hi / nyq))
            return out
        return [f / nyq for f in per["cutoff_hz"]]

    def specs(self, inputs: Mapping[str, ft.StreamSpec]) -> dict[str, ft.StreamSpec]:
        x = inputs["x"]
        self._edges(x.size, float(x.rate_hz or 0.0))
        return {"y": x}

    def reset(self) -> None:
        cfg = self.config
        spec = self.input_specs["x"]
        self._shape, self._nc = spec.shape, spec.size
        edges = self._edges(self._nc, float(spec.rate_hz or 0.0))
        designs = {  # one design per distinct edge (a hand of 17 000 afferents has 17 cut-offs)
            wn: design_sos(cfg.family, cfg.order, cfg.btype, wn, cfg.ripple_db, cfg.stop_db)
            for wn in set(edges)
        }
        self._sos = np.ascontiguousarray(
            np.stack([designs[wn] for wn in edges], axis=-1), np.float64
        )  # (S, 6, C)
        self._zi = np.zeros((self._sos.shape[0], 2, self._nc))
        self._last: np.ndarray | None = None

    def step(self, x: ft.Chunk) -> dict[str, ft.Chunk]:
        x, self._last = ft.screen_nonfinite(self, x, self.config.on_bad_data, "x", self._last)
        n = len(x)
        if n == 0:
            return {"y": ft.Chunk.empty(shape=self._shape, end=x.end)}
        y = sos_apply(np.ascontiguousarray(x.data.reshape(n, self._nc), np.float64), self._sos, self._zi)
        return {"y": ft.Chunk(x.t, y.reshape(n, *self._shape), x.end)}

    @classmethod
    def example(cls) -> ft.Example:
        rng = np.random.default_rng(5)
        n = 1000
        x = np.cumsum(rng.normal(0.0, 0.01, (n, 3)), axis=0)
        return ft.Example(
            params={"cutoff_hz": [20.0, 50.0, 200.0]}, inputs={"x": x}, rate_hz=5000.0, units={"x": "mm"}
        )
