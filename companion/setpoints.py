"""Offboard setpoints, stamped with the time the planner produced them, and their mailbox.

The planner publishes into a `SetpointSource`; the link's streamer reads the latest one at the
setpoint rate and the watchdog judges it by its age (STYLE.md practice 2 and 6).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

import numpy as np


class SetpointKind(Enum):
    """Which SET_POSITION_TARGET_LOCAL_NED fields a setpoint controls."""

    VELOCITY = "velocity"  # velocity NED + yaw
    POSITION = "position"  # position NED + yaw


@dataclass(frozen=True)
class Setpoint:
    """One planner output for the autopilot, produced at `stamp_s` (monotonic, s).

    `vector_ned` is a velocity (m/s) for VELOCITY and a position (m) for POSITION, NED from the
    autopilot's local origin, shape (3,). `yaw_rad` is the heading in NED (0 north, positive
    clockwise); NaN means "keep the current heading" (the link fills in the measured yaw).
    """

    kind: SetpointKind
    vector_ned: np.ndarray
    yaw_rad: float
    stamp_s: float

    @classmethod
    def velocity(cls, velocity_ned_mps: np.ndarray, yaw_rad: float, stamp_s: float) -> Setpoint:
        """A velocity + yaw setpoint."""
        return cls(SetpointKind.VELOCITY, _vec3(velocity_ned_mps), float(yaw_rad), stamp_s)

    @classmethod
    def position(cls, position_ned_m: np.ndarray, yaw_rad: float, stamp_s: float) -> Setpoint:
        """A position + yaw setpoint."""
        return cls(SetpointKind.POSITION, _vec3(position_ned_m), float(yaw_rad), stamp_s)

    @classmethod
    def brake(cls, yaw_rad: float, stamp_s: float) -> Setpoint:
        """Zero velocity, holding `yaw_rad`."""
        return cls.velocity(np.zeros(3), yaw_rad, stamp_s)

    def with_yaw(self, yaw_rad: float) -> Setpoint:
        """This setpoint with its yaw replaced when it is NaN."""
        if not math.isnan(self.yaw_rad):
            return self
        return Setpoint(self.kind, self.vector_ned, float(yaw_rad), self.stamp_s)

    def age_s(self, now_s: float) -> float:
        """How old this planner output is at `now_s`, s."""
        return now_s - self.stamp_s


def _vec3(v: np.ndarray) -> np.ndarray:
    out = np.asarray(v, dtype=np.float64).reshape(3).copy()
    if not np.all(np.isfinite(out)):
        raise ValueError(f"setpoint vector must be finite, got {out}")
    out.setflags(write=False)
    return out


class SetpointSource:
    """The latest setpoint from the planner (a one-slot mailbox; newer replaces older)."""

    def __init__(self) -> None:
        self._latest: Setpoint | None = None
        self.published = 0

    def publish(self, setpoint: Setpoint) -> None:
        """Replace the latest setpoint."""
        self._latest = setpoint
        self.published += 1

    def latest(self) -> Setpoint | None:
        """The most recent setpoint, or None before the first."""
        return self._latest
