"""Calibration of the AuNP strain-gauge sensor (Rager et al.): gauge signals → force and shear angle.

Gauge signals are relative resistance changes r_i = ΔR_i/R_i (dimensionless, units ``"1"``) of
gauges 1..4; gauges 1 and 3 lie on the x axis, 2 and 4 on the y axis (blocks/touch/aunp.py).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

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
    nonfinite_counter_docs,
    param,
    screen_nonfinite,
)
from flowtact.streams.align import Aligner, screen_aligned

from .aunp import SENSITIVITY_PER_N, reduced_matrix

__all__ = ["GaugeForce", "GaugeForceConfig", "ShearAngle", "ShearAngleConfig"]

_LABELS = ("Fx", "Fy", "Fz")
_NO_REF = np.empty(0)


@njit(cache=True)
def _forces(r: np.ndarray, ref: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, int]:
    """``f = a · (r − ref)`` per sample (``ref`` may hold no samples: then ``a · r``), summed over
    the gauges in a fixed order (no BLAS: chunking never changes a bit); and how many samples'
    forces overflowed to ±inf/NaN. One compiled pass: a 1 kHz step costs one call."""
    n = r.shape[0]
    f = np.empty((n, 3))
    overflow = 0
    with_ref = ref.shape[0] == n
    for j in range(n):
        d = ref[j] if with_ref else 0.0  # x − 0.0 is x, bit for bit (−0.0 included)
        r0, r1, r2, r3 = r[j, 0] - d, r[j, 1] - d, r[j, 2] - d, r[j, 3] - d
        bad = False
        for i in range(3):
            v = a[i, 0] * r0 + a[i, 1] * r1
            v += a[i, 2] * r2
            v += a[i, 3] * r3
            f[j, i] = v
            bad |= not math.isfinite(v)
        overflow += bad
    return f, overflow


# -- gauge_force ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class GaugeForceConfig(BadDataConfig):
    """Parameters of :class:`GaugeForce`."""

    mode: Literal["general", "reduced"] = param(
        "reduced", doc="general: F = A·r with 'matrix' (eq. 1); reduced: orthogonal identical gauges (eq. 2)"
    )
    matrix: tuple[tuple[float, ...], ...] | None = param(
        None,
        doc="3×4 calibration matrix A, rows Fx, Fy, Fz, in N per unit ΔR/R (mode general)",
        min_len=3,
        max_len=3,
    )
    sensitivity_per_n: tuple[float, ...] = param(
        SENSITIVITY_PER_N,
        doc="(Xs, Ys, Zs): ΔR/R per newton of eq. 2 (mode reduced)",
        min_len=3,
        max_len=3,
        gt=0,
    )
    tare_samples: int = param(0, doc="subtract the mean force of the first k samples (0 = off)", ge=0)

    def check(self) -> None:
        if self.mode == "general":
            if self.matrix is None:
                raise self.error("matrix", "is required with mode 'general' (3 rows of 4 numbers, F = A·r)")
            for i, row in enumerate(self.matrix):
                if len(row) != 4:
                    raise self.error(
                        "matrix", f"must have 4 columns (gauges 1..4); row {i + 1} has {len(row)}"
                    )
        elif self.matrix is not None:
            raise self.error(
                "matrix", "is only used with mode 'general' (mode 'reduced' uses sensitivity_per_n)"
            )

    def calibration_matrix(self) -> np.ndarray:
        """The 3×4 matrix A applied (eq. 2 written as a matrix in reduced mode)."""
        if self.mode == "general":
            assert self.matrix is not None
            return np.array(self.matrix, np.float64)
        return np.array(reduced_matrix(*self.sensitivity_per_n), np.float64)


class GaugeForce(Block):
    """Force [Fx, Fy, Fz] from the four strain gauges: eq. 1 (F = A·r) or eq. 2 of Rager et al.

    Ports
    -----
    r : float64, shape (4,), units "1" — ΔR/R of gauges 1..4
    ref : float64, shape (), units "1", optional — reference gauge, subtracted from every gauge
        (temperature compensation); must be sample-aligned with ``r``
    f : float64, shape (3,), units "N", labels (Fx, Fy, Fz)

    Config
    ------
    See :class:`GaugeForceConfig`. ``reduced`` (default): Fx = (r3 − r1)/Xs, Fy = (r2 − r4)/Ys,
    Fz = (r1 + r2 + r3 + r4)/Zs with ``sensitivity_per_n`` = (Xs, Ys, Zs), defaults from
    blocks/touch/aunp.py (the synthetic sensor's constants, so the default graph recovers its force);
    ``general``: any 3×4 ``matrix`` from a calibration fit.

    Notes
    -----
    Reduced mode is computed as ``general`` with ``aunp.reduced_matrix`` (bit-identical). The
    product is elementwise products summed over the gauges in a fixed order (no BLAS), so chunking
    never changes a bit.
    ``tare_samples: k`` (off by default) subtracts the mean force of the first k samples — for a
    sensor that starts unloaded but with a gauge offset. Those k samples are held back until the
    offset is known, then emitted tared (a one-off start-up latency of k samples; no sample is
    lost); a stream shorter than k is tared with the mean of what arrived, at flush. Beware: a
    tare taken under load (the paper's 120 mN baseline) removes real force. Finite readings whose
    force overflows float64 give ±inf/NaN, counted ``overflow`` (the consumer's ``on_bad_data`` applies). Latency otherwise 0;
    with ``ref`` connected, that of the later of ``r`` and ``ref``.

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.touch.calibration import GaugeForce
    >>> from flowtact.testing import run_offline
    >>> r = np.array([[0.0, 0.01, 0.02, 0.01]])           # r3 − r1 = 0.02, sum 0.04
    >>> run_offline(GaugeForce(), r=r)["f"].data.round(12).tolist()   # Xs = Ys = 0.02, Zs = 0.04
    [[1.0, 0.0, 1.0]]
    """

    config_cls = GaugeForceConfig
    inputs = {
        "r": Port(dtype="float64", shape=(4,), units="1", require_rate=True, doc="ΔR/R of gauges 1..4"),
        "ref": Port(
            dtype="float64",
            shape=(),
            units="1",
            optional=True,
            require_rate=True,
            doc="reference gauge ΔR/R (temperature)",
        ),
    }
    outputs = {"f": Port(dtype="float64", shape=(3,), units="N", doc="force [Fx, Fy, Fz] in N")}
    counter_docs = {
        "nonfinite_drop": "instants where 'r' or 'ref' had NaN/inf, removed (on_bad_data: drop): "
        "upstream sent bad data",
        "nonfinite_hold": "gauge samples (per input, 'r' and 'ref') with NaN/inf, held at the last finite "
        "value (on_bad_data: hold): upstream sent bad data",
        "unpaired_at_end": "samples of 'r' or 'ref' with no partner on the other input when the stream "
        "ended: not used (the inputs delivered different numbers of samples)",
        "overflow": "samples whose force from finite readings overflowed float64: emitted as ±inf/NaN, so "
        "the consumer's on_bad_data applies; readings far outside any physical range",
        "tare_short": "the stream ended before tare_samples samples arrived: the tare offset is the mean "
        "of fewer samples",
    }

    def specs(self, inputs: Mapping[str, StreamSpec]) -> dict[str, StreamSpec]:
        r = inputs["r"]
        if "ref" in inputs and not math.isclose(inputs["ref"].rate_hz or 0.0, r.rate_hz or 0.0, rel_tol=1e-9):
            raise SpecError("ref", f"'ref' is {inputs['ref'].rate_hz:g} Hz but 'r' is {r.rate_hz:g} Hz")
        return {"f": StreamSpec(dtype="float64", shape=(3,), units="N", rate_hz=r.rate_hz, labels=_LABELS)}

    def reset(self) -> None:
        self._a = self.config.calibration_matrix()
        self._ports = ["r", "ref"] if "ref" in self.input_specs else ["r"]
        rate = self.input_specs["r"].rate_hz or 1.0
        self._align = Aligner(self.node, self.input_specs, self._ports, tol_s=1e-6 / rate)
        self._last: dict[str, np.ndarray | None] = {p: None for p in self._ports}
        self._offset: np.ndarray | None = None if self.config.tare_samples else np.zeros(3)
        self._acc = np.zeros(3)
        self._seen = 0
        self._held: list[tuple[np.ndarray, np.ndarray]] = []

    def step(self, **inputs: Chunk) -> dict[str, Chunk]:
        t, data = self._align.push(inputs)
        if len(t):
            t, data = screen_aligned(self, self.config.on_bad_data, t, data, self._last)
        f, overflow = _forces(data["r"], data.get("ref", _NO_REF), self._a)
        self.count("overflow", overflow)
        if not self.config.tare_samples:
            return {"f": Chunk(t, f)}  # no offset: f − 0 is f, bit for bit
        if self._offset is None:
            return {"f": self._tare(t, f)}
        return {"f": Chunk(t, f - self._offset)}

    def _tare(self, t: np.ndarray, f: np.ndarray) -> Chunk:
        k = self.config.tare_samples
        take = min(k - self._seen, len(t))
        for i in range(take):  # sequential sum: the same additions whatever the chunking
            self._acc = self._acc + f[i]
        self._seen += take
        if len(t):
            self._held.append((t, f))
        if self._seen < k:
            return Chunk.empty(shape=(3,))
        return self._release()

    def _release(self) -> Chunk:
        self._offset = self._acc / self._seen
        t = np.concatenate([h[0] for h in self._held])
        f = np.concatenate([h[1] for h in self._held])
        self._held = []
        return Chunk(t, f - self._offset)

    def flush(self) -> dict[str, Chunk]:
        self.count("unpaired_at_end", sum(self._align.pending().values()))
        if self._offset is None and self._seen:
            self.count("tare_short", 1)
            return {"f": self._release()}
        return {}

    @classmethod
    def example(cls) -> Example:
        rng = np.random.default_rng(4)
        n = 400
        t = np.arange(n) / 1000.0
        force = np.stack(
            [0.2 * np.sin(2 * np.pi * 3 * t), 0.1 * np.cos(2 * np.pi * 2 * t), 0.12 + 0.3 * t], 1
        )
        xs, ys, zs = SENSITIVITY_PER_N
        drift = 1e-3 * t  # temperature: every gauge and the reference drift together
        r = (
            np.stack(
                [
                    force[:, 2] * zs / 4 - force[:, 0] * xs / 2,
                    force[:, 2] * zs / 4 + force[:, 1] * ys / 2,
                    force[:, 2] * zs / 4 + force[:, 0] * xs / 2,
                    force[:, 2] * zs / 4 - force[:, 1] * ys / 2,
                ],
                1,
            )
            + drift[:, None]
            + rng.normal(0, 1e-5, (n, 4))
        )
        return Example(params={"tare_samples": 30}, inputs={"r": r, "ref": drift + 0.001})


# -- shear_angle ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class ShearAngleConfig(BadDataConfig):
    """Parameters of :class:`ShearAngle`."""


class ShearAngle(Block):
    """Direction of the shear force from the gauges: Θ = atan2(r2 − r4, r3 − r1) (eq. 3, Rager et al.).

    Ports
    -----
    r : float64, shape (4,), units "1" — ΔR/R of gauges 1..4
    theta : float64, shape (), units "rad", in (−π, π]; 0 along +x (gauge 3), π/2 along +y (gauge 2)

    Config
    ------
    See :class:`ShearAngleConfig` (only the bad-data policy).

    Notes
    -----
    Stateless, latency 0. Eq. 3 assumes identical x and y gauge sensitivities (Xs = Ys); it
    ignores any common-mode term (temperature, normal force), so no reference gauge is needed.
    With no shear (r2 = r4, r3 = r1) the angle is atan2(0, 0) = 0 and, in practice, the angle of
    the noise: gate it on the shear magnitude downstream if that matters.

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.touch.calibration import ShearAngle
    >>> from flowtact.testing import run_offline
    >>> r = np.array([[0.0, 0.01, 0.0, 0.0]])             # r2 > r4: shear along +y
    >>> float(run_offline(ShearAngle(), r=r)["theta"].data[0])   # π/2
    1.5707963267948966
    """

    config_cls = ShearAngleConfig
    inputs = {"r": Port(dtype="float64", shape=(4,), units="1", require_rate=True, doc="ΔR/R of gauges 1..4")}
    outputs = {"theta": Port(dtype="float64", shape=(), units="rad", doc="shear angle in radians")}
    counter_docs = nonfinite_counter_docs("gauge samples")

    def specs(self, inputs: Mapping[str, StreamSpec]) -> dict[str, StreamSpec]:
        return {"theta": StreamSpec(dtype="float64", shape=(), units="rad", rate_hz=inputs["r"].rate_hz)}

    def reset(self) -> None:
        self._last: np.ndarray | None = None

    def step(self, r: Chunk) -> dict[str, Chunk]:
        if len(r) == 0:
            return {"theta": Chunk.empty()}
        r, self._last = screen_nonfinite(self, r, self.config.on_bad_data, "r", self._last)
        d = r.data
        return {"theta": Chunk(r.t, np.arctan2(d[:, 1] - d[:, 3], d[:, 2] - d[:, 0]))}

    @classmethod
    def example(cls) -> Example:
        rng = np.random.default_rng(5)
        n = 300
        phi = np.linspace(-3.0, 3.0, n)
        r = 0.01 + rng.normal(0, 1e-4, (n, 4))
        r[:, 2] += 0.005 * np.cos(phi)
        r[:, 1] += 0.005 * np.sin(phi)
        return Example(inputs={"r": r})
