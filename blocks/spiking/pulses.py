"""Stimulation: spikes → a safe train of current pulses (one pulse per spike, inside an envelope).

Rager et al. mean their afferent spike trains to drive electrical stimulation, one current pulse
per spike. This module turns any event stream into pulses and guarantees a safety envelope
(amplitude range, charge per phase, rate and amplitude ramp per unit) whatever arrives.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numba import njit

from flowtact.block import BadDataConfig, Block, Example, Port, nonfinite_counter_docs, screen_nonfinite
from flowtact.chunk import Chunk, StreamSpec
from flowtact.errors import SpecError
from flowtact.params import param

__all__ = ["FLAGS", "Pulses", "PulsesConfig", "pulse_kernel", "pulse_kernel_py"]

# Per-event outcome flags written by the kernel (a delivered pulse may carry several change flags).
DELIVERED = 1
CLIPPED_AMPLITUDE = 2
CLIPPED_CHARGE = 4
RAMP_LIMITED = 8
DROPPED_RATE = 16
DROPPED_AMPLITUDE = 32
BAD_UNIT = 64
NONFINITE = 128

#: Counter name of each flag (``DELIVERED`` is not counted).
FLAGS: dict[int, str] = {
    CLIPPED_AMPLITUDE: "clipped_amplitude",
    CLIPPED_CHARGE: "clipped_charge",
    RAMP_LIMITED: "ramp_limited",
    DROPPED_RATE: "dropped_rate",
    DROPPED_AMPLITUDE: "dropped_amplitude",
    BAD_UNIT: "bad_unit",
    NONFINITE: "nonfinite",
}


def pulse_kernel_py(
    t: np.ndarray,
    unit: np.ndarray,
    req: np.ndarray,
    n_units: int,
    min_interval_s: float,
    a_min: float,
    a_max: float,
    a_charge: float,
    ramp_ua_per_s: float,
    last_t: np.ndarray,
    last_a: np.ndarray,
    out_a: np.ndarray,
    flags: np.ndarray,
) -> None:
    """Reference (plain Python) twin of :func:`pulse_kernel`; same arguments, same results.

    For each event in order: drop it if its unit is out of range, its requested amplitude is not
    finite or below ``a_min`` (a request for no pulse), or it comes less than ``min_interval_s``
    after the unit's previous delivered pulse (also for times that go backwards or are NaN);
    otherwise clip the amplitude to ``a_max``, then to the charge ceiling ``a_charge``, then limit
    its change from the unit's previous delivered amplitude to ``ramp_ua_per_s`` times the
    elapsed time. ``last_t`` / ``last_a`` (per unit) carry state across calls; -inf = none yet.
    """
    for i in range(len(t)):
        u = unit[i]
        if u < 0 or u >= n_units:
            flags[i] = BAD_UNIT
            continue
        a = req[i]
        if not np.isfinite(a):
            flags[i] = NONFINITE
            continue
        if not a >= a_min:
            flags[i] = DROPPED_AMPLITUDE
            continue
        gap = t[i] - last_t[u]
        if not gap >= min_interval_s:
            flags[i] = DROPPED_RATE
            continue
        f = DELIVERED
        if a > a_max:
            a = a_max
            f |= CLIPPED_AMPLITUDE
        if a > a_charge:
            a = a_charge
            f |= CLIPPED_CHARGE
        if last_t[u] > -np.inf:
            lim = ramp_ua_per_s * gap
            if a > last_a[u] + lim:
                a = last_a[u] + lim
                f |= RAMP_LIMITED
            elif a < last_a[u] - lim:
                a = last_a[u] - lim
                f |= RAMP_LIMITED
        out_a[i] = a
        flags[i] = f
        last_t[u] = t[i]
        last_a[u] = a


pulse_kernel = njit(cache=True, nogil=True)(pulse_kernel_py)
pulse_kernel.__doc__ = "numba version of :func:`pulse_kernel_py` (the per-event safety loop)."


@dataclass(frozen=True)
class PulsesConfig(BadDataConfig):
    amplitude_ua: float = param(
        60.0, doc="pulse amplitude per spike (also held before the first amplitude sample)", gt=0
    )
    width_us: float = param(200.0, doc="pulse width (per phase)", gt=0)
    max_rate_hz: float = param(
        300.0,
        doc="per unit: a pulse closer than 1/max_rate_hz to the previous delivered one is dropped",
        gt=0,
    )
    min_amplitude_ua: float = param(
        5.0, doc="smallest pulse delivered; requests below it (zero, negative) give no pulse", gt=0
    )
    max_amplitude_ua: float = param(250.0, doc="largest pulse amplitude; larger requests are clipped", gt=0)
    max_charge_nc: float = param(
        30.0, doc="charge per phase limit (amplitude × width); the amplitude is clipped to respect it", gt=0
    )
    max_ramp_ua_per_s: float = param(
        5000.0,
        doc="largest amplitude change between consecutive pulses of a unit, per second between them",
        gt=0,
    )
    max_units: int = param(64, doc="most stimulation channels (units) the stream may index", ge=1)

    def charge_ceiling_ua(self) -> float:
        """Largest amplitude allowed by the charge limit at this width: 1000·max_charge_nc / width_us."""
        return 1000.0 * self.max_charge_nc / self.width_us

    def state_bytes(self) -> dict[str, float]:
        """Per unit: last pulse time and amplitude, ramp and screen state (a few float64 each)."""
        return {"max_units": self.max_units * 8.0 * 8}

    def check(self) -> None:
        if self.min_amplitude_ua > self.max_amplitude_ua:
            raise self.error("min_amplitude_ua", f"must be <= max_amplitude_ua ({self.max_amplitude_ua:g})")
        if not self.min_amplitude_ua <= self.amplitude_ua <= self.max_amplitude_ua:
            raise self.error(
                "amplitude_ua",
                f"must lie in [min_amplitude_ua, max_amplitude_ua] = [{self.min_amplitude_ua:g}, "
                f"{self.max_amplitude_ua:g}]; got {self.amplitude_ua:g}",
            )
        charge = self.amplitude_ua * self.width_us / 1000.0
        if charge > self.max_charge_nc:
            raise self.error(
                "max_charge_nc",
                f"must be >= amplitude_ua × width_us = {charge:g} nC (the nominal pulse); got {self.max_charge_nc:g}",
            )
        if self.width_us * 1e-6 >= 1.0 / self.max_rate_hz:
            raise self.error(
                "width_us", f"must be shorter than 1/max_rate_hz = {1e6 / self.max_rate_hz:g} µs"
            )


class Pulses(Block):
    """Spikes → stimulation pulses, one per spike, always inside a safety envelope.

    Ports
    -----
    spikes : events, int (unit index), n_units ≤ max_units
        The spike trains to deliver (e.g. an ``nlif`` population's ``spikes``).
    amplitude : float64 () or (n_units,), units "uA", optional
        Requested amplitude, sample-and-hold: a spike at time t uses the latest sample at or
        before t (``amplitude_ua`` before the first sample). Unconnected: ``amplitude_ua``.
    y : events, float64 (3,), labels (unit, amplitude_ua, width_us)
        One row per delivered pulse, stamped with the spike time (pulse onset). ``Chunk.end`` is
        the watermark: no pulse before it will follow.

    Config
    ------
    See the field docs (``flowtact blocks pulses``). ``check()`` rejects a nominal pulse outside
    the envelope (amplitude outside [min, max], amplitude × width above the charge limit, a width
    longer than the minimum interval).

    Notes
    -----
    Envelope, per event in time order (``pulse_kernel``; a plain-Python twin is the test oracle):

    1. unit index outside [0, n_units) → dropped (``bad_unit``); non-finite event time → dropped
       (``bad_time``);
    2. requested amplitude below ``min_amplitude_ua`` (zero, negative, tiny) → no pulse
       (``dropped_amplitude``): a request below the minimum means "no stimulus", and raising it
       would deliver more than asked;
    3. less than 1/``max_rate_hz`` after the unit's previous DELIVERED pulse (or time going
       backwards) → dropped (``dropped_rate``);
    4. amplitude above ``max_amplitude_ua`` → clipped (``clipped_amplitude``);
    5. charge per phase: the WIDTH is fixed (it is the configured operating point on the
       strength–duration curve, and a shorter pulse would need more current to recruit the same
       fibres), so the AMPLITUDE is clipped to ``1000 · max_charge_nc / width_us``
       (``clipped_charge``); as this ceiling is constant the ramp limit below can never undo it;
    6. the change from the unit's previous delivered amplitude is limited to
       ``max_ramp_ua_per_s × (t − t_prev)`` (``ramp_limited``; a unit's first pulse is free). Both
       ends of that step lie in [min, ceiling], so the result does too.

    Non-finite amplitude SAMPLES are handled at the input by ``on_bad_data`` (counted as
    ``nonfinite_drop`` / ``nonfinite_hold``; ``hold`` keeps the unit's last finite value, starting
    from ``amplitude_ua``); +inf is non-finite, 1e300 is merely clipped. Every dropped spike is
    counted exactly once; a delivered pulse whose amplitude differs from its request carries at
    least one of the three change counters.

    State: per unit the time and amplitude of the last delivered pulse, the held amplitude sample,
    and (when ``amplitude`` is connected) spikes newer than the last amplitude sample, held back
    until a sample at or after their time arrives so that the result does not depend on how the two
    streams are chunked; ``flush`` delivers them with the last amplitude. Latency: none without
    ``amplitude``; otherwise until the amplitude stream reaches the spike time.

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.testing import run_offline
    >>> spikes = (np.array([0.010, 0.011, 0.020, 0.021]), np.array([0, 0, 0, 1]))
    >>> out = run_offline(Pulses(amplitude_ua=50.0), spikes=spikes)
    >>> out["y"].t  # the pulse 1 ms after the first one of unit 0 breaks max_rate_hz = 300
    array([0.01 , 0.02 , 0.021])
    >>> out["y"].data[0].tolist()
    [0.0, 50.0, 200.0]
    """

    config_cls = PulsesConfig
    inputs = {
        "spikes": Port(dtype=None, shape=(), events=True, doc="spike events (t = time, data = unit index)"),
        "amplitude": Port(
            dtype="float64", units="uA", optional=True, doc="requested amplitude per unit or for all (µA)"
        ),
    }
    outputs = {
        "y": Port(
            dtype="float64", shape=(3,), events=True, doc="delivered pulses: [unit, amplitude_ua, width_us]"
        ),
    }
    counter_docs = {
        "bad_time": "spikes with a NaN/inf time: dropped, no pulse (bad data upstream)",
        "bad_unit": "spikes whose unit index is outside [0, n_units): dropped, no pulse (bad data upstream)",
        "nonfinite": "spikes whose requested amplitude was NaN/inf: dropped, no pulse (a safety net "
        "behind on_bad_data, which screens the amplitude input)",
        "dropped_amplitude": "spikes whose requested amplitude was below min_amplitude_ua (a request for "
        "no stimulus): no pulse, as asked",
        "dropped_rate": "spikes less than 1/max_rate_hz after the unit's previous delivered pulse (or "
        "before it): no pulse, the rate limit acted",
        "clipped_amplitude": "pulses requested above max_amplitude_ua: delivered at max_amplitude_ua",
        "clipped_charge": "pulses whose amplitude × width_us exceeded max_charge_nc: delivered at the "
        "charge ceiling",
        "ramp_limited": "pulses whose amplitude changed faster than max_ramp_ua_per_s since the unit's "
        "previous pulse: delivered at the ramp-limited amplitude",
        **nonfinite_counter_docs("amplitude samples"),
    }

    def specs(self, inputs: Mapping[str, StreamSpec]) -> dict[str, StreamSpec]:
        c = self.config
        sp = inputs["spikes"]
        if np.dtype(sp.dtype).kind not in "iu":
            raise SpecError("spikes", f"expects integer unit indices; got dtype {sp.dtype}")
        if sp.shape != ():
            raise SpecError("spikes", f"expects one unit index per event (shape ()); got shape {sp.shape}")
        n_units = sp.n_units if sp.n_units is not None else c.max_units
        if n_units > c.max_units:
            raise SpecError(
                "spikes",
                f"indexes {n_units} units but max_units is {c.max_units}: one stimulation channel per unit; "
                f"set max_units: {n_units} if the stimulator has that many channels",
            )
        amp = inputs.get("amplitude")
        if amp is not None:
            if amp.events:
                raise SpecError("amplitude", "expects a sampled stream, not events")
            if amp.units != "uA":
                raise SpecError("amplitude", f"expects units 'uA'; got '{amp.units}'")
            if np.dtype(amp.dtype).kind != "f":
                raise SpecError("amplitude", f"expects a float stream; got dtype {amp.dtype}")
            if amp.shape not in ((), (n_units,)):
                raise SpecError(
                    "amplitude", f"expects shape () or ({n_units},) (one per unit); got shape {amp.shape}"
                )
        return {
            "y": StreamSpec(
                dtype="float64",
                shape=(3,),
                units="1",
                events=True,
                n_units=n_units,
                labels=("unit", "amplitude_ua", "width_us"),
            )
        }

    def reset(self) -> None:
        c = self.config
        self.n_units = self.output_specs["y"].n_units or c.max_units
        self.has_amp = "amplitude" in self.input_specs
        self.last_t = np.full(self.n_units, -np.inf)
        self.last_a = np.zeros(self.n_units)
        self.amp_t = -np.inf
        self.amp_last = np.full(self.n_units, c.amplitude_ua)
        self.screen_last: np.ndarray | None = None
        if self.has_amp:
            shape = self.input_specs["amplitude"].shape
            self.screen_last = np.full(shape, c.amplitude_ua)
        self.pend_t = np.empty(0)
        self.pend_u = np.empty(0, np.int64)

    def step(self, spikes: Chunk, amplitude: Chunk | None = None) -> dict[str, Chunk]:
        c = self.config
        new_t = np.asarray(spikes.t, np.float64)
        new_u = np.asarray(spikes.data).astype(np.int64)
        bad = ~np.isfinite(new_t)
        if bad.any():
            self.count("bad_time", int(bad.sum()))
            new_t, new_u = new_t[~bad], new_u[~bad]
        ev_t = np.concatenate([self.pend_t, new_t]) if len(self.pend_t) else new_t
        ev_u = np.concatenate([self.pend_u, new_u]) if len(self.pend_u) else new_u
        if not self.has_amp:
            return {"y": self._deliver(ev_t, ev_u, np.full(len(ev_t), c.amplitude_ua), spikes.end)}
        # Sample-and-hold lookup over [last held sample] + this chunk's (screened) samples.
        a_t, a_v = np.array([self.amp_t]), self.amp_last[None, :]
        if amplitude is not None and len(amplitude):
            amplitude, self.screen_last = screen_nonfinite(
                self, amplitude, c.on_bad_data, "amplitude", self.screen_last
            )
            if len(amplitude):
                rows = np.broadcast_to(
                    np.asarray(amplitude.data, np.float64).reshape(len(amplitude), -1),
                    (len(amplitude), self.n_units),
                )
                a_t = np.concatenate([a_t, amplitude.t])
                a_v = np.concatenate([a_v, rows])
        horizon = float(a_t[-1])
        # Spikes after the last amplitude sample wait for the amplitude stream (kept in order).
        late = np.flatnonzero(ev_t > horizon)
        n_ready = int(late[0]) if len(late) else len(ev_t)
        self.pend_t, self.pend_u = ev_t[n_ready:], ev_u[n_ready:]
        ev_t, ev_u = ev_t[:n_ready], ev_u[:n_ready]
        k = np.searchsorted(a_t, ev_t, side="right") - 1
        req = a_v[np.maximum(k, 0), np.clip(ev_u, 0, self.n_units - 1)]
        self.amp_t, self.amp_last = horizon, a_v[-1].copy()
        end = horizon if spikes.end is None else min(horizon, spikes.end)
        return {"y": self._deliver(ev_t, ev_u, req, end)}

    def flush(self) -> dict[str, Chunk]:
        if not len(self.pend_t):
            return {}
        ev_t, ev_u = self.pend_t, self.pend_u
        self.pend_t, self.pend_u = np.empty(0), np.empty(0, np.int64)
        req = self.amp_last[np.clip(ev_u, 0, self.n_units - 1)]
        return {"y": self._deliver(ev_t, ev_u, req, float(ev_t[-1]))}

    def _deliver(self, t: np.ndarray, u: np.ndarray, req: np.ndarray, end: float | None) -> Chunk:
        c = self.config
        n = len(t)
        out_a = np.empty(n)
        flags = np.zeros(n, np.int64)
        if n:
            pulse_kernel(
                np.ascontiguousarray(t, np.float64),
                np.ascontiguousarray(u, np.int64),
                np.ascontiguousarray(req, np.float64),
                self.n_units,
                1.0 / c.max_rate_hz,
                c.min_amplitude_ua,
                c.max_amplitude_ua,
                c.charge_ceiling_ua(),
                c.max_ramp_ua_per_s,
                self.last_t,
                self.last_a,
                out_a,
                flags,
            )
            for bit, name in FLAGS.items():
                self.count(name, int(np.count_nonzero(flags & bit)))
        keep = (flags & DELIVERED) != 0
        data = np.empty((int(keep.sum()), 3))
        data[:, 0] = u[keep]
        data[:, 1] = out_a[keep]
        data[:, 2] = c.width_us
        return Chunk(t[keep].copy(), data, end)

    @classmethod
    def example(cls) -> Example:
        rng = np.random.default_rng(11)
        n = 1000
        parts_t, parts_u = [], []
        for unit, rate in enumerate((120.0, 250.0, 40.0)):
            t = np.cumsum(rng.exponential(1.0 / rate, 400))
            parts_t.append(t[t < 0.99])
            parts_u.append(np.full(len(parts_t[-1]), unit))
        parts_t.append(0.5 + 1e-6 * np.arange(50))  # a 1 MHz burst on unit 0
        parts_u.append(np.zeros(50, np.int64))
        t = np.concatenate(parts_t)
        u = np.concatenate(parts_u)
        order = np.lexsort((u, t))
        tt = np.arange(n) / 1000.0
        amp = np.stack(
            [400.0 * np.sin(2 * np.pi * 2 * tt), 80.0 + 60.0 * np.sin(2 * np.pi * 7 * tt), np.full(n, 40.0)],
            axis=1,
        )
        amp[300, 1] = np.nan
        amp[600, 2] = np.inf
        return Example(
            params={"on_bad_data": "hold", "max_ramp_ua_per_s": 3000.0},
            inputs={"spikes": (t[order], u[order].astype(np.int64)), "amplitude": amp},
            units={"amplitude": "uA"},
        )
