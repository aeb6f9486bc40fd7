"""A first-order low-pass on the samples' own time stamps (irregular streams welcome)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numba import njit

import flowtact.api as ft

__all__ = ["Lowpass", "LowpassConfig", "lowpass_apply", "lowpass_apply_python"]


@njit(cache=True)
def lowpass_apply(
    t: np.ndarray,
    x: np.ndarray,
    state: np.ndarray,
    prev_t: float,
    started: bool,
    w: float,
    alpha_nominal: float,
    use_t: bool,
    init_first: bool,
) -> tuple[np.ndarray, float, bool, int]:
    """First-order low-pass ``s += a·(x − s)`` sample by sample; updates ``state`` (C,) in place.

    ``a = 1 − exp(−w·dt)`` (computed as ``−expm1(−w·dt)``) with ``dt`` the time since the previous
    sample when ``use_t``, else the constant ``alpha_nominal``. A sample whose ``dt <= 0`` leaves the
    state unchanged (counted in the last result). The first sample of the stream sets the state
    (``init_first``) or is filtered from zero with ``alpha_nominal``. Returns (y (n, C), prev_t,
    started, n_nonincreasing). Strictly sequential: chunk boundaries never change a bit.
    """
    n, nc = x.shape
    y = np.empty((n, nc))
    bad = 0
    for i in range(n):
        if not started:
            started = True
            prev_t = t[i]
            if init_first:
                for c in range(nc):
                    state[c] = x[i, c]
            else:
                for c in range(nc):
                    state[c] = state[c] + alpha_nominal * (x[i, c] - state[c])
        else:
            a = alpha_nominal
            if use_t:
                dt = t[i] - prev_t
                if dt > 0.0:
                    a = -math.expm1(-w * dt)
                    prev_t = t[i]
                else:
                    a = 0.0
                    bad += 1
            else:
                prev_t = t[i]
            for c in range(nc):
                state[c] = state[c] + a * (x[i, c] - state[c])
        for c in range(nc):
            y[i, c] = state[c]
    return y, prev_t, started, bad


#: The plain-Python form of :func:`lowpass_apply` (the same source, run by the interpreter): the
#: test reference for the compiled kernel.
lowpass_apply_python = lowpass_apply.py_func


@dataclass(frozen=True)
class LowpassConfig(ft.BadDataConfig):
    """Parameters of :class:`Lowpass`."""

    cutoff_hz: float = ft.param(10.0, doc="-3 dB cut-off frequency of the first-order low-pass, Hz", gt=0)
    time_base: Literal["timestamps", "nominal"] = ft.param(
        "timestamps",
        doc="timestamps: each step uses the time since the previous sample; nominal: a fixed 1/rate step",
    )
    initial: Literal["first", "zero"] = ft.param(
        "first", doc="state before the stream: its first sample (no start transient) or zero"
    )


class Lowpass(ft.Block):
    """First-order (one-pole) low-pass per channel, stepped on the samples' own timestamps.

    Config
    ------
    See :class:`LowpassConfig`.

    Notes
    -----
    y[n] = y[n−1] + a·(x[n] − y[n−1]), a = 1 − exp(−2π·f_c·Δt): the exact discretisation of
    τ·y' = x − y (τ = 1/(2π·f_c)) for an input held between samples. With ``time_base:
    timestamps`` (default) Δt is the time since the previous sample, so a stream stamped
    irregularly (the exoskeleton's samples, stamped by a clock estimator; dropped packets) is
    filtered as what happened in time: a gap lets the output move further, jitter does not
    change the cut-off. ``nominal`` uses Δt = 1/rate for every sample (a fixed IIR). A sample
    stamped at or before its predecessor does not move the state (counted ``nonincreasing_t``).
    One pole, not a 2nd-order Butterworth: no overshoot on a force step (a servo controller
    downstream must not see a filter ringing), −20 dB/decade, and exact on irregular steps; its
    step response lag is τ (16 ms at 10 Hz). The thesis low-passes the FSR without giving a
    cut-off; 10 Hz keeps its 0.25–0.6 s force step responses intact. The state starts at the
    first sample (``initial: first``) or at zero. Latency 0 (the lag is in the values);
    state: one value per channel and the last timestamp. Strictly sequential (numba kernel
    :func:`lowpass_apply`, Python twin :func:`lowpass_apply_python`): chunk boundaries never
    change a bit. The cut-off must lie below half the nominal rate. ``end`` is passed on.

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.signal.lowpass import Lowpass
    >>> from flowtact.testing import run_offline
    >>> x = np.r_[0.0, np.ones(3)]                        # a unit step at 100 Hz
    >>> y = run_offline(Lowpass(cutoff_hz=10.0), x=x, rate_hz=100.0)["y"].data
    >>> np.round(y, 4).tolist()                           # 1 − e^(−2π·10·0.01·k)
    [0.0, 0.4665, 0.7154, 0.8482]
    """

    config_cls = LowpassConfig
    inputs = {
        "x": ft.Port(
            dtype="float64",
            require_rate=True,
            doc="signal, any shape and units (e.g. the three FSR forces in N)",
        )
    }
    outputs = {
        "y": ft.Port(dtype="float64", doc="low-passed signal: the same shape, units, rate and labels as x")
    }
    counter_docs = {
        "nonincreasing_t": "samples stamped at or before the previous one: they did not move the filter "
        "(the output repeats); timestamps went wrong upstream",
        **ft.nonfinite_counter_docs("samples on 'x'"),
    }

    def specs(self, inputs: Mapping[str, ft.StreamSpec]) -> dict[str, ft.StreamSpec]:
        x = inputs["x"]
        if self.config.cutoff_hz >= 0.5 * x.rate_hz:
            raise ft.SpecError(
                "x",
                f"cutoff_hz {self.config.cutoff_hz:g} must be below half the stream's rate "
                f"({x.rate_hz:g} Hz)",
            )
        return {"y": x}

    def reset(self) -> None:
        cfg = self.config
        spec = self.input_specs["x"]
        self._shape = spec.shape
        self._nc = spec.size
        self._w = 2.0 * math.pi * cfg.cutoff_hz
        self._alpha = -math.expm1(-self._w / float(spec.rate_hz or 1.0))
        self._state = np.zeros(self._nc)
        self._prev_t = 0.0
        self._started = False
        self._last: np.ndarray | None = None

    def step(self, x: ft.Chunk) -> dict[str, ft.Chunk]:
        cfg = self.config
        x, self._last = ft.screen_nonfinite(self, x, cfg.on_bad_data, "x", self._last)
        n = len(x)
        if n == 0:
            return {"y": ft.Chunk.empty(shape=self._shape, end=x.end)}
        y, self._prev_t, self._started, bad = lowpass_apply(
            np.ascontiguousarray(x.t, np.float64),
            np.ascontiguousarray(x.data.reshape(n, self._nc), np.float64),
            self._state,
            self._prev_t,
            self._started,
            self._w,
            self._alpha,
            cfg.time_base == "timestamps",
            cfg.initial == "first",
        )
        self.count("nonincreasing_t", bad)
        return {"y": ft.Chunk(x.t, y.reshape(n, *self._shape), x.end)}

    @classmethod
    def example(cls) -> ft.Example:
        rng = np.random.default_rng(11)
        n = 200
        t = np.arange(n) / 100.0
        f = np.outer((t > 0.5) * 1.5, [1.0, 0.8, 1.2]) + rng.normal(0, 0.1, (n, 3))
        return ft.Example(params={"cutoff_hz": 5.0}, inputs={"x": f}, rate_hz=100.0, units={"x": "N"})
