"""The AuNP sensor emulator's configuration: the trial it plays, the sensor's gains, drift and noise.

A module of its own so that the compiled sample kernel (:mod:`.aunp_samples`) and the block
(:mod:`.aunp_sensor`) both read it without importing each other.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import flowtact.api as ft

from .aunp import SENSITIVITY_PER_N

__all__ = ["AunpSensorConfig"]


@dataclass(frozen=True)
class AunpSensorConfig(ft.Config):
    scenario: Literal["touch", "slip", "rest"] = ft.param(
        "touch", doc="trial played: normal-force touch, tangential slip, or baseline load only"
    )
    rate_hz: float = ft.param(1000.0, doc="sample rate of every output (the paper samples at 1 kHz)", gt=0)
    baseline_n: float = ft.param(0.12, doc="normal force holding the sensor (the paper's 120 mN)", ge=0)
    indentation_um: float = ft.param(
        20.0, doc="indentation of the bump added by the probe (touch and slip)", ge=0
    )
    stiffness_n_per_mm: float = ft.param(
        10.0, doc="normal stiffness of the PDMS bump turning indentation into added Fz", gt=0
    )
    onset_s: float = ft.param(0.2, doc="time the probe starts loading the bump (first trial)", ge=0)
    ramp_s: float = ft.param(0.01, doc="duration of the raised-cosine normal loading ramp", gt=0)
    unload_s: float = ft.param(0.03, doc="duration of the raised-cosine normal unloading ramp", gt=0)
    hold_s: float = ft.param(
        0.5, doc="touch: plateau of the added normal force; slip: time held after the slip", ge=0
    )
    period_s: float = ft.param(2.0, doc="time between the onsets of repeated trials", gt=0)
    repeat: int = ft.param(1, doc="number of trials played (0 = repeat for ever)", ge=0)
    shear_ratio: float = ft.param(
        0.8, doc="touch: tangential/normal ratio of the probe load on the plateau (<= friction_mu)", ge=0
    )
    shear_angle_deg: float = ft.param(
        0.0, doc="direction in the x-y plane of the touch's tangential force and of the slip drag (0 = +x)"
    )
    shear_rise_s: float = ft.param(
        0.08, doc="touch: raised-cosine build-up time of the tangential force", gt=0
    )
    shear_release_s: float = ft.param(
        0.003, doc="touch: time the stored tangential force takes to spring back at unloading", gt=0
    )
    friction_mu: float = ft.param(1.0, doc="static friction coefficient of probe on PDMS (eq. 4, mu_s)", gt=0)
    kinetic_ratio: float = ft.param(0.6, doc="slip: kinetic/static friction ratio (mu_k / mu_s)", gt=0, le=1)
    drag_s: float = ft.param(0.3, doc="slip: tangential loading time from zero to the friction limit", gt=0)
    slip_s: float = ft.param(0.26, doc="slip: duration of the slip event (the paper's ~260 ms)", gt=0)
    slip_turn_deg: float = ft.param(
        180.0, doc="slip: rotation of the tangential force during the slip event", ge=-360, le=360
    )
    noise_sd: float = ft.param(1e-5, doc="white noise of each gauge and of the reference, in ΔR/R", ge=0)
    temp_drift_c: float = ft.param(0.5, doc="amplitude of the slow temperature drift (0 = off)", ge=0)
    temp_period_s: float = ft.param(20.0, doc="period of the temperature drift", gt=0)
    temp_coeff_per_c: float = ft.param(-1e-3, doc="temperature coefficient of every gauge, ΔR/R per °C")
    ambient_c: float = ft.param(25.0, doc="mean sensor temperature")
    sensitivity_per_n: tuple[float, ...] = ft.param(
        SENSITIVITY_PER_N,
        doc="gauge sensitivities (Xs, Ys, Zs) of eq. 2, ΔR/R per N",
        gt=0,
        min_len=3,
        max_len=3,
    )

    def trial_s(self) -> float:
        """Length of one trial from its onset until every force is back to baseline."""
        if self.scenario == "touch":
            return self.ramp_s + self.hold_s + max(self.unload_s, self.shear_release_s)
        if self.scenario == "slip":
            return self.ramp_s + self.drag_s + self.slip_s + self.hold_s + self.unload_s
        return 0.0

    def state_bytes(self) -> dict[str, float]:
        """A longest tick of output: 10 float64 channels (r, ref, temp_c, force) and a few scratch copies."""
        return {"rate_hz": self.rate_hz * ft.MAX_TICK_S * 8 * 10 * 4}

    def check(self) -> None:
        if self.shear_ratio > self.friction_mu:
            raise self.error(
                "shear_ratio",
                f"must be <= friction_mu ({self.friction_mu:g}): a stuck contact cannot carry more "
                f"tangential force than mu_s times its normal load; got {self.shear_ratio:g}",
            )
        if self.shear_release_s > self.unload_s:
            raise self.error(
                "shear_release_s",
                f"must be <= unload_s ({self.unload_s:g}): the tangential force cannot outlast the normal load "
                f"that holds it by friction; got {self.shear_release_s:g}",
            )
        if self.repeat != 1 and self.period_s < self.trial_s():
            raise self.error(
                "period_s",
                f"must be >= the length of one {self.scenario} trial ({self.trial_s():g} s) when trials "
                f"repeat; got {self.period_s:g}",
            )
