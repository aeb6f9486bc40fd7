"""The remote gripper (the tactile Model-O, T-MO) and the object it grasps, for the emulated teleop loop.

White 2023 grasps a soft plush strawberry and a firm water bottle with the T-MO (§4.2.3, Fig. 4.5);
this block stands in for both: gripper commands in, true contact forces out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

import flowtact.api as ft

from .hand import FINGERS, N_FINGERS

__all__ = ["GraspSim", "GraspSimConfig", "grasp_sim_apply", "object_index"]


def object_index(t: np.ndarray, n_objects: int, period_s: float, swap_at_s: float) -> np.ndarray:
    """Index of the object in hand at times ``t``: object 0 until the first swap, then the next in turn.

    Swaps happen at ``swap_at_s``, ``swap_at_s + period_s``, … (with ``swap_at_s = 0`` the first one
    is at ``period_s``).
    """
    k = np.floor((np.asarray(t, np.float64) - swap_at_s) / period_s) + (1.0 if swap_at_s > 0 else 0.0)
    return np.mod(k, n_objects)


def grasp_sim_apply(
    t: np.ndarray,
    u: np.ndarray,
    obj: np.ndarray,
    state: np.ndarray,
    prev_t: float,
    stiffness: np.ndarray,
    contact: np.ndarray,
    tau_s: float,
    damping: float,
    max_force: float,
    dt0: float,
) -> tuple[np.ndarray, float]:
    """The gripper and object, sample by sample; ``state`` (3,) closures, updated in place.

    closure += (1 − e^(−Δt/τ))·(u − closure), then limited to contact + max_force/k (the motor's
    torque limit against the object); F = k·max(0, closure − contact) + damping·(penetration
    rate), clipped to [0, max_force]. Δt from the timestamps (``dt0`` for the first sample);
    a non-increasing stamp leaves the closure in place. Returns (forces (n, 3), prev_t).
    """
    n = len(t)
    f = np.empty((n, N_FINGERS))
    for k in range(n):
        tk = float(t[k])
        dt = dt0 if not math.isfinite(prev_t) else tk - prev_t
        a = -math.expm1(-dt / tau_s) if dt > 0.0 else 0.0
        if dt > 0.0:
            prev_t = tk
        stiff = float(stiffness[int(obj[k])])
        for i in range(N_FINGERS):
            c_old = float(state[i])
            c = c_old + a * (float(u[k, i]) - c_old)
            c = min(c, float(contact[i]) + max_force / stiff)
            state[i] = c
            pen = c - float(contact[i])
            if pen <= 0.0:
                f[k, i] = 0.0
                continue
            force = stiff * pen
            if damping > 0.0 and dt > 0.0:
                force += damping * (c - max(c_old, float(contact[i]))) / dt
            f[k, i] = min(max(force, 0.0), max_force)
    return f, prev_t


@dataclass(frozen=True)
class GraspSimConfig(ft.BadDataConfig):
    """Parameters of :class:`GraspSim`."""

    object_names: tuple[str, ...] = ft.param(
        ("strawberry", "bottle"), doc="the objects grasped in turn", min_len=1
    )
    stiffness_n: tuple[float, ...] = ft.param(
        (4.0, 40.0), doc="stiffness of each object, N per unit of gripper closure", min_len=1, gt=0
    )
    contact: tuple[float, ...] = ft.param(
        (0.45, 0.45, 0.45),
        doc="closure at which each finger (thumb, index, middle) touches the object",
        min_len=3,
        max_len=3,
        ge=0,
        le=1,
    )
    tau_s: float = ft.param(0.15, doc="time constant of a gripper finger following its command, s", gt=0)
    damping_n_s: float = ft.param(0.0, doc="object damping, N·s per unit closure (0: purely elastic)", ge=0)
    max_force_n: float = ft.param(6.0, doc="contact force at which the gripper's motors stall, N", gt=0)
    period_s: float = ft.param(5.0, doc="time between object swaps (one grasp per period), s", gt=0)
    swap_at_s: float = ft.param(
        0.0, doc="time within each period at which the next object is put in hand, s", ge=0
    )

    def check(self) -> None:
        if len(self.stiffness_n) != len(self.object_names):
            raise self.error(
                "stiffness_n",
                f"needs one value per object ({len(self.object_names)}: {', '.join(self.object_names)}); "
                f"got {len(self.stiffness_n)}",
            )
        if self.swap_at_s >= self.period_s:
            raise self.error("swap_at_s", f"must be < period_s ({self.period_s:g}); got {self.swap_at_s:g}")


class GraspSim(ft.Block):
    """Simulated T-MO gripper closing on an object: gripper command in, true contact force per finger out.

    Config
    ------
    See :class:`GraspSimConfig`. Defaults: a soft "strawberry" (4 N per unit closure) and a firm
    "bottle" (40 N per unit closure) alternating every 5 s, touched at closure 0.45.

    Notes
    -----
    Each gripper finger's closure follows its command with a first-order lag (``tau_s``; exact for
    a command held over each interval, on the samples' own timestamps). The object touches finger
    i at closure ``contact[i]`` and pushes back elastically: F = k·max(0, closure − contact)
    (+ ``damping_n_s`` × penetration rate, off by default), so the same closing command gives a
    soft object a smaller force and a deeper squeeze — the root of the thesis' Fig. 4.6 effect. The
    gripper's motors stall at ``max_force_n``: the closure stops at contact + max_force/k (the
    thesis tightens each grasp "until the motors in the T-MO reach their maximum torque").
    Objects: ``object_names[j]`` with ``stiffness_n[j]``, in turn; the next one is put in hand at
    ``swap_at_s`` into each period (the exoskeleton emulator's simulated user grasps once per
    period, so choose a swap time at which that hand is open; a swap during a grasp changes the
    force at once). ``object`` gives the index per sample, so analyses can split by object.
    A plain transform (no loop delay: that sits at the serial_io block): one output per command
    sample, at its time; commands outside [0, 1] are clipped (counted ``clipped``). Pure and
    deterministic; a sequential per-sample loop, so chunking never changes a bit. State: the three
    closures (starting open, 0) and the last timestamp. ``end`` is passed on.

    Example
    -------
    >>> import numpy as np
    >>> from flowtact.blocks.teleop.grasp_sim import GraspSim
    >>> from flowtact.testing import run_offline
    >>> grip = np.full((300, 3), 0.6)                     # 3 s closed to 0.6 on the strawberry
    >>> out = run_offline(GraspSim(), grip=grip, rate_hz=100.0)
    >>> np.round(out["force"].data[-1], 3).tolist()       # 4 N × (0.6 − 0.45)
    [0.6, 0.6, 0.6]
    """

    config_cls = GraspSimConfig
    inputs = {
        "grip": ft.Port(
            dtype="float64",
            shape=(3,),
            units="1",
            require_rate=True,
            doc="gripper command per finger, 0 open … 1 closed",
        )
    }
    outputs = {
        "force": ft.Port(
            dtype="float64", shape=(3,), units="N", labels=FINGERS, doc="true contact force at each fingertip"
        ),
        "object": ft.Port(
            dtype="float64",
            shape=(),
            units="1",
            categories="object_names",
            doc="index into object_names of the object in hand",
        ),
    }
    counter_docs = {
        "clipped": "command samples with a finger outside [0, 1] (beyond open or closed): clipped into range",
        **ft.nonfinite_counter_docs("command samples on 'grip'"),
    }

    def reset(self) -> None:
        cfg = self.config
        self._state = np.zeros(N_FINGERS)
        self._prev_t = -math.inf
        self._dt0 = 1.0 / float(self.input_specs["grip"].rate_hz or 1.0)
        self._stiff = np.asarray(cfg.stiffness_n, np.float64)
        self._contact = np.asarray(cfg.contact, np.float64)
        self._last: np.ndarray | None = None

    def step(self, grip: ft.Chunk) -> dict[str, ft.Chunk]:
        cfg = self.config
        grip, self._last = ft.screen_nonfinite(self, grip, cfg.on_bad_data, "grip", self._last)
        u = grip.data
        outside = (u < 0.0) | (u > 1.0)
        if outside.any():
            self.count("clipped", int(outside.any(axis=1).sum()))
            u = np.clip(u, 0.0, 1.0)
        obj = object_index(grip.t, len(cfg.object_names), cfg.period_s, cfg.swap_at_s)
        f, self._prev_t = grasp_sim_apply(
            grip.t, u, obj, self._state, self._prev_t, self._stiff, self._contact,
            cfg.tau_s, cfg.damping_n_s, cfg.max_force_n, self._dt0,
        )  # fmt: skip
        out = {}
        if "force" in self.demanded:
            out["force"] = ft.Chunk(grip.t, f, grip.end)
        if "object" in self.demanded:
            out["object"] = ft.Chunk(grip.t, obj, grip.end)
        return out

    @classmethod
    def example(cls) -> ft.Example:
        n = 200  # 2 s at 100 Hz, objects swapped every second: grasp, release, grasp
        t = np.arange(n) / 100.0
        grasp = np.clip(np.sin(2 * np.pi * t), 0.0, 1.0)
        grip = np.outer(grasp, [0.7, 0.8, 0.75])
        grip[150, 0] = 1.2  # out of range: clipped
        return ft.Example(params={"period_s": 1.0, "damping_n_s": 0.5}, inputs={"grip": grip}, rate_hz=100.0)
