"""``speed_controller``: the high-level policy of the Braille loop — scan slowly while the decoder is
unsure, fast when it is sure — and an optional low-level lateral (±Y) corrector."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

import numpy as np

from flowtact.block import Block, Example, Port
from flowtact.chunk import Chunk, StreamSpec
from flowtact.errors import SpecError
from flowtact.params import Config, param

__all__ = ["SpeedController", "SpeedControllerConfig", "confidence"]


def confidence(p: np.ndarray, measure: str) -> np.ndarray:
    """Confidence in [0, 1] of posterior rows ``p`` (n, C): the largest probability, or 1 − the
    entropy over its maximum log C. Rows are normalised first; NaN where a row is not a
    distribution (a non-finite or negative value, or a zero sum)."""
    p = np.asarray(p, np.float64)
    s = p.sum(axis=1, keepdims=True)
    bad = ~(np.isfinite(p).all(axis=1) & (p >= 0).all(axis=1) & (s[:, 0] > 0))
    q = np.where(bad[:, None], 1.0, p) / np.where(bad[:, None] | (s <= 0), p.shape[1], s)
    if measure == "max":
        c = q.max(axis=1)
    else:
        with np.errstate(divide="ignore", invalid="ignore"):
            h = -np.where(q > 0, q * np.log(q), 0.0).sum(axis=1)
        c = 1.0 - h / math.log(p.shape[1]) if p.shape[1] > 1 else np.ones(len(q))
    return np.where(bad, np.nan, c)


@dataclass(frozen=True)
class SpeedControllerConfig(Config):
    """Parameters of :class:`SpeedController` (speeds in mm/s, accelerations in mm/s², offsets in mm)."""

    min_speed_mm_s: float = param(10.0, doc="slowest commanded speed, mm/s (also the fail-safe speed)", gt=0)
    max_speed_mm_s: float = param(80.0, doc="fastest commanded speed, mm/s", gt=0)
    start_speed_mm_s: float | None = param(
        None, doc="speed before the first posterior, mm/s (None: min)", gt=0
    )
    measure: Literal["max", "entropy"] = param(
        "max", doc="confidence of a posterior: its largest probability, or 1 − normalised entropy"
    )
    unsure: float = param(0.5, doc="confidence at or below which the speed target is the minimum", ge=0, lt=1)
    sure: float = param(0.95, doc="confidence at or above which the speed target is the maximum", gt=0, le=1)
    max_accel_mm_s2: float = param(2000.0, doc="rate limit: largest speed change per second, mm/s²", gt=0)
    lateral_gain_hz: float = param(
        5.0, doc="lateral corrector: integral gain, correction in mm per s per mm of error", ge=0
    )
    max_lateral_mm: float = param(2.0, doc="lateral corrector: largest correction either way, mm", gt=0)

    def check(self) -> None:
        if self.max_speed_mm_s < self.min_speed_mm_s:
            raise self.error(
                "max_speed_mm_s",
                f"must be >= min_speed_mm_s ({self.min_speed_mm_s}); got {self.max_speed_mm_s}",
            )
        if self.sure <= self.unsure:
            raise self.error("sure", f"must be > unsure ({self.unsure}); got {self.sure}")
        s = self.start_speed_mm_s
        if s is not None and not self.min_speed_mm_s <= s <= self.max_speed_mm_s:
            raise self.error(
                "start_speed_mm_s",
                f"must lie in [min, max] = [{self.min_speed_mm_s}, {self.max_speed_mm_s}]; got {s}",
            )


class SpeedController(Block):
    """Scanning speed from the decoder's confidence (slow when unsure), bounded and rate-limited.

    Ports
    -----
    posterior : float64 (n_classes,), with a rate
        A posterior per sample, e.g. ``naive_bayes.running``.
    lateral_error : float64 (), mm, with a rate (optional)
        An estimate of the finger's lateral (±Y) offset from the line; connect it to get ``lateral``.
    speed : float64 (), mm/s, one per posterior sample
        The commanded scanning speed, always within [min_speed_mm_s, max_speed_mm_s].
    lateral : float64 (), mm, one per lateral_error sample
        The lateral correction, within ±max_lateral_mm.

    Config
    ------
    Speed bounds, the confidence measure and its ``unsure``/``sure`` corners, the rate limit, and
    the lateral corrector's gain and bound; see the field docs.

    Notes
    -----
    Confidence ``c`` (:func:`confidence`) maps linearly onto a target: the minimum speed at
    ``c <= unsure``, the maximum at ``c >= sure`` (targets held at a bound are counted as
    ``clamped``). The command follows the target at most ``max_accel_mm_s2`` per second
    (``rate_limited``), starting from ``start_speed_mm_s``. A posterior that is no distribution
    (NaN, inf, negative, all zero) commands the minimum speed at once, not rate-limited
    (``fail_safe``): unsure input must never speed the finger up. The lateral corrector is an
    integrator, ``y[n] = clip(y[n-1] − gain·dt·e[n], ±max_lateral_mm)`` (``lateral_clamped``);
    a non-finite error holds the correction (``lateral_fail_safe``).

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.braille.speed_controller import SpeedController
    >>> from flowtact.testing import run_offline
    >>> sure, unsure = np.array([[0.98, 0.01, 0.01]] * 50), np.array([[0.4, 0.3, 0.3]] * 50)
    >>> out = run_offline(SpeedController(max_accel_mm_s2=1e4), posterior=np.vstack([sure, unsure]), rate_hz=250.0)
    >>> out["speed"].data[[0, 49, 99]].tolist()  # from 10 mm/s up to 80, then back down
    [50.0, 80.0, 10.0]
    """

    config_cls = SpeedControllerConfig
    inputs = {
        "posterior": Port(dtype="float64", ndim=(1,), require_rate=True, doc="posterior over the classes"),
        "lateral_error": Port(
            dtype="float64",
            shape=(),
            units="mm",
            optional=True,
            require_rate=True,
            doc="lateral offset estimate, mm",
        ),
    }
    outputs = {
        "speed": Port(dtype="float64", shape=(), units="mm/s", doc="commanded scanning speed"),
        "lateral": Port(dtype="float64", shape=(), units="mm", doc="lateral correction"),
    }
    counter_docs = {
        "clamped": "speed targets cut to the minimum or maximum (confidence below unsure or above sure): normal",
        "rate_limited": "samples where the speed change was cut to max_accel_mm_s2: normal on jumps",
        "fail_safe": "posteriors that were no distribution (NaN/inf/negative/zero): minimum speed commanded; "
        "a fault upstream",
        "lateral_clamped": "lateral corrections held at ±max_lateral_mm: the error is larger than it can correct",
        "lateral_fail_safe": "non-finite lateral errors: the correction was held; a fault upstream",
    }

    def specs(self, inputs: Mapping[str, StreamSpec]) -> dict[str, StreamSpec]:
        p = inputs["posterior"]
        if p.shape[0] < 1:
            raise SpecError("posterior", f"{self.node}: input 'posterior' needs at least one class")
        out = {"speed": StreamSpec(dtype="float64", shape=(), units="mm/s", rate_hz=p.rate_hz)}
        if "lateral_error" in inputs:
            out["lateral"] = StreamSpec(
                dtype="float64", shape=(), units="mm", rate_hz=inputs["lateral_error"].rate_hz
            )
        return out

    def reset(self) -> None:
        c = self.config
        self._v = c.start_speed_mm_s if c.start_speed_mm_s is not None else c.min_speed_mm_s
        self._t: float | None = None
        self._y = 0.0
        self._t_lat: float | None = None

    def step(self, posterior: Chunk, lateral_error: Chunk | None = None) -> dict[str, Chunk]:
        out = {"speed": Chunk(posterior.t, self._speeds(posterior), posterior.end)}
        if lateral_error is not None:
            out["lateral"] = Chunk(lateral_error.t, self._lateral(lateral_error), lateral_error.end)
        return out

    def _speeds(self, posterior: Chunk) -> np.ndarray:
        c = self.config
        conf = confidence(posterior.data, c.measure)
        frac = (conf - c.unsure) / (c.sure - c.unsure)
        self.count("clamped", int(np.sum((frac < 0) | (frac > 1))))
        target = c.min_speed_mm_s + (c.max_speed_mm_s - c.min_speed_mm_s) * np.clip(frac, 0.0, 1.0)
        v = np.empty(len(conf))
        for i, (t, want) in enumerate(zip(posterior.t.tolist(), target.tolist(), strict=True)):
            if math.isnan(want):
                self.count("fail_safe")
                self._v = c.min_speed_mm_s
            else:
                dt = 1.0 / self.input_specs["posterior"].rate_hz if self._t is None else t - self._t  # type: ignore[operator]
                step = c.max_accel_mm_s2 * max(dt, 0.0)
                if abs(want - self._v) > step:
                    self.count("rate_limited")
                    want = self._v + math.copysign(step, want - self._v)
                self._v = min(max(want, c.min_speed_mm_s), c.max_speed_mm_s)
            self._t = t
            v[i] = self._v
        return v

    def _lateral(self, err: Chunk) -> np.ndarray:
        c = self.config
        y = np.empty(len(err))
        for i, (t, e) in enumerate(zip(err.t.tolist(), np.asarray(err.data).tolist(), strict=True)):
            dt = 1.0 / self.input_specs["lateral_error"].rate_hz if self._t_lat is None else t - self._t_lat  # type: ignore[operator]
            self._t_lat = t
            if not math.isfinite(e):
                self.count("lateral_fail_safe")
            else:
                y_new = self._y - c.lateral_gain_hz * max(dt, 0.0) * e
                if abs(y_new) > c.max_lateral_mm:
                    self.count("lateral_clamped")
                self._y = min(max(y_new, -c.max_lateral_mm), c.max_lateral_mm)
            y[i] = self._y
        return y

    @classmethod
    def example(cls) -> Example:
        rng = np.random.default_rng(2)
        logits = rng.normal(0.0, 1.0, (500, 5)) * np.linspace(0.2, 4.0, 500)[:, None]
        p = np.exp(logits) / np.exp(logits).sum(axis=1, keepdims=True)
        p[100] = np.nan  # a broken posterior: the fail-safe
        lat = 1.5 * np.sin(np.linspace(0, 6, 500))
        lat[200] = np.inf
        return Example(
            params={"max_accel_mm_s2": 500.0},
            inputs={"posterior": p, "lateral_error": lat},
            rate_hz=250.0,
            units={"lateral_error": "mm"},
        )
