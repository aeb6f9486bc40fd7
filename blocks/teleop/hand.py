"""The three instrumented fingers of the teleoperation rig, in the order every teleop stream uses."""

from __future__ import annotations

__all__ = ["FINGERS", "N_FINGERS"]

#: Axis 0 of every teleop stream (frames, forces, angles, servo commands) follows this order.
FINGERS: tuple[str, str, str] = ("thumb", "index", "middle")
N_FINGERS = len(FINGERS)
