"""Force feedback for the Remote Feelings exoskeleton (White 2023, §3.2.2): blocking and variable, with safety.

One controller per finger (thumb, index, middle: :data:`flowtact.blocks.teleop.hand.FINGERS`), vectorised
into one block whose output is the servo command stream of the teleop contract: ``cmd`` (3, 2),
column 0 engage (0.0 / 1.0), column 1 the deviation from the contact position in µs of PWM.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

import flowtact.api as ft
from flowtact.streams.merge import LatestMerger

from .hand import FINGERS, N_FINGERS

__all__ = ["GAIN_US_PER_N", "ForceFeedback", "ForceFeedbackConfig"]

#: §3.2.2: proportional gains of the variable feedback, µs of PWM per N (thumb, index, middle).
GAIN_US_PER_N = (80.0, 100.0, 100.0)

_CMD = (N_FINGERS, 2)
#: One name per command value (C order); the ``_us`` suffix gives the unit of a column that is not
#: the stream's own (engage is a 0/1 flag), so plots draw the two columns on their own axes.
_CMD_LABELS = tuple(f"{finger} {what}" for finger in FINGERS for what in ("engage_1", "deviation_us"))


def _fill(
    t: np.ndarray, x: np.ndarray, val: np.ndarray, when: np.ndarray, max_abs: float
) -> tuple[np.ndarray, int, int]:
    """Per finger, the latest valid value and its time at each sample: (n, 3, 2) [value, time].

    A value is valid if finite and |value| ≤ ``max_abs``; ``val``/``when`` (3,) carry the last
    valid ones across chunks and are updated in place. Returns the filled rows and the number
    of samples with a non-finite / out-of-range value.
    """
    n = len(t)
    out = np.empty((n, N_FINGERS, 2))
    nonfinite = out_of_range = 0
    for k in range(n):
        bad_nf = bad_oor = False
        tk = float(t[k])
        for i in range(N_FINGERS):
            v = float(x[k, i])
            if not math.isfinite(v):
                bad_nf = True
            elif abs(v) > max_abs:
                bad_oor = True
            else:
                val[i] = v
                when[i] = tk
            out[k, i, 0] = val[i]
            out[k, i, 1] = when[i]
        nonfinite += bad_nf
        out_of_range += bad_oor
    return out, nonfinite, out_of_range


@dataclass(frozen=True)
class ForceFeedbackConfig(ft.Config):
    """Parameters of :class:`ForceFeedback` (per-finger tuples: thumb, index, middle)."""

    mode: Literal["blocking", "variable"] = ft.param(
        "variable", doc="blocking: hold the contact position; variable: deviate by K·(F_f − F_T)"
    )
    gain_us_per_n: tuple[float, ...] = ft.param(
        GAIN_US_PER_N,
        doc="K per finger, µs of PWM per N (thesis: 80 thumb, 100 index/middle)",
        min_len=3,
        max_len=3,
        ge=0,
    )
    contact_n: float = ft.param(0.5, doc="contact detected when the TacTip force F_T exceeds this, N", ge=0)
    release_n: float = ft.param(
        0.0, doc="release when the fingertip force F_f falls below this, N (thesis: 0)"
    )
    min_us: float = ft.param(
        -300.0, doc="lowest deviation commanded, µs (negative: pushes the finger open)", le=0
    )
    max_us: float = ft.param(
        600.0, doc="highest deviation commanded, µs (positive: lets the finger close)", ge=0
    )
    max_rate_us_per_s: float = ft.param(
        2000.0, doc="largest change of the deviation per second while engaged", gt=0
    )
    stall_s: float = ft.param(
        0.2, doc="an input without valid data for this long disengages the servos, s", gt=0
    )
    max_wait_s: float = ft.param(
        0.05, doc="longest a finger sample waits for the target stream's watermark before going on, s", ge=0
    )
    max_force_n: float = ft.param(
        50.0, doc="forces of larger magnitude are implausible: treated as missing, N", gt=0
    )

    def check(self) -> None:
        if self.min_us >= self.max_us:
            raise self.error("max_us", f"must be > min_us ({self.min_us:g}); got {self.max_us:g}")
        if self.max_wait_s > self.stall_s:
            raise self.error("max_wait_s", f"must be <= stall_s ({self.stall_s:g}); got {self.max_wait_s:g}")


class ForceFeedback(ft.Block):
    """Force-feedback controller per finger: engage on contact, release on negative finger force, P control.

    Config
    ------
    See :class:`ForceFeedbackConfig`. Defaults: variable feedback, K = (80, 100, 100) µs/N.

    Notes
    -----
    **Control** (§3.2.2, per finger). Contact is detected when F_T > ``contact_n``; the finger then
    engages (servo holds the contact position, deviation 0). It releases (engage 0, deviation 0)
    when F_f < ``release_n`` (0: the thesis' "negative FSR force": the user opens the hand). After a
    release or a stall it re-engages only on a *fresh* contact: F_T must first be seen at or below
    ``contact_n`` (the gripper came off the object), then exceed it again; it also starts disarmed
    (a sensor loaded at start-up does not engage). An engage needs F_f ≥ ``release_n``.
    *blocking*: the deviation stays 0 while engaged. *variable*: deviation = K·(F_f − F_T).
    Sign mapping: the thesis writes F_R = F_T − F_f and φ̂1 = K·F_R; here a positive deviation lets
    the finger close further than the contact position (the teleop contract), so
    deviation = −φ̂1 = K·(F_f − F_T): the finger advances while it pushes harder than the object
    pushes back; a soft object's F_T rises slowly as the gripper closes, so deviations spread wider.

    **Safety** (not optional). Every deviation is clamped to [``min_us``, ``max_us``] and, while a
    finger stays engaged, rate-limited: |Δ| ≤ ``max_rate_us_per_s``·Δt with Δt the time between
    consecutive output rows (timestamps, not nominal rate). An engage starts from 0 and a
    disengage is immediate (engage 0 has deviation 0: the servo is off, nothing moves). Defaults:
    +600 µs is K·6 N, about the largest FSR force eq. 3.10 can report above its preload (7.2 N at
    a full-scale reading), ≈ 55° on an MG90S (≈ 11 µs/°); −300 µs (≈ 27°) bounds how far the servo
    may push a finger back open; 2000 µs/s lets a full-range move take ≥ 0.45 s, inside the
    thesis' 0.25–0.6 s force step responses. NaN/inf and |F| > ``max_force_n`` are missing data
    (counted ``nonfinite_target``/``_finger``, ``out_of_range_target``/``_finger``), never used:
    each finger holds its last valid value and its age grows. **Stall**: a finger whose last
    valid ``target`` or ``finger`` value is older than ``stall_s`` (at the time of the row being
    computed) is disengaged and disarmed; each onset counts ``stalled`` (and ``stalled_target`` /
    ``stalled_finger`` by cause). A camera that dies while the exoskeleton runs is caught by the
    target's age on the next ``finger`` samples: within ``stall_s`` + one sample. A ``finger``
    stream that stops (serial unplugged) produces no rows to act on, so the block emits one
    extra all-disengaged row at t_last + ``stall_s`` as soon as either input's watermark passes
    that time; if the stream resumes, its next row follows normally.

    **Merging** (:class:`flowtact.streams.merge.LatestMerger`): each ``finger`` sample is paired with the
    latest ``target`` sample at or before its time, and released once the target's watermark
    passes it — chunking-invariant. A ``finger`` sample waits at most ``max_wait_s`` of graph time
    (the larger input watermark) for that; then it is computed with the target known so far, so a
    target chain whose watermark froze (a dead process) still gets disengaged, within
    ``stall_s`` + ``max_wait_s`` + one sample. Only those forced releases, and ``finger`` samples
    arriving more than ``stall_s`` behind the other input (dropped, counted ``late``), depend on
    arrival order: both are fault conditions. The output watermark is the earliest time a row
    may still come. State: the merger, per finger the last valid values and times, engaged,
    armed, last deviation; latency 0 beyond the wait for the target's watermark.

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.teleop.feedback import ForceFeedback
    >>> from flowtact.testing import run_offline
    >>> n = 100                                           # 1 s at 100 Hz, F_T 1 N, F_f 3 N
    >>> target = np.r_[np.zeros((10, 3)), np.ones((n - 10, 3))]
    >>> out = run_offline(ForceFeedback(), target=target, finger=np.full((n, 3), 3.0), rate_hz=100.0,
    ...                   units={"target": "N", "finger": "N"})
    >>> out["cmd"].data[-1].tolist()                      # engaged, K·(3 − 1)
    [[1.0, 160.0], [1.0, 200.0], [1.0, 200.0]]
    """

    config_cls = ForceFeedbackConfig
    inputs = {
        "target": ft.Port(
            dtype="float64",
            shape=(3,),
            units="N",
            require_rate=True,
            doc="contact force F_T at the TacTips (≈ 40 Hz)",
        ),
        "finger": ft.Port(
            dtype="float64",
            shape=(3,),
            units="N",
            require_rate=True,
            doc="signed fingertip force F_f (exo rate; drives the output)",
        ),
    }
    outputs = {
        "cmd": ft.Port(
            dtype="float64",
            shape=(3, 2),
            units="us",
            rate="finger",
            labels=_CMD_LABELS,
            doc="per finger [engage 0/1, deviation µs], one row per finger sample, plus one disengaging "
            "row when the finger stream stalls",
        )
    }
    counter_docs = {
        "stalled": "times live fingers were disengaged because an input had no valid data for stall_s "
        "(re-engaging needs a fresh contact): an input stalled or died",
        "stalled_target": "stalls caused by the TacTip force 'target' going stale (camera or vision chain)",
        "stalled_finger": "stalls caused by the fingertip force 'finger' going stale or stopping "
        "(exoskeleton link)",
        "late": "finger samples dropped: stamped at or before an earlier one, or behind a stall "
        "(disengage) row already sent; a timing fault upstream",
        "target_late": "finger samples that waited max_wait_s for the 'target' watermark, then were "
        "computed with the latest target known: the target stream lags",
        "nonfinite_target": "target samples with NaN/inf on a finger: ignored, the finger keeps its last "
        "valid value (aging towards a stall)",
        "out_of_range_target": "target samples with |F| > max_force_n on a finger (implausible): ignored "
        "like NaN",
        "nonfinite_finger": "finger samples with NaN/inf on a finger: ignored, the finger keeps its last "
        "valid value (aging towards a stall)",
        "out_of_range_finger": "finger samples with |F| > max_force_n on a finger (implausible): ignored "
        "like NaN",
    }

    def reset(self) -> None:
        cfg = self.config
        self._k = np.asarray(cfg.gain_us_per_n, np.float64)
        self._merger = LatestMerger(
            "finger", {"target": np.array([[0.0, -np.inf]] * N_FINGERS)}, (N_FINGERS, 2)
        )
        self._t_val, self._t_when = np.zeros(N_FINGERS), np.full(N_FINGERS, -np.inf)
        self._f_val, self._f_when = np.zeros(N_FINGERS), np.full(N_FINGERS, -np.inf)
        self._wm_target = -np.inf
        self._wm_finger = -np.inf
        self._last_in = -np.inf  # latest finger sample received
        self._last_proc = -np.inf  # latest finger sample computed
        self._stall_sent = True  # nothing to report before the first finger sample
        self._last_out = -np.inf  # time of the last row emitted
        self._end_out = -np.inf
        self._engaged = [False] * N_FINGERS
        self._armed = [False] * N_FINGERS
        self._live = [False] * N_FINGERS
        self._dev = [0.0] * N_FINGERS

    # -- one row --------------------------------------------------------------------------------------
    def _row(self, t: float, f: np.ndarray, tgt: np.ndarray, rows: list, times: list) -> None:
        cfg = self.config
        dt = t - self._last_out if math.isfinite(self._last_out) else 0.0
        limit = cfg.max_rate_us_per_s * max(dt, 0.0)
        row = np.zeros(_CMD)
        onset_t = onset_f = False
        for i in range(N_FINGERS):
            ff, f_when = float(f[i, 0]), float(f[i, 1])
            ft, t_when = float(tgt[i, 0]), float(tgt[i, 1])
            stale_t = not (t - t_when <= cfg.stall_s)
            stale_f = not (t - f_when <= cfg.stall_s)
            if stale_t or stale_f:
                if self._live[i]:
                    onset_t |= stale_t
                    onset_f |= stale_f
                self._live[i] = self._engaged[i] = self._armed[i] = False
                self._dev[i] = 0.0
                continue
            self._live[i] = True
            if ft <= cfg.contact_n:
                self._armed[i] = True
            if self._engaged[i] and ff < cfg.release_n:
                self._engaged[i] = self._armed[i] = False
                self._dev[i] = 0.0
            elif not self._engaged[i] and self._armed[i] and ft > cfg.contact_n and ff >= cfg.release_n:
                self._engaged[i] = True
                self._dev[i] = 0.0
            if not self._engaged[i]:
                continue
            want = 0.0 if cfg.mode == "blocking" else float(self._k[i]) * (ff - ft)
            want = min(max(want, cfg.min_us), cfg.max_us)  # clamp (also ±inf from overflow)
            prev = self._dev[i]
            dev = min(max(want, prev - limit), prev + limit)
            self._dev[i] = dev
            row[i, 0] = 1.0
            row[i, 1] = dev
        if onset_t or onset_f:
            self.count("stalled")
            self.count("stalled_target", int(onset_t))
            self.count("stalled_finger", int(onset_f))
        rows.append(row)
        times.append(t)
        self._last_out = t

    def _stall_row(self, t: float, rows: list, times: list) -> None:
        """The finger stream went quiet: one all-disengaged row at ``t`` (= last sample + stall_s)."""
        if any(self._live):
            self.count("stalled")
            self.count("stalled_finger")
        self._live = [False] * N_FINGERS
        self._engaged = [False] * N_FINGERS
        self._armed = [False] * N_FINGERS
        self._dev = [0.0] * N_FINGERS
        rows.append(np.zeros(_CMD))
        times.append(t)
        self._last_out = t
        self._stall_sent = True

    def _compute(self, t: np.ndarray, f: np.ndarray, tgt: np.ndarray, rows: list, times: list) -> None:
        """Rows for released finger samples ``t`` (n,), ``f`` and ``tgt`` (n, 3, 2) [value, time]."""
        stall_s = self.config.stall_s
        for k in range(len(t)):
            tk = float(t[k])
            if tk <= self._last_out:  # behind a stall row already sent: too late to act on
                self.count("late")
                continue
            if not self._stall_sent and tk > self._last_proc + stall_s:
                self._stall_row(self._last_proc + stall_s, rows, times)
            self._row(tk, f[k], tgt[k], rows, times)
            self._last_proc = tk
            self._stall_sent = False

    def _ingest(self, target: ft.Chunk | None, finger: ft.Chunk | None) -> dict[str, ft.Chunk]:
        """Fill missing values per finger, track watermarks; the chunks to push into the merger."""
        cfg = self.config
        feed: dict[str, ft.Chunk] = {}
        if target is not None:
            filled, nf, oor = _fill(target.t, target.data, self._t_val, self._t_when, cfg.max_force_n)
            self.count("nonfinite_target", nf)
            self.count("out_of_range_target", oor)
            feed["target"] = ft.Chunk(target.t, filled, target.end)
            marks = [self._wm_target, *([float(target.t[-1])] if len(target) else [])]
            self._wm_target = max([*marks, *([float(target.end)] if target.end is not None else [])])
        if finger is not None:
            keep = np.ones(len(finger), bool)
            last = self._last_in
            for k in range(len(finger)):  # timestamps must increase: drop what goes back in time
                if finger.t[k] > last:
                    last = float(finger.t[k])
                else:
                    keep[k] = False
            if not keep.all():
                self.count("late", int((~keep).sum()))
                finger = ft.Chunk(finger.t[keep], finger.data[keep], finger.end)
            filled, nf, oor = _fill(finger.t, finger.data, self._f_val, self._f_when, cfg.max_force_n)
            self.count("nonfinite_finger", nf)
            self.count("out_of_range_finger", oor)
            feed["finger"] = ft.Chunk(finger.t, filled, finger.end)
            self._last_in = last
            marks = [self._wm_finger, last, *([float(finger.end)] if finger.end is not None else [])]
            self._wm_finger = max(marks)
        return feed

    def step(self, target: ft.Chunk, finger: ft.Chunk) -> dict[str, ft.Chunk]:
        cfg = self.config
        rows: list[np.ndarray] = []
        times: list[float] = []
        t, f, vals = self._merger.push(self._ingest(target, finger))
        self._compute(t, f, vals["target"], rows, times)
        clock = max(self._wm_target, self._wm_finger)
        if math.isfinite(clock) and len(self._merger.held_times()):
            t, f, vals = self._merger.release_through(clock - cfg.max_wait_s)
            self.count("target_late", len(t))
            self._compute(t, f, vals["target"], rows, times)
        if (
            not self._stall_sent
            and not len(self._merger.held_times())
            and clock >= self._last_proc + cfg.stall_s
        ):
            self._stall_row(self._last_proc + cfg.stall_s, rows, times)
        return {"cmd": self._out(rows, times)}

    def _out(self, rows: list, times: list) -> ft.Chunk:
        held = self._merger.held_times()
        nxt = [float(held[0])] if len(held) else []
        if math.isfinite(self._wm_finger):
            nxt.append(self._wm_finger)
        end = None
        if nxt:
            self._end_out = max(self._end_out, min(nxt))
            end = self._end_out
        if not rows:
            return ft.Chunk.empty(shape=_CMD, end=end)
        return ft.Chunk(np.asarray(times, np.float64), np.stack(rows), end)

    def flush(self) -> dict[str, ft.Chunk]:
        rows: list[np.ndarray] = []
        times: list[float] = []
        t, f, vals = self._merger.flush()
        self._compute(t, f, vals["target"], rows, times)
        if not rows:
            return {}
        return {"cmd": ft.Chunk(np.asarray(times, np.float64), np.stack(rows))}

    @classmethod
    def example(cls) -> ft.Example:
        rng = np.random.default_rng(12)
        n = 200  # 2 s at 100 Hz: a grasp per finger, a NaN burst and a camera dropout
        t = np.arange(n) / 100.0
        target = np.outer(np.clip((t - 0.3) * 3.0, 0.0, 2.0) * (t < 1.5), [1.0, 1.2, 0.8])
        finger = np.outer(np.clip((t - 0.2) * 4.0, 0.0, 3.0), [1.0, 1.0, 1.1]) - 2.0 * (t > 1.6)[:, None]
        target += rng.normal(0, 0.05, (n, 3))
        finger += rng.normal(0, 0.05, (n, 3))
        target[60:64, 1] = np.nan
        finger[90:93, 2] = np.inf
        target[110:140] = np.nan  # 0.3 s without a valid target: stall, then a fresh contact is needed
        return ft.Example(
            inputs={"target": target, "finger": finger}, rate_hz=100.0, units={"target": "N", "finger": "N"}
        )
