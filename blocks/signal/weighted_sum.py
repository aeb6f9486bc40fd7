"""A weighted sum of up to four aligned sample streams (the drive of an afferent population)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numba import njit

from flowtact import (
    BadDataConfig,
    Block,
    Chunk,
    Example,
    Port,
    SpecError,
    StreamSpec,
    param,
)
from flowtact.streams.align import Aligner, screen_aligned

__all__ = ["WeightedSum", "WeightedSumConfig"]

_INPUTS = ("x1", "x2", "x3", "x4")


@njit(cache=True)
def _weighted(x: np.ndarray, w: np.ndarray, bias: float) -> tuple[np.ndarray, int]:
    """``bias + Σ_c w[c] · x[:, c]`` per sample, over the non-zero weights in channel order, and how
    many of the sums are not finite."""
    y = np.empty(x.shape[0])
    y[:] = bias
    return y, _add_weighted(y, x, w)


@njit(cache=True)
def _add_weighted(y: np.ndarray, x: np.ndarray, w: np.ndarray) -> int:
    """``y += w[c] · x[:, c]`` for every non-zero weight, channel by channel: the sum's fixed order.

    Returns how many ``y`` are then not finite: with finite inputs, sums that overflowed (±inf or
    NaN, never a warning). After the last input's pass, that is the block's ``overflow`` count.
    """
    bad = 0
    for j in range(y.shape[0]):
        acc = y[j]
        for c in range(w.shape[0]):
            if w[c] != 0.0:
                acc += w[c] * x[j, c]
        y[j] = acc
        if not math.isfinite(acc):
            bad += 1
    return bad


@dataclass(frozen=True)
class WeightedSumConfig(BadDataConfig):
    """Parameters of :class:`WeightedSum`."""

    w1: tuple[float, ...] | None = param(None, doc="weights on x1, one per channel", min_len=1)
    w2: tuple[float, ...] | None = param(None, doc="weights on x2, one per channel", min_len=1)
    w3: tuple[float, ...] | None = param(None, doc="weights on x3, one per channel", min_len=1)
    w4: tuple[float, ...] | None = param(None, doc="weights on x4, one per channel", min_len=1)
    bias: float = param(0.0, doc="constant added to every output sample")
    units: str = param("1", doc="units of the output")
    expect_units: tuple[str, ...] = param(
        (),
        doc="units the inputs must have, x1 first (weights are per unit: N and mN differ 1000x); empty: any",
    )

    def check(self) -> None:
        if self.w1 is None:
            raise self.error("w1", "is required (one weight per channel of x1)")
        if len(self.expect_units) > len(_INPUTS):
            raise self.error("expect_units", f"must name at most {len(_INPUTS)} units (x1..x4)")

    def weights(self) -> dict[str, tuple[float, ...] | None]:
        """The weights per input (None: not given)."""
        return {f"x{i}": getattr(self, f"w{i}") for i in range(1, 5)}


class WeightedSum(Block):
    """Weighted sum of up to four sampled inputs: the drive of an afferent population.

    Ports
    -----
    x1 : float64, shape () or (C1,), sampled — required
    x2, x3, x4 : float64, shape () or (Ck,), optional
    y : float64, shape (), units ``units`` — ``bias + Σ_k w_k · x_k`` per sample, stamped like x1

    Config
    ------
    See :class:`WeightedSumConfig`. ``expect_units`` makes the units part of the weights' meaning:
    feeding ``mN`` or ``N/s`` where ``N`` is expected is an error naming the port. A domain's
    preset sets both (``preset: touch.SA1``: Table I of Rager et al. on F, F' and F'').

    Notes
    -----
    Demand: only inputs with at least one non-zero weight are needed (x1 always, it is the clock),
    so zero weights on x3 (Table I's on F'') make x3 unneeded and the compiler prunes its producer.
    Wiring rules (checked when specs are resolved): a connected input without weights is an error
    (its data would be silently ignored); an unconnected input with a non-zero weight is an error
    (its term would be silently missing); zero weights may be left unconnected.

    Alignment: inputs may arrive with different delays (a centred derivative comes (N−1)/2
    samples after the raw force, with equal timestamps). Each input is buffered and the common
    prefix is emitted; paired samples must carry equal timestamps (to 1e-6 of a period), else
    :class:`MisalignedError`. Latency: that of the slowest input; samples still unpaired at the
    end of the stream are dropped and counted (``unpaired_at_end``).
    ``on_bad_data: drop`` drops the whole instant (every input) so that the streams stay aligned.
    Finite inputs whose sum overflows (≳ 1e308) give ±inf (or NaN for inf − inf), counted
    ``overflow``: the consumer's own ``on_bad_data`` then applies (nlif stops by default).
    The sum is elementwise in a fixed order (bias, then x1..x4 channel by channel): chunking
    never changes a bit.

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.signal.weighted_sum import WeightedSum
    >>> from flowtact.testing import run_offline
    >>> f = np.tile([0.0, 0.1, 0.12], (4, 1))             # N
    >>> out = run_offline(WeightedSum(w1=[0.405, 8.908, 0.382], w2=[-1e-3, 1e-3, 5.4e-4]),
    ...                   x1=f, x2=np.zeros((4, 3)), units={"x1": "N", "x2": "N/s"})
    >>> round(float(out["y"].data[0]), 6)                 # 8.908·0.1 + 0.382·0.12
    0.93664
    """

    config_cls = WeightedSumConfig
    inputs = {
        "x1": Port(dtype="float64", ndim=(0, 1), require_rate=True, doc="first input (the output's clock)"),
        "x2": Port(dtype="float64", ndim=(0, 1), require_rate=True, optional=True, doc="second input"),
        "x3": Port(dtype="float64", ndim=(0, 1), require_rate=True, optional=True, doc="third input"),
        "x4": Port(dtype="float64", ndim=(0, 1), require_rate=True, optional=True, doc="fourth input"),
    }
    outputs = {"y": Port(dtype="float64", shape=(), doc="weighted sum, one value per sample")}
    counter_docs = {
        "nonfinite_drop": "instants where an input had NaN/inf, removed from every input (on_bad_data: "
        "drop): upstream sent bad data",
        "nonfinite_hold": "input samples (per input) with NaN/inf, held at the last finite value "
        "(on_bad_data: hold): upstream sent bad data",
        "overflow": "samples whose sum of finite inputs overflowed float64 (|y| > 1.8e308): emitted as "
        "±inf or NaN, so the consumer's on_bad_data applies; inputs far outside any physical range",
        "unpaired_at_end": "input samples with no partners on the other inputs when the stream ended: not "
        "summed (the inputs delivered different numbers of samples)",
    }

    def needs(self, connected: frozenset[str]) -> frozenset[str]:
        w = self.config.weights()
        return frozenset(
            p for p in connected if p == "x1" or (w[p] is not None and any(v != 0 for v in w[p]))
        )

    def specs(self, inputs: Mapping[str, StreamSpec]) -> dict[str, StreamSpec]:
        cfg, w = self.config, self.config.weights()
        for p in _INPUTS:
            wp = w[p]
            if p not in inputs:
                if wp is not None and any(v != 0 for v in wp):
                    raise SpecError(p, f"w{p[1]} gives non-zero weights to '{p}' but '{p}' is not connected")
                continue
            spec = inputs[p]
            if wp is None:
                raise SpecError(
                    p, f"input '{p}' is connected but has no weights (set w{p[1]}, or disconnect it)"
                )
            if len(wp) != spec.size:
                raise SpecError(
                    p,
                    f"w{p[1]} has {len(wp)} weights but input '{p}' has {spec.size} channel(s)",
                )
            i = int(p[1]) - 1
            if i < len(cfg.expect_units) and spec.units != cfg.expect_units[i]:
                raise SpecError(
                    p,
                    f"input '{p}' must be in '{cfg.expect_units[i]}' (expect_units: the weights are per "
                    f"{cfg.expect_units[i]}) but gets '{spec.units}'",
                )
            if not math.isclose(spec.rate_hz or 0.0, inputs["x1"].rate_hz or 0.0, rel_tol=1e-9):
                raise SpecError(
                    p, f"input '{p}' is {spec.rate_hz:g} Hz but x1 is {inputs['x1'].rate_hz:g} Hz"
                )
        return {"y": StreamSpec(dtype="float64", shape=(), units=cfg.units, rate_hz=inputs["x1"].rate_hz)}

    def reset(self) -> None:
        w = self.config.weights()
        used = self.needs(frozenset(self.input_specs))
        self._ports = [p for p in _INPUTS if p in used]
        self._w = {p: np.asarray(w[p], np.float64) for p in self._ports}
        self._nc = {p: self.input_specs[p].size for p in self._ports}
        rate = self.input_specs["x1"].rate_hz or 1.0
        self._align = Aligner(self.node, self.input_specs, self._ports, tol_s=1e-6 / rate)
        self._last: dict[str, np.ndarray | None] = {p: None for p in self._ports}

    def step(self, **inputs: Chunk) -> dict[str, Chunk]:
        t, data = self._align.push(inputs)
        n = len(t)
        if n:
            t, data = screen_aligned(self, self.config.on_bad_data, t, data, self._last)
            n = len(t)
        first, *rest = self._ports
        y, bad = _weighted(data[first].reshape(n, self._nc[first]), self._w[first], self.config.bias)
        for p in rest:
            bad = _add_weighted(y, data[p].reshape(n, self._nc[p]), self._w[p])
        self.count("overflow", bad)
        return {"y": Chunk(t, y)}

    def flush(self) -> dict[str, Chunk]:
        left = sum(self._align.pending().values())
        self.count("unpaired_at_end", left)
        return {}

    @classmethod
    def example(cls) -> Example:
        rng = np.random.default_rng(2)
        n = 500
        f = np.abs(np.cumsum(rng.normal(0.0, 0.01, (n, 3)), axis=0))
        df = np.gradient(f, 1e-3, axis=0)
        return Example(
            params={"w1": [1.417, 2.359, 0.452], "w2": [-0.012, -9.912e-4, 0.024], "w3": [0.0, 0.0, 0.0]},
            inputs={"x1": f, "x2": df, "x3": np.gradient(df, 1e-3, axis=0)},
            units={"x1": "N", "x2": "N/s", "x3": "N/s^2"},
        )
