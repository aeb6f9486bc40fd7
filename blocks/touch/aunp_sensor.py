"""Synthetic sensors: the four-gauge gold-nanoparticle (AuNP) sensor of Rager et al.

The sensor is a source: it plays a touch, slip or rest trial and emits what the real sensor
would (four gauge signals and a reference gauge, ΔR/R) together with the true force, so that a
graph's force reconstruction and afferent models can be checked against the truth.
"""

from __future__ import annotations

import numpy as np

import flowtact.api as ft

from .aunp_config import AunpSensorConfig
from .aunp_samples import SCENARIOS, sensor_samples, trial_constants

__all__ = ["AunpSensor", "AunpSensorConfig"]

_NO_NOISE = np.empty((0, 5))  # r and ref not demanded: no normals drawn
#: Rows of normals drawn ahead: one generator call per this many one-sample steps, not one per step
#: (numpy's generator makes the same values whatever the sizes of the requests).
NOISE_AHEAD = 1024


class AunpSensor(ft.Source):
    """Synthetic four-gauge AuNP tactile sensor (Rager et al.) playing touch, slip or rest trials.

    Config
    ------
    See the field docs (``flowtact blocks aunp_sensor``). Units are in the field names.

    Notes
    -----
    *Gauge model.* The gauges are the inverse of eq. 2 with identical gauges,
    ``r1 = Fz·Zs/4 − Fx·Xs/2``, ``r3 = Fz·Zs/4 + Fx·Xs/2``, ``r2 = Fz·Zs/4 + Fy·Ys/2``,
    ``r4 = Fz·Zs/4 − Fy·Ys/2`` (``reduced_matrix`` of blocks/touch/aunp.py maps them back exactly), plus
    ``temp_coeff_per_c · ΔT(t)`` on every gauge and on the reference (so subtracting ``ref``
    removes it), plus independent white noise ``noise_sd``. ``ΔT(t) = temp_drift_c ·
    sin(2π t / temp_period_s + φ)`` with φ drawn from the block's seed. AuNP films have a
    temperature coefficient of resistance of order −1e-3/°C; with the default sensitivities a 0.5 °C
    drift moves the uncompensated Fz by ~0.05 N, a quarter of a touch, which is why the reference
    gauge exists. ``noise_sd = 1e-5`` gives ≈ 0.7 mN RMS on Fx/Fy and 0.5 mN on Fz after eq. 2
    (1.1 mN on Fz once the reference, with its own noise, is subtracted from every gauge).
    The paper gives neither sensitivities, temperature coefficient nor noise: these are
    order-of-magnitude assumptions.

    *Touch* (Fig. 4.1): a probe adds ``ΔFz = stiffness_n_per_mm · indentation_um/1000`` on top of
    ``baseline_n``: a raised-cosine loading ramp of ``ramp_s``, a plateau of ``hold_s`` and an
    unloading ramp of ``unload_s`` (20 µm in 10 ms is a 2 mm/s probe; the unloading is slower,
    as the PDMS recovers viscoelastically). The default stiffness is that of a PDMS (Sylgard 184,
    E ≈ 1.6 MPa) cylinder of 2 mm diameter and 0.5 mm height, k = E·A/L ≈ 10 N/mm, so the paper's
    20 µm indentation adds ≈ 0.2 N (the paper does not give the bump's geometry or force).
    The probe also loads the bump tangentially (a slightly tilted or off-centre probe bends the
    bump; ``shear_ratio`` of the added normal load, in direction ``shear_angle_deg``). That
    tangential force follows a stick/creep-then-release hysteresis: while loading, the contact sticks
    and the shear builds with the viscoelastic creep of the PDMS, lagging the normal force
    (raised-cosine rise over ``shear_rise_s`` > ``ramp_s``); at unloading the contact pressure
    drops, the stuck contact lets go and the shear stored in the bump springs back elastically,
    without the creep lag, within ``shear_release_s`` (a few ms), faster than the normal force
    unloads. The tangential force never exceeds ``friction_mu`` times the probe's normal load.

    Why it is shaped so: Table I's FA1 drive is linear in F and F' with w6 = +0.024 on Fz' and
    w4 = −0.012 on Fx'. At unloading Fz' < 0 can only inhibit FA1; the fast release of a positive
    Fx (Fx' ≪ 0, so −0.012·Fx' > 0) is what can give FA1 an offset transient (Fig. 4), while the
    slow build-up keeps −0.012·Fx' small during loading so that the +0.024·Fz' onset transient
    stands. The offset kick integrates to 0.012·ΔFx, the onset kick to 0.024·ΔFz: with a
    tangential force bounded by friction, the offset response needs a large ``shear_ratio`` (0.8)
    and a release much faster than the unloading. Noise-free Table I drives with the defaults
    (5-point centred derivative): FA1 0.054 at rest, peak 0.85 at onset, 0.37 on the plateau, peak
    1.09 at offset, down to −0.16 during the rest of the unloading; SA1 0.046 at rest, 0.19 on the
    plateau (0.24 briefly at offset), no onset overshoot: SA1's extra onset activity must come from
    the neuron model's adaptation, not from the force.

    *Slip* (Fig. 4.2): the flat probe adds the same ΔFz over ``ramp_s``; then drags: the
    tangential force builds over ``drag_s`` (raised cosine, direction ``shear_angle_deg``) up to the
    traction limit ``friction_mu · Fz`` (eq. 4, with Fz the total normal force the sensor
    measures). At that instant the probe slips for ``slip_s`` (≈ 260 ms): the tangential magnitude
    falls to the kinetic level ``kinetic_ratio · friction_mu · Fz`` while its direction turns by
    ``slip_turn_deg`` (180° = the shear reverses through the perpendicular axis: the "marked change
    of direction" of the paper). The contact then sticks again, holds for ``hold_s`` and the probe
    lifts (every force back to baseline over ``unload_s``). |F_xy| ≤ μs·Fz at every sample.

    *Rest*: the baseline normal force only (plus drift and noise).

    Profiles are analytic functions of the sample time ``t = i / rate_hz`` (an integer counter),
    C¹ (raised cosines), so derivatives are meaningful. Trials repeat every ``period_s``. Noise and
    the drift phase come from generators spawned from the block's seed; all outputs share them,
    so the signals do not depend on which outputs are demanded (undemanded ones are not built).
    State: the sample counter and the noise generator. No latency.

    Example
    -------
    >>> from flowtact.testing import run_source
    >>> out = run_source(AunpSensor(scenario="touch", hold_s=0.3), 0.8)
    >>> out["force"].data.shape, round(float(out["force"].data[:, 2].max()), 2)
    ((800, 3), 0.32)
    """

    config_cls = AunpSensorConfig
    outputs = {
        "r": ft.Port(
            shape=(4,),
            units="1",
            rate="rate_hz",
            labels=("r1", "r2", "r3", "r4"),
            doc="ΔR/R of gauges 1..4 (eq. 2 layout: gauges 1 and 3 on the x axis, 2 and 4 on the y axis), "
            "including the common temperature term and white noise",
        ),
        "ref": ft.Port(
            shape=(),
            units="1",
            rate="rate_hz",
            doc="ΔR/R of the reference gauge: no strain, the same temperature term, its own noise",
        ),
        "temp_c": ft.Port(shape=(), units="degC", rate="rate_hz", doc="the sensor temperature"),
        "force": ft.Port(
            shape=(3,),
            units="N",
            rate="rate_hz",
            labels=("Fx", "Fy", "Fz"),
            doc="the TRUE force on the bump, for evaluation (noise- and drift-free)",
        ),
    }

    def reset(self) -> None:
        self.i = 0
        noise_rng, temp_rng = self.rng.spawn(2)
        self.noise_rng = noise_rng
        self.temp_phase = float(temp_rng.uniform(0.0, 2.0 * np.pi))
        self._scenario = SCENARIOS[self.config.scenario]
        self._p = trial_constants(self.config, self.temp_phase)
        self._noise, self._noise_i = _NO_NOISE, 0

    def _normals(self, n: int) -> np.ndarray:
        """The next ``n`` rows of the noise stream (gauges 1..4, reference), from rows drawn ahead."""
        i = self._noise_i
        if i + n > self._noise.shape[0]:
            fresh = self.noise_rng.standard_normal((max(n, NOISE_AHEAD), 5))
            self._noise, i = np.concatenate([self._noise[i:], fresh]), 0
        self._noise_i = i + n
        return self._noise[i : i + n]

    def step(self, now: float) -> dict[str, ft.Chunk]:
        c = self.config
        n = max(self.due(now, c.rate_hz) - self.i, 0)
        want = self.demanded
        noisy = "r" in want or "ref" in want
        noise = self._normals(n) if noisy else _NO_NOISE
        t, f, r, ref, temp = sensor_samples(self.i, n, c.rate_hz, self._scenario, self._p, noise)
        self.i += n
        made = {"r": r, "ref": ref, "temp_c": temp, "force": f}
        return {k: ft.Chunk(t, made[k]) for k in self.outputs if k in want}

    @classmethod
    def example(cls) -> ft.Example:
        return ft.Example(params={"scenario": "touch", "onset_s": 0.1, "hold_s": 0.3}, duration_s=0.8)
