"""The planner's and tracker's limits from the PX4 parameters of the vehicle they fly.

PX4 flies an offboard velocity setpoint through its velocity PID unsmoothed: how fast the vehicle
stops when the planner commands zero is set by MPC_XY_VEL_P/I/D_ACC, the tilt limit and the
airframe's drag, not by any constant of ours. `vehicle_limits(px4)` maps PX4's parameters
(read from the autopilot, `PX4_LIMIT_PARAMETERS`; PX4's defaults for the missing ones) to:
- speed, acceleration and jerk limits for the trajectory library: MPC_XY_VEL_MAX (capped by the
  cruise speed asked for), MPC_ACC_HOR within the tilt limit g tan(MPC_TILTMAX_AIR),
  MPC_JERK_AUTO, MPC_Z_VEL_MAX_UP/_DN, MPC_YAWRAUTO_MAX;
- `braking_distance_m(speed)`: the distance PX4's horizontal velocity loop covers in
  `BRAKING_HORIZON_S` after a zero setpoint, from a steady flight at `speed` (its integrator
  then holds the drag, and keeps pushing while it unwinds): the closed loop
  a_cmd = -P v + I - D dv/dt (|a_cmd| <= g tan(tilt)), lagged by the attitude response
  (1 / MC_ROLL_P), minus the drag k v, with I' = -I_gain v, integrated numerically;
- `planning_overrides()`: `PlanningParams` values whose braking formula (v^2 / 2a + v a / 2j,
  `planning.selection.braking_distance_m`) gives that distance at the top speed.
The drag per unit mass k comes from SIH_KDV / SIH_MASS when the autopilot is PX4's SIH simulator
(1.0 / s: strong), else `DEFAULT_DRAG_PER_S` (a 1-2 kg quadrotor, ~0.2 / s). Pure: no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

GRAVITY_MPS2 = 9.80665
BRAKING_HORIZON_S = 5.0
DEFAULT_DRAG_PER_S = 0.2
_STEP_S = 0.005

# PX4-Autopilot main defaults (multicopter) of the parameters read
PX4_LIMIT_DEFAULTS: dict[str, float] = {
    "MPC_XY_VEL_MAX": 12.0,
    "MPC_XY_CRUISE": 5.0,
    "MPC_ACC_HOR": 3.0,
    "MPC_JERK_AUTO": 4.0,
    "MPC_TILTMAX_AIR": 45.0,
    "MPC_Z_VEL_MAX_UP": 3.0,
    "MPC_Z_VEL_MAX_DN": 1.5,
    "MPC_YAWRAUTO_MAX": 60.0,
    "MPC_XY_VEL_P_ACC": 1.8,
    "MPC_XY_VEL_I_ACC": 0.4,
    "MPC_XY_VEL_D_ACC": 0.2,
    "MC_ROLL_P": 4.0,
}
# read when present: only PX4's SIH simulator has them
PX4_DRAG_PARAMETERS = ("SIH_KDV", "SIH_MASS")
PX4_LIMIT_PARAMETERS: tuple[str, ...] = (*PX4_LIMIT_DEFAULTS, *PX4_DRAG_PARAMETERS)


@dataclass(frozen=True)
class VehicleLimits:
    """What the vehicle can fly, from its PX4 parameters. Units in the names; NED horizontal."""

    max_speed_mps: float
    max_accel_mps2: float
    max_jerk_mps3: float
    max_vertical_speed_mps: float
    max_yaw_rate_radps: float
    velocity_p_per_s: float
    velocity_i_per_s2: float
    velocity_d: float
    attitude_time_constant_s: float
    tilt_max_rad: float
    drag_per_s: float

    def braking_distance_m(self, speed_mps: float | np.ndarray) -> np.ndarray:
        """Distance covered in BRAKING_HORIZON_S after a zero velocity setpoint from a steady
        flight at `speed_mps` (any shape), m."""
        v = np.asarray(speed_mps, dtype=np.float64).copy()
        k = self.drag_per_s
        a_max = GRAVITY_MPS2 * math.tan(self.tilt_max_rad)
        integral = k * v  # steady flight: the integrator holds the drag
        a_actual = np.zeros_like(v)
        a_prev = np.zeros_like(v)
        distance = np.zeros_like(v)
        alpha = min(_STEP_S / self.attitude_time_constant_s, 1.0)
        for _ in range(round(BRAKING_HORIZON_S / _STEP_S)):
            command = np.clip(
                -self.velocity_p_per_s * v + integral - self.velocity_d * a_prev, -a_max, a_max
            )
            a_actual += alpha * (command - a_actual)
            acceleration = a_actual - k * v
            integral -= self.velocity_i_per_s2 * v * _STEP_S
            v = v + acceleration * _STEP_S
            distance += v * _STEP_S
            a_prev = acceleration
        return distance

    def braking_accel_mps2(self, speed_mps: float) -> float:
        """The deceleration a for which v^2/(2a) + v a/(2j) (the planner's braking formula with
        j = max_jerk_mps3) equals `braking_distance_m(speed_mps)`, m/s^2 (at most max_accel)."""
        v, j = speed_mps, self.max_jerk_mps3
        d = float(self.braking_distance_m(v))
        # v a^2 / (2 j) - d a + v^2 / 2 = 0: the gentler root (the other needs a > sqrt(j v))
        disc = d * d - v**3 / j
        if v <= 0.0:
            return self.max_accel_mps2
        a = math.sqrt(j * v) if disc < 0.0 else (d - math.sqrt(disc)) * j / v
        return min(a, self.max_accel_mps2)

    def planning_overrides(self) -> dict[str, float]:
        """`PlanningParams` field values for this vehicle (`model_copy(update=...)`)."""
        return {
            "max_speed_mps": self.max_speed_mps,
            "max_accel_mps2": self.braking_accel_mps2(self.max_speed_mps),
            "max_jerk_mps3": self.max_jerk_mps3,
            "max_vertical_speed_mps": self.max_vertical_speed_mps,
            "max_yaw_rate_radps": self.max_yaw_rate_radps,
        }


def vehicle_limits(
    px4: Mapping[str, float | int | None], cruise_speed_mps: float | None = None
) -> VehicleLimits:
    """The limits of a vehicle with PX4 parameters `px4` (missing or None: PX4's defaults);
    `cruise_speed_mps` (the mission's) caps the top speed below MPC_XY_VEL_MAX."""
    p = {**PX4_LIMIT_DEFAULTS, **{k: float(v) for k, v in px4.items() if v is not None}}
    tilt = math.radians(p["MPC_TILTMAX_AIR"])
    speed = (
        p["MPC_XY_VEL_MAX"]
        if cruise_speed_mps is None
        else min(cruise_speed_mps, p["MPC_XY_VEL_MAX"])
    )
    mass, kdv = p.get("SIH_MASS"), p.get("SIH_KDV")
    drag = kdv / mass if mass and kdv is not None else DEFAULT_DRAG_PER_S
    return VehicleLimits(
        max_speed_mps=speed,
        max_accel_mps2=min(p["MPC_ACC_HOR"], GRAVITY_MPS2 * math.tan(tilt)),
        max_jerk_mps3=p["MPC_JERK_AUTO"],
        max_vertical_speed_mps=min(p["MPC_Z_VEL_MAX_UP"], p["MPC_Z_VEL_MAX_DN"]),
        max_yaw_rate_radps=math.radians(p["MPC_YAWRAUTO_MAX"]),
        velocity_p_per_s=p["MPC_XY_VEL_P_ACC"],
        velocity_i_per_s2=p["MPC_XY_VEL_I_ACC"],
        velocity_d=p["MPC_XY_VEL_D_ACC"],
        attitude_time_constant_s=1.0 / max(p["MC_ROLL_P"], 0.1),
        tilt_max_rad=tilt,
        drag_per_s=drag,
    )
