"""``linear_force``: contact force from SSIM by a per-sensor line (White 2023, §4.1.2, Table 4.2).

F = intercept + slope·SSIM per sensor; ``flowtact fit-force`` (:mod:`.fit_force`) fits the lines
on a recording. numpy only.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

import flowtact.api as ft

__all__ = ["LinearForce", "LinearForceConfig"]

#: Default lines (N per unit SSIM, N): F = 0 at SSIM 0.85 (an undeformed TacTip against its own
#: start-up reference is ≈ 0.85–1) rising to ≈ 3 N at SSIM 0.70, the spans of Table 3.2. The
#: thesis does not print its fitted coefficients (Fig. 4.2 only plots them); fit your own with
#: ``flowtact fit-force`` (:mod:`flowtact.blocks.teleop.fit_force`).
DEFAULT_SLOPE_N = (-20.0, -20.0, -20.0)
DEFAULT_INTERCEPT_N = (17.0, 17.0, 17.0)


# -- linear_force ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class LinearForceConfig(ft.BadDataConfig):
    """Parameters of :class:`LinearForce`."""

    slope_n: tuple[float, ...] = ft.param(
        DEFAULT_SLOPE_N, doc="slope per sensor in N per unit SSIM (one per sensor, or one for all)", min_len=1
    )
    intercept_n: tuple[float, ...] = ft.param(
        DEFAULT_INTERCEPT_N, doc="force at SSIM 0 per sensor in N (one per sensor, or one for all)", min_len=1
    )
    clip_negative: bool = ft.param(True, doc="clip negative forces to 0 (a contact force cannot pull)")

    def check(self) -> None:
        if len(self.slope_n) != len(self.intercept_n) and 1 not in (len(self.slope_n), len(self.intercept_n)):
            raise self.error(
                "intercept_n",
                f"must have as many values as slope_n ({len(self.slope_n)}), or one; got {len(self.intercept_n)}",
            )


class LinearForce(ft.Block):
    """Contact force from SSIM per sensor: F = intercept + slope·SSIM (White 2023, Table 4.2's model).

    Config
    ------
    See :class:`LinearForceConfig`. The defaults are a placeholder line (F = 17 − 20·SSIM N,
    0 N at SSIM 0.85, 3 N at 0.70): the thesis does not print its coefficients, so fit them
    on your sensor or on ``tactip_sim`` data with ``flowtact fit-force REC.h5``
    (``flowtact fit-force``) and paste the result into the graph.

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
    >>> from flowtact.blocks.teleop.force_linear import LinearForce
    >>> from flowtact.testing import run_offline
    >>> ssim = np.array([[0.85, 0.70, 0.90]])
    >>> run_offline(LinearForce(), x=ssim, rate_hz=40.0)["y"].data.round(9).tolist()
    [[0.0, 3.0, 0.0]]
    """

    name = "linear_force"
    config_cls = LinearForceConfig
    inputs = {
        "x": ft.Port(
            dtype="float64",
            units="1",
            ndim=(0, 1),
            require_rate=True,
            doc="SSIM per sensor (ssim.y), shape (n,) or ()",
        )
    }
    outputs = {
        "y": ft.Port(dtype="float64", units="N", doc="estimated contact force F_T per sensor, the shape of x")
    }
    counter_docs = ft.nonfinite_counter_docs("SSIM samples on 'x'")

    def specs(self, inputs: Mapping[str, ft.StreamSpec]) -> dict[str, ft.StreamSpec]:
        x = inputs["x"]
        n = x.shape[0] if x.shape else 1
        for field in ("slope_n", "intercept_n"):
            k = len(getattr(self.config, field))
            if k not in (1, n):
                raise ft.SpecError("x", f"'{field}' has {k} values but the SSIM stream has {n} sensors")
        return {"y": x.with_(units="N")}

    def reset(self) -> None:
        x = self.input_specs["x"]
        n = x.shape[0] if x.shape else 1
        slope = np.broadcast_to(np.array(self.config.slope_n, np.float64), (n,)).copy()
        intercept = np.broadcast_to(np.array(self.config.intercept_n, np.float64), (n,)).copy()
        self._slope = slope.reshape(x.shape)
        self._intercept = intercept.reshape(x.shape)
        self._last: np.ndarray | None = None

    def step(self, x: ft.Chunk) -> dict[str, ft.Chunk]:
        if len(x):
            x, self._last = ft.screen_nonfinite(self, x, self.config.on_bad_data, "x", self._last)
        f = self._intercept + self._slope * x.data
        if self.config.clip_negative:
            f = np.maximum(f, 0.0)
        return {"y": ft.Chunk(x.t, f, x.end)}

    @classmethod
    def example(cls) -> ft.Example:
        t = np.arange(40) / 40.0
        ssim = np.stack([0.9 - 0.2 * t, 0.88 - 0.15 * t**2, 0.8 + 0.05 * np.sin(6 * t)], 1)
        return ft.Example(
            params={"slope_n": [-20.0, -25.0, -14.0], "intercept_n": [17.5, 21.0, 12.0]},
            inputs={"x": ssim},
            rate_hz=40.0,
            duration_s=1.0,
        )
