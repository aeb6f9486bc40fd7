"""A synthetic ramp-and-hold at the receptors: the static (s) and dynamic (d) terms TouchSim's
afferent models take, for graphs that run without a replayed file."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

import flowtact.api as ft
from flowtact.blocks.signal.shapes import raised_cosine

__all__ = ["TouchsimProbe", "TouchsimProbeConfig"]


@dataclass(frozen=True)
class TouchsimProbeConfig(ft.Config):
    """Parameters of :class:`TouchsimProbe`."""

    n: int = ft.param(1, doc="afferents (columns of s and d), each under the same stimulus", ge=1)
    rate_hz: float = ft.param(5000.0, doc="sampling rate (TouchSim's models are fitted at 5 kHz)", gt=0)
    s_peak: tuple[float, ...] = ft.param(
        (0.0128,), doc="s on the plateau, per afferent (one value: all)", min_len=1
    )
    d_peak: tuple[float, ...] = ft.param(
        (4.0,), doc="largest |d| during the ramps, per afferent (one value: all)", min_len=1
    )
    onset_s: float = ft.param(0.05, doc="time the ramp on starts, s", ge=0)
    ramp_s: float = ft.param(0.05, doc="duration of each ramp (on and off), s", gt=0)
    hold_s: float = ft.param(0.6, doc="plateau between the ramps, s", ge=0)
    tail_s: float = ft.param(0.1, doc="rest after the ramp off before the stream ends (or repeats), s", ge=0)
    repeat: bool = ft.param(False, doc="play the ramp-and-hold again and again (a stream that never ends)")

    def length_s(self) -> float:
        return self.onset_s + 2 * self.ramp_s + self.hold_s + self.tail_s


class TouchsimProbe(ft.Source):
    """Ramp-and-hold s and d at n receptors: a stand-in for TouchSim's skin mechanics.

    Config
    ------
    See :class:`TouchsimProbeConfig`.

    Notes
    -----
    Not TouchSim's skin mechanics (a pin's indentation through its elastic half-space): a smooth
    (raised-cosine) ramp on, hold, ramp off. s follows the indentation, s_peak·r(t); d is its
    rate of change, scaled so that |d| peaks at d_peak: d = d_peak·r'(t)/max|r'| (positive on,
    negative off). The defaults are the magnitudes of the development set's 0.3 mm ramp at an
    SA1 receptor. Replay real s and d with ``--replay probe=FILE.npz`` (arrays t, s, d; see
    docs/touchsim.md). Sample i at t = i/rate_hz; the stream ends after ``length_s``, or with
    ``repeat`` starts again every ``length_s`` (times continuing) and never ends.

    Example
    -------
    >>> from flowtact.blocks.touch.touchsim_probe import TouchsimProbe
    >>> from flowtact.testing import run_source
    >>> out = run_source(TouchsimProbe(n=2), 1.0, tick_s=0.1)
    >>> out["s"].data.shape, round(float(out["d"].data.max()), 3)
    ((4250, 2), 4.0)
    """

    config_cls = TouchsimProbeConfig
    shardable = True
    per_unit_params = ("s_peak", "d_peak")

    @classmethod
    def shard_units(cls, config: TouchsimProbeConfig) -> int:
        return config.n

    outputs = {
        "s": ft.Port(dtype="float64", ndim=1, units="1", doc="static term per receptor"),
        "d": ft.Port(dtype="float64", ndim=1, units="1", doc="dynamic term per receptor"),
    }

    def specs(self, inputs: Mapping[str, ft.StreamSpec]) -> dict[str, ft.StreamSpec]:  # noqa: ARG002 - a source: none
        cfg = self.config
        for name in ("s_peak", "d_peak"):
            if len(getattr(cfg, name)) not in (1, cfg.n):
                raise ft.SpecError(
                    name,
                    f"{name} has {len(getattr(cfg, name))} values for n = {cfg.n} afferents (give 1 or {cfg.n})",
                )
        spec = ft.StreamSpec(dtype="float64", shape=(cfg.n,), units="1", rate_hz=cfg.rate_hz)
        return {"s": spec, "d": spec}

    def ends_at(self, inputs: Mapping[str, ft.StreamSpec]) -> float | None:  # noqa: ARG002 - no inputs
        return None if self.config.repeat else self.config.length_s()

    def reset(self) -> None:
        cfg = self.config
        self._i = 0
        self._period = cfg.length_s()
        self._total = round(self._period * cfg.rate_hz) if not cfg.repeat else np.iinfo(np.int64).max
        self._s = np.broadcast_to(np.asarray(cfg.s_peak, np.float64), (cfg.n,))
        self._d = np.broadcast_to(np.asarray(cfg.d_peak, np.float64), (cfg.n,))

    def _shape(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """r(t) and r'(t)/max|r'| of the ramp-and-hold."""
        cfg = self.config
        on = (t - cfg.onset_s) / cfg.ramp_s
        off = (t - cfg.onset_s - cfg.ramp_s - cfg.hold_s) / cfg.ramp_s
        r = raised_cosine(on) - raised_cosine(off)
        dr = np.where((on > 0) & (on < 1), np.sin(np.pi * on), 0.0) - np.where(
            (off > 0) & (off < 1), np.sin(np.pi * off), 0.0
        )
        return r, dr

    def step(self, now: float) -> dict[str, ft.Chunk]:
        cfg = self.config
        end = min(self.due(now, cfg.rate_hz), self._total)
        i = np.arange(self._i, max(end, self._i))
        self._i = max(end, self._i)
        t = i / cfg.rate_hz
        r, dr = self._shape(np.mod(t, self._period) if cfg.repeat else t)
        return {"s": ft.Chunk(t, r[:, None] * self._s), "d": ft.Chunk(t, dr[:, None] * self._d)}

    @classmethod
    def example(cls) -> ft.Example:
        return ft.Example(params={"n": 3, "s_peak": [0.0128, 0.0029, 0.0019], "d_peak": [4.0, 0.14, 0.09]})
