"""``braille_scan``: a fingertip of 24 capacitive taxels sliding along a line of Braille (Bologna et al. 2013)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numba import njit

import flowtact.api as ft

from .cell_windows import cell_window_values
from .cells import CATEGORIES, LETTERS, Geometry, dot_positions, text_cells
from .fingertip import COLS, ROWS, Fingertip
from .variation import CONDITION_LABELS, ROBOT, Drift, Trials, dot_scales

__all__ = ["TAXEL_LABELS", "BrailleScan", "BrailleScanConfig"]

#: Taxel ``j = row·4 + col`` is labelled ``r{row}c{col}`` (row 0 top, +Y; column 0 trailing, −X).
TAXEL_LABELS = tuple(f"r{r}c{c}" for r in range(ROWS) for c in range(COLS))


@dataclass(frozen=True)
class BrailleScanConfig(ft.BadDataConfig):
    """Parameters of :class:`BrailleScan` (lengths in mm, speeds in mm/s)."""

    text: str = ft.param("", doc="the line to read: letters a-z and spaces ('' with random_letters > 0)")
    random_letters: int = ft.param(
        0, doc="if > 0, read this many random letters a-z drawn from the node's seed instead of text", ge=0
    )
    rate_hz: float = ft.param(250.0, doc="sampling rate of the taxels (Bologna et al.: 4 ms clock)", gt=0)
    speed_mm_s: float = ft.param(30.0, doc="scanning speed when the speed input is not connected", gt=0)
    min_speed_mm_s: float = ft.param(5.0, doc="slowest speed the finger is driven at (safe range)", gt=0)
    max_speed_mm_s: float = ft.param(100.0, doc="fastest speed the finger is driven at (safe range)", gt=0)
    y_offset_mm: float = ft.param(0.0, doc="lateral (±Y) error of the finger centre from the middle dot row")
    max_lateral_mm: float = ft.param(5.0, doc="lateral corrections are clamped to ±this", ge=0)
    lead_mm: float = ft.param(8.0, doc="blank paper before the first cell and after the last", ge=0)
    noise: float = ft.param(0.01, doc="sd of the white sensor noise on each reading (ΔC/C0)", ge=0)
    scale: float = ft.param(1.7, doc="scaling of the Braille dimensions (Bologna et al.: 1:1.7)", gt=0)
    taxel_mm: float = ft.param(1.6, doc="side of a square taxel electrode", gt=0)
    pitch_mm: float = ft.param(2.0, doc="taxel centre-to-centre distance, both directions", gt=0)
    cover_mm: float = ft.param(1.0, doc="thickness of the neoprene cover", gt=0)
    spread: float = ft.param(0.6, doc="sd of the cover's spatial spread per mm of cover thickness", gt=0)
    press_mm: float = ft.param(0.1, doc="uniform compression of the cover pressed on the paper", ge=0)
    transmission: float = ft.param(
        0.3, doc="fraction of the cover compression closing the taxel gap", gt=0, le=1
    )
    gap_mm: float = ft.param(0.5, doc="dielectric gap of a taxel at rest", gt=0)
    # -- the fingertip's variation (docs/braille.md, "A fingertip that varies"); 0: none --------------
    trial_cells: int = ft.param(
        0,
        doc="cells per trial: each trial draws its own press, lateral offset, yaw and gain (0: one trial)",
        ge=0,
    )
    press_sd_mm: float = ft.param(0.0, doc="sd of the per-trial offset of press_mm", ge=0)
    press_drift_mm: float = ft.param(0.0, doc="sd of the slow drift of press_mm within a trial", ge=0)
    drift_tau_s: float = ft.param(2.0, doc="correlation time of the slow press and gain drifts", gt=0)
    dot_height_min: float = ft.param(1.0, doc="lowest dot height, as a factor of the nominal one", gt=0)
    dot_height_max: float = ft.param(1.0, doc="highest dot height (each dot uniform in [min, max])", gt=0)
    lateral_sd_mm: float = ft.param(0.0, doc="sd of the per-trial lateral (±Y) offset of the line", ge=0)
    yaw_sd_deg: float = ft.param(
        0.0,
        doc="sd of the per-trial yaw of the line (degrees, about the trial's first cell boundary)",
        ge=0,
        le=10,
    )
    speed_jitter: float = ft.param(
        0.0, doc="sd of the actual speed around the command, as a fraction of it", ge=0, le=0.2
    )
    speed_jitter_tau_s: float = ft.param(0.1, doc="correlation time of the speed jitter", gt=0)
    gain_sd: float = ft.param(0.0, doc="sd of the per-trial log sensor gain", ge=0, le=1)
    gain_drift: float = ft.param(0.0, doc="sd of the slow drift of the log sensor gain", ge=0, le=1)
    cover_tau_s: float = ft.param(
        0.0,
        doc="the cover's relaxation time: the compression reaches the taxels low-passed by it (0: at once)",
        ge=0,
    )
    wear_per_m: float = ft.param(
        0.0, doc="cover wear: growth of its spread per metre slid, as a fraction of spread·cover_mm", ge=0
    )

    def check(self) -> None:
        if self.text and self.random_letters:
            raise self.error("text", "must be '' when random_letters > 0 (give one or the other)")
        if not self.text and not self.random_letters:
            raise self.error("text", "must name the letters to read (or set random_letters > 0)")
        bad = sorted({ch for ch in self.text if ch != " " and ch not in LETTERS})
        if bad:
            raise self.error("text", f"must hold only letters a-z and spaces; got {''.join(bad)!r}")
        if self.max_speed_mm_s < self.min_speed_mm_s:
            raise self.error("max_speed_mm_s", f"must be >= min_speed_mm_s ({self.min_speed_mm_s:g})")
        if self.dot_height_max < self.dot_height_min:
            raise self.error("dot_height_max", f"must be >= dot_height_min ({self.dot_height_min:g})")
        top = self.transmission * (self.press_top() + 0.5 * self.scale * self.dot_height_max)
        if top >= self.gap_mm:
            raise self.error(
                "gap_mm",
                f"must exceed transmission·(highest press + highest dot) = {top:g} mm (the gap would close)",
            )

    def press_top(self) -> float:
        """The highest press (mm) a sample may have: nominal + 4 sd of trial offset and drift (clipped there)."""
        return self.press_mm + 4.0 * (self.press_sd_mm + self.press_drift_mm)

    def slowest(self) -> float:
        """The lowest factor of the command the jittered speed reaches (clipped at 4 sd, at most −50 %)."""
        return 1.0 - min(4.0 * self.speed_jitter, 0.5)

    def fingertip(self) -> Fingertip:
        """The sensor model these parameters describe."""
        return Fingertip(
            Geometry(scale=self.scale),
            taxel_mm=self.taxel_mm,
            pitch_mm=self.pitch_mm,
            cover_mm=self.cover_mm,
            spread=self.spread,
            press_mm=self.press_mm,
            transmission=self.transmission,
            gap_mm=self.gap_mm,
        )

    def n_cells(self) -> int:
        return self.random_letters or len(self.text)

    def track(self) -> tuple[float, float]:
        """Finger centre (mm) at the first sample, and the last position it reads at."""
        pitch = self.scale * 6.0
        return -self.lead_mm, self.n_cells() * pitch + self.lead_mm


SUMMARY_TEXT_CHARS = 60
"""At most this many characters of the line in :meth:`BrailleScan.summary`."""


@njit(cache=True)
def _relax(u: np.ndarray, a: float, state: np.ndarray, started: bool) -> np.ndarray:
    """First-order low-pass of each column of ``u``: ``y_i = a·y_{i−1} + (1 − a)·u_i``, continuing
    from ``state`` (updated in place); the first sample of a run starts at rest on ``u_0``."""
    out = np.empty_like(u)
    for i in range(u.shape[0]):
        for j in range(u.shape[1]):
            if i == 0 and not started:
                state[j] = u[0, j]
            else:
                state[j] = a * state[j] + (1.0 - a) * u[i, j]
            out[i, j] = state[j]
    return out


@njit(cache=True)
def _samples_at(x0: float, x_end: float, step: float) -> int:
    """How many samples ``x_i = x_{i−1} + step`` (from x0) stay at or before x_end, summed as the block does."""
    n, x = 0, x0
    while x <= x_end:
        n += 1
        x = x + step
    return n


class BrailleScan(ft.Source):
    """A fingertip of 24 capacitive taxels (6 × 4) under a neoprene cover scanning a line of Braille.

    Config
    ------
    See the field docs (``flowtact blocks braille_scan``). The text is ``text`` or, with
    ``random_letters``, letters drawn uniformly from the node's seed.

    Notes
    -----
    *Geometry* (``cells``): DIN 32976 nominal Braille (dot pitch 2.5 mm, cell pitch 6 mm, dot
    base diameter 1.5 mm, height 0.5 mm) scaled by ``scale`` (1.7: 4.25 mm, 10.2 mm, 2.55 mm,
    0.85 mm). Dots are paraboloid domes.
    *Sensor* (``fingertip``): the paper's Fig. 1 gives the taxel dimensions only as a drawing, so
    these are choices: 1.6 mm square electrodes at 2 mm pitch (a 12 × 8 mm array, wide enough to
    span a scaled cell's 11 mm of dots across the line), 6 rows across the line (±Y) × 4 columns
    along it. Dots → indentation of the 1 mm cover (plus a uniform ``press_mm``) → Gaussian
    spread of sd ``spread·cover_mm`` (0.6 mm) → mean over each electrode → a fraction
    ``transmission`` closes the dielectric gap ``gap_mm`` → ``ΔC/C0 = u / (gap − u)`` (0.06 at
    rest, ~0.4 with a dot centred on a taxel) + white noise of sd ``noise`` (seeded).
    *Motion*: sample i at ``t_i = i/rate_hz``; ``x_0 = −lead_mm``, ``x_i = x_{i−1} + v·dt`` with v
    the latest ``speed`` sample stamped at or before ``t_{i−1}`` (so a loop that answers sample
    i−1's taxels in the same tick steers sample i: one 4 ms tick of delay at 250 Hz; a later
    answer takes effect at the first sample after it arrives). The scan ends after the last
    sample with ``x ≤`` (cells · pitch + lead_mm): nothing is emitted after it. ``ends_at`` is
    that time exactly at constant speed; with ``speed`` connected, the time at
    ``min_speed_mm_s`` (a bound; flowtact runs until the latest source end before a graph's
    ``duration_s``, so shorten a closed loop with ``--duration``).
    *Variation* (``variation``; none by default, docs/braille.md "A fingertip that varies"): per
    trial of ``trial_cells`` cells a press offset, the line's lateral offset and yaw, and a sensor
    gain; slow OU drifts of press and gain; an OU jitter of the actual speed around the command
    (``position`` is the true position, ``speed`` the actual speed); per-dot heights uniform in
    [``dot_height_min``, ``dot_height_max``] × nominal; the cover's spread growing with the distance
    slid (``wear_per_m``) and its compression relaxing with ``cover_tau_s``. All drawn from the
    node's seed on streams of their own, recorded per sample in ``conditions``.
    *Safety*: speeds outside the range (0, negative, huge) are clamped and counted
    (``speed_clamped``); NaN/inf speed or lateral samples follow ``on_bad_data`` (drop and hold
    both keep the previous command).
    Chunking-invariant whenever the inputs' samples arrive in the tick that covers their time
    stamp (offline runs); in a graph the loop's tick fixes what arrived when, so runs are still
    deterministic.

    Example
    -------
    >>> from flowtact.blocks.braille.scan import BrailleScan
    >>> from flowtact.testing import run_source
    >>> out = run_source(BrailleScan(text="ab"), 2.0, tick_s=0.1)
    >>> out["taxels"].data.shape[1], round(float(out["position"].data[-1]), 1)
    (24, 28.4)
    """

    config_cls = BrailleScanConfig
    inputs = {
        "speed": ft.Port(
            dtype="float64",
            shape=(),
            units="mm/s",
            optional=True,
            delay=True,
            doc="commanded scanning speed, clamped to [min_speed_mm_s, max_speed_mm_s]; unconnected: the "
            "constant speed_mm_s",
        ),
        "lateral": ft.Port(
            dtype="float64",
            shape=(),
            units="mm",
            optional=True,
            delay=True,
            doc="lateral (±Y) correction added to y_offset_mm (clamped to ±max_lateral_mm); 0 before any",
        ),
    }
    outputs = {
        "taxels": ft.Port(
            dtype="float64",
            shape=(ROWS * COLS,),
            units="1",
            rate="rate_hz",
            labels=TAXEL_LABELS,
            doc="relative capacitance change ΔC/C0 of each taxel, ``j = row·4 + col``; row 0 is the top "
            "row (+Y, dots 1 and 4), column 0 the trailing one (the finger moves towards +X)",
        ),
        "char": ft.Port(
            dtype="float64",
            shape=(),
            units="1",
            rate="rate_hz",
            categories=CATEGORIES,
            doc="the letter whose cell lies under the finger's centre (its two dot columns ± a dot "
            "radius), else ``gap``. Ground truth for decoders: a run of equal values is one character "
            "window",
        ),
        "position": ft.Port(
            dtype="float64",
            shape=(),
            units="mm",
            rate="rate_hz",
            doc="the finger centre along the line; cell k spans [k, k + 1)·cell pitch (10.2 mm scaled)",
        ),
        "y": ft.Port(
            dtype="float64",
            shape=(),
            units="mm",
            rate="rate_hz",
            doc="the finger centre across the line as the robot commands it: y_offset_mm + correction (the "
            "line's own offset and yaw are in conditions' lateral)",
        ),
        "speed": ft.Port(
            dtype="float64",
            shape=(),
            units="mm/s",
            rate="rate_hz",
            doc="the finger's actual speed from this sample: the (clamped) command times the jitter",
        ),
        "conditions": ft.Port(
            dtype="float64",
            shape=(len(CONDITION_LABELS),),
            units="mm",
            rate="rate_hz",
            labels=CONDITION_LABELS,
            doc="what the taxels met at each sample: press (mm), lateral (the finger centre from the line's "
            "middle dot row, mm: what the taxels saw), spread (the cover's blur sd, mm), dot_scale_1 (mean "
            "dot height factor of the cell under the finger centre, 0 without dots), yaw_deg, gain_1",
        ),
    }
    counter_docs = {
        "speed_clamped": "speed samples outside [min_speed_mm_s, max_speed_mm_s] (0, negative or too fast), "
        "clamped into it: the controller asked for more than the rig allows",
        "lateral_clamped": "lateral corrections beyond ±max_lateral_mm, clamped",
        **ft.nonfinite_counter_docs("speed or lateral samples"),
    }

    def ends_at(self, inputs: Mapping[str, ft.StreamSpec]) -> float | None:
        c = self.config
        v = c.min_speed_mm_s if "speed" in inputs else self._clamp_speed(c.speed_mm_s)
        v = v * c.slowest() if c.speed_jitter else v
        x0, x_end = c.track()
        return _samples_at(x0, x_end, v / c.rate_hz) / c.rate_hz

    def _clamp_speed(self, v: float) -> float:
        return min(max(v, self.config.min_speed_mm_s), self.config.max_speed_mm_s)

    def reset(self) -> None:
        c = self.config
        text_rng, self._noise_rng, var_rng = self.rng.spawn(3)
        trial_rng, dot_rng, self._drift_rng = var_rng.spawn(3)
        if c.random_letters:
            self.text = "".join(LETTERS[k] for k in text_rng.integers(0, len(LETTERS), c.random_letters))
        else:
            self.text = c.text
        self._tip = c.fingertip()
        cells = text_cells(self.text)
        self._dots = dot_positions(cells, self._tip.geometry)
        self._scales = dot_scales(dot_rng, len(self._dots), c.dot_height_min, c.dot_height_max)
        cell = self._dots[:, 2].astype(np.int64)
        n_dots = np.bincount(cell, minlength=len(cells))
        self._cell_scale = np.bincount(cell, self._scales, minlength=len(cells)) / np.maximum(n_dots, 1)
        g = self._tip.geometry
        self._trials = Trials.draw(
            trial_rng, len(cells), c.trial_cells, g.cell_pitch, c.press_sd_mm, c.lateral_sd_mm, c.yaw_sd_deg,
            c.gain_sd,
        )  # fmt: skip
        self._drifts = (
            Drift(c.press_drift_mm, c.drift_tau_s, 1.0 / c.rate_hz),
            Drift(c.gain_drift, c.drift_tau_s, 1.0 / c.rate_hz),
            Drift(c.speed_jitter, c.speed_jitter_tau_s, 1.0 / c.rate_hz),
        )
        self._cover = np.zeros(ROWS * COLS)  # the cover's relaxing compression (cover_tau_s)
        self._drifting = bool(c.press_drift_mm or c.gain_drift or c.speed_jitter)
        self._cat = np.array([CATEGORIES.index("space" if ch == " " else ch) for ch in self.text], np.float64)
        self._dt = 1.0 / c.rate_hz
        self._i = 0
        self._x0, self._x_end = c.track()
        self._x = self._x0
        self._x_last = self._x0  # the last emitted sample's position (for summary)
        self._v = self._clamp_speed(c.speed_mm_s)
        self._lat = 0.0
        self._done = False
        self._pending: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {"speed": [], "lateral": []}
        self._last = {"speed": self._v, "lateral": 0.0}
        self._range = {
            "speed": (c.min_speed_mm_s, c.max_speed_mm_s),
            "lateral": (-c.max_lateral_mm, c.max_lateral_mm),
        }

    # -- inputs ----------------------------------------------------------------------------------
    def _take(self, port: str, chunk: ft.Chunk | None) -> None:
        """Screen, clamp and queue the commands that arrived on ``port``.

        Non-finite samples: ``raise`` stops the run; ``drop`` removes them; ``hold`` repeats the
        previous (clamped) command. Finite ones outside the safe range are clamped and counted.
        """
        if chunk is None or len(chunk) == 0:
            return
        policy = self.config.on_bad_data
        t = np.asarray(chunk.t, np.float64)
        v = np.asarray(chunk.data, np.float64)
        bad = ~np.isfinite(v)
        if bad.any():
            if policy == "raise":
                ft.screen_nonfinite(self, chunk, policy, port, None)  # raises, naming node and port
            self.count("nonfinite_drop" if policy == "drop" else "nonfinite_hold", int(bad.sum()))
        lo, hi = self._range[port]
        clamped = int((~bad & ((v < lo) | (v > hi))).sum())
        self.count("speed_clamped" if port == "speed" else "lateral_clamped", clamped)
        v = np.clip(v, lo, hi)
        if policy == "drop":
            t, v = t[~bad], v[~bad]
        elif bad.any():  # hold: forward-fill from the last good (clamped) command
            good = np.where(~bad, np.arange(len(v)), -1)
            src = np.maximum.accumulate(good)
            v = np.where(src >= 0, v[np.maximum(src, 0)], self._last[port])
        if len(v):
            self._last[port] = float(v[-1])
            self._pending[port].append((t, v))

    def _apply_until(self, port: str, t: float) -> float | None:
        """The latest queued command stamped at or before ``t`` (dropping it and older ones), or None."""
        latest = None
        q = self._pending[port]
        tol = 1e-9 * self._dt
        while q:
            ts, vs = q[0]
            k = int(np.searchsorted(ts, t + tol, side="right"))
            if k:
                latest = float(vs[k - 1])
            if k < len(ts):
                q[0] = (ts[k:], vs[k:])
                break
            q.pop(0)
        return latest

    # -- step --------------------------------------------------------------------------------------
    def step(
        self, now: float, speed: ft.Chunk | None = None, lateral: ft.Chunk | None = None
    ) -> dict[str, ft.Chunk]:
        self._take("speed", speed)
        self._take("lateral", lateral)
        c = self.config
        n_due = max(self.due(now, c.rate_hz) - self._i, 0)
        rows: list[tuple[float, ...]] = []  # per sample: x, y, actual speed, press, lateral, gain, trial
        trials, (press_drift, gain_drift, jitter) = self._trials, self._drifts
        lo = c.slowest()
        for _ in range(n_due if not self._done else 0):
            eps = self._drift_rng.standard_normal(3) if self._drifting else (0.0, 0.0, 0.0)
            factor = min(max(1.0 + jitter.step(eps[2]), lo), 2.0 - lo) if c.speed_jitter else 1.0
            if self._i > 0:
                t_prev = (self._i - 1) * self._dt
                v = self._apply_until("speed", t_prev)
                self._v = self._v if v is None else v
                lat = self._apply_until("lateral", t_prev)
                self._lat = self._lat if lat is None else lat
                self._x = self._x + self._v * factor * self._dt
            if self._x > self._x_end:
                self._done = True
                break
            k = trials.index(self._x)
            y = c.y_offset_mm + self._lat
            press = min(max(c.press_mm + trials.press[k] + press_drift.step(eps[0]), 0.0), c.press_top())
            gain = math.exp(trials.log_gain[k] + gain_drift.step(eps[1]))
            rows.append((self._x, y, self._v * factor, press, y - trials.line_y(k, self._x), gain, k))
            self._i += 1
        n = len(rows)
        table = np.array(rows, np.float64).reshape(n, 7)
        x, y = table[:, 0].copy(), table[:, 1].copy()
        if n:
            self._x_last = float(x[-1])
        t = (self._i - n + np.arange(n)) / c.rate_hz
        out: dict[str, ft.Chunk] = {}
        want = self.demanded
        spread = self._tip.sigma_mm * (1.0 + c.wear_per_m * 1e-3 * (x - self._x0)) if c.wear_per_m else None
        if "taxels" in want:
            noise = self._noise_rng.standard_normal((n, ROWS * COLS)) * c.noise
            squeeze = self._tip.compression(
                x, table[:, 4], self._dots, height_scale=self._scales, sigma_mm=spread, press_mm=table[:, 3]
            )
            if c.cover_tau_s and n:
                a = math.exp(-self._dt / c.cover_tau_s)
                squeeze = _relax(squeeze, a, self._cover, self._i > n)
            out["taxels"] = ft.Chunk(t, self._tip.reading(squeeze) * table[:, 5:6] + noise)
        if "char" in want:
            out["char"] = ft.Chunk(t, self._char(x))
        if "position" in want:
            out["position"] = ft.Chunk(t, x)
        if "y" in want:
            out["y"] = ft.Chunk(t, y)
        if "speed" in want:
            out["speed"] = ft.Chunk(t, table[:, 2].copy())
        if "conditions" in want:
            out["conditions"] = ft.Chunk(t, self._conditions(table, spread))
        return out

    def _conditions(self, table: np.ndarray, spread: np.ndarray | None) -> np.ndarray:
        """(n, 6) what each sample's taxels met, in :data:`CONDITION_LABELS` order."""
        x, k = table[:, 0], table[:, 6].astype(np.int64)
        cell = np.floor(x / self._tip.geometry.cell_pitch).astype(np.int64)
        inside = (cell >= 0) & (cell < len(self._cell_scale))
        scale = np.where(inside, self._cell_scale[np.clip(cell, 0, max(len(self._cell_scale) - 1, 0))], 0.0)
        return np.column_stack(
            [
                table[:, 3],
                table[:, 4],
                np.full(len(x), self._tip.sigma_mm) if spread is None else spread,
                scale,
                np.degrees(self._trials.yaw_rad[k]),
                table[:, 5],
            ]
        )

    def _char(self, x: np.ndarray) -> np.ndarray:
        """Category of the cell under each finger position (0 between cells and off the text): the
        window rule of ``braille_cell_windows``, with the text's letter in each window."""
        k = cell_window_values(x, self._tip.geometry)
        on = (k >= 0) & (k < len(self._cat))
        kk = np.where(on, k, 0.0).astype(np.int64)
        return np.where(on, self._cat[kk] if len(self._cat) else 0.0, 0.0)

    def summary(self) -> str | None:
        """``scanned "qwerty…" (26 letters) in 2.31 s, 231 mm/s mean`` (the mean over the distance
        scanned; ``… 40 of 120 mm`` when the run ended before the line did); None before a sample."""
        if self._i < 2:
            return None
        span = (self._i - 1) * self._dt
        dist = self._x_last - self._x0
        text = (
            self.text if len(self.text) <= SUMMARY_TEXT_CHARS else self.text[: SUMMARY_TEXT_CHARS - 1] + "…"
        )
        letters = sum(1 for ch in self.text if ch != " ")
        part = "" if self._done else f", {dist:.0f} of {self._x_end - self._x0:.0f} mm"
        return f'scanned "{text}" ({letters} letters{part}) in {span:.2f} s, {dist / span:.0f} mm/s mean'

    @classmethod
    def example(cls) -> ft.Example:
        n = 250
        speed = 30.0 + 20.0 * np.sin(np.arange(n) / 40.0)
        speed[100] = 0.0  # clamped to the minimum
        lateral = 0.3 * np.sin(np.arange(n) / 60.0)
        return ft.Example(
            params={
                "text": "bat",
                "rate_hz": 250.0,
                **ROBOT,
            },  # every variation on: the suite checks them too
            inputs={"speed": speed, "lateral": lateral},
            units={"speed": "mm/s", "lateral": "mm"},
            rate_hz=250.0,
            duration_s=1.0,
        )
