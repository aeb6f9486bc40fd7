"""``braille_cell_windows``: the decoder's character windows from the finger's position and the known
cell pitch — what a robot knows — never from the simulator's ground truth (``braille_scan.char``)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

import flowtact.api as ft

from .cells import PAPER_SCALE, Geometry

__all__ = ["NO_CELL", "BrailleCellWindows", "BrailleCellWindowsConfig", "cell_window_values"]

#: Window value between cells (a gap for ``naive_bayes``: values < 0 are no window).
NO_CELL = -1.0


def cell_window_values(x: np.ndarray, geometry: Geometry, origin_mm: float = 0.0) -> np.ndarray:
    """For finger positions ``x`` (mm): the index k ≥ 0 of the cell whose dot columns (± a dot
    radius) lie under the finger's centre, else :data:`NO_CELL`. Cell k spans
    ``origin + [k, k + 1)·pitch``. ``braille_scan`` marks its ``char`` stream by this rule too, so on a
    line whose every cell holds a letter the windows are the ``char`` stream's, to the sample."""
    x = np.asarray(x, np.float64) - origin_mm
    with np.errstate(invalid="ignore"):
        k = np.floor(x / geometry.cell_pitch)
    ok = np.isfinite(k) & (k >= 0)
    kk = np.where(ok, k, 0.0).astype(np.int64)
    lo, hi = geometry.cell_span(kk)
    on = ok & (x >= lo) & (x <= hi)
    return np.where(on, kk.astype(np.float64), NO_CELL)


@dataclass(frozen=True)
class BrailleCellWindowsConfig(ft.Config):
    """Parameters of :class:`BrailleCellWindows` (what the robot knows of the page: its layout, not its text)."""

    scale: float = ft.param(
        PAPER_SCALE, doc="scaling of the DIN 32976 Braille dimensions (Bologna et al.: 1:1.7)", gt=0
    )
    origin_mm: float = ft.param(
        0.0, doc="finger position (mm) where the line's first cell begins (braille_scan: 0)"
    )


class BrailleCellWindows(ft.Block):
    """Character windows from position: cell k while the finger's centre is over its dots, −1 between.

    Config
    ------
    ``scale`` (cell pitch 6 mm × scale = 10.2 mm; dots 2.5 mm apart, 1.5 mm wide, × scale) and
    ``origin_mm``.

    Notes
    -----
    A window is cell k's two dot columns ± a dot radius (6.8 mm of the 10.2 mm pitch at 1:1.7)
    around its centre ``origin + (k + ½)·pitch``: the window rule of ``braille_scan.char``, with
    the cell found from position alone. It knows nothing of the text: a dot-less (space) cell, or
    a cell past the line's end, is a window too (the decoder reads it as an empty window). Pure
    and per sample: chunking-invariant. A non-finite position is no window (``nonfinite_positions``).

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.braille.cell_windows import BrailleCellWindows
    >>> from flowtact.testing import run_offline
    >>> x = np.array([0.0, 1.8, 5.1, 8.6, 9.0, 12.0, 20.0])  # mm
    >>> run_offline(BrailleCellWindows(), position=x, rate_hz=250.0, units={"position": "mm"})["window"].data.tolist()
    [-1.0, 0.0, 0.0, 0.0, -1.0, 1.0, -1.0]
    """

    config_cls = BrailleCellWindowsConfig
    inputs = {
        "position": ft.Port(
            dtype="float64",
            shape=(),
            units="mm",
            require_rate=True,
            doc="the finger centre along the line (e.g. braille_scan.position)",
        )
    }
    outputs = {
        "window": ft.Port(
            dtype="float64",
            shape=(),
            units="1",
            doc="the cell index k >= 0 under the finger's centre, −1 between cells: a window stream for "
            "naive_bayes (values < 0 are gaps), at the position's rate",
        )
    }
    counter_docs = {
        "nonfinite_positions": "position samples that were NaN or inf: no window there; a fault upstream",
    }

    def specs(self, inputs: Mapping[str, ft.StreamSpec]) -> dict[str, ft.StreamSpec]:
        return {
            "window": ft.StreamSpec(dtype="float64", shape=(), units="1", rate_hz=inputs["position"].rate_hz)
        }

    def reset(self) -> None:
        self._geometry = Geometry(scale=self.config.scale)

    def step(self, position: ft.Chunk) -> dict[str, ft.Chunk]:
        x = np.asarray(position.data, np.float64)
        self.count("nonfinite_positions", int((~np.isfinite(x)).sum()))
        w = cell_window_values(x, self._geometry, self.config.origin_mm)
        return {"window": ft.Chunk(position.t, w, position.end)}

    @classmethod
    def example(cls) -> ft.Example:
        t = np.arange(500) / 250.0
        x = -8.0 + 30.0 * t  # 30 mm/s from 8 mm before the line: cells 0 and 1
        x[300] = np.nan
        return ft.Example(params={}, inputs={"position": x}, units={"position": "mm"}, rate_hz=250.0)
