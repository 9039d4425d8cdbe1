"""The kinematic vehicle of the planning tests: it flies a `Setpoint` as an ideal autopilot
would, its velocity plus a unit-gain position loop (clipped at 1 m/s per axis) on the position
a POSITION, TRAJECTORY or planned BRAKE carries."""

import numpy as np

from planning.types import Setpoint


def flown_velocity(setpoint: Setpoint, position_ned_m: np.ndarray) -> np.ndarray:
    """(3,) NED velocity the kinematic vehicle at `position_ned_m` flies for `setpoint`, m/s."""
    velocity = setpoint.velocity_ned_mps
    if setpoint.position_ned_m is None:
        return velocity
    return velocity + np.clip(setpoint.position_ned_m - position_ned_m, -1.0, 1.0)
