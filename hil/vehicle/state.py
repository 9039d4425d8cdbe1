"""The simulated vehicle's ground truth: one immutable `RigidBodyState` per step."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from geometry.rotation import euler_from_quaternion, rotation_from_quaternion


@dataclass(frozen=True)
class RigidBodyState:
    """Ground truth at `time_s` (simulated seconds since boot). Arrays are read-only copies.

    position_ned_m (3,) NED m, z = 0 at home ground; velocity_ned_mps (3,); acceleration_ned_mps2
    (3,) kinematic acceleration; attitude_wxyz (4,) unit quaternion body FRD -> NED;
    angular_velocity_frd_radps (3,); thrust_n collective thrust, N; on_ground: in ground contact.
    """

    time_s: float
    position_ned_m: np.ndarray
    velocity_ned_mps: np.ndarray
    acceleration_ned_mps2: np.ndarray
    attitude_wxyz: np.ndarray
    angular_velocity_frd_radps: np.ndarray
    thrust_n: float
    on_ground: bool
    wind_ned_mps: np.ndarray

    def rotation_ned_from_frd(self) -> np.ndarray:
        """(3, 3) R with v_ned = R @ v_frd."""
        return rotation_from_quaternion(self.attitude_wxyz)

    def euler_rad(self) -> tuple[float, float, float]:
        """(roll, pitch, yaw), rad, Z-Y-X."""
        return euler_from_quaternion(self.attitude_wxyz)

    @property
    def yaw_rad(self) -> float:
        """Heading, rad, 0 = north, positive clockwise seen from above."""
        return self.euler_rad()[2]

    @property
    def tilt_rad(self) -> float:
        """Angle between body z and world down, rad."""
        return math.acos(float(np.clip(self.rotation_ned_from_frd()[2, 2], -1.0, 1.0)))


def frozen(a: np.ndarray | list[float] | tuple[float, ...]) -> np.ndarray:
    """A read-only float copy of `a`."""
    out = np.array(a, dtype=float)
    out.flags.writeable = False
    return out
