"""The setpoints of PX4's auto modes (FlightTaskAuto): jerk-limited trajectories to a target.

PX4 never steps an auto-mode setpoint: its position smoothing flies a jerk-limited (MPC_JERK_AUTO)
trajectory, accelerating at most MPC_ACC_HOR (MPC_ACC_UP_MAX / MPC_ACC_DOWN_MAX vertically), at
most MPC_XY_CRUISE (MPC_Z_V_AUTO_UP / _DN) fast, and slowing down so that it can stop at the
target: the speed allowed at distance d is PX4's `computeMaxSpeedFromDistance`. `AutoTrajectory`
is that smoothing in compact form, per axis group (horizontal as one vector, vertical alone):
the desired velocity is steered with an acceleration that can be ramped to zero in time
(a <= sqrt(2 j |dv|)), and the acceleration changes at most by the jerk limit. It outputs
position, velocity and acceleration setpoints that PX4's position controller tracks. Frames NED.
"""

from __future__ import annotations

import math

import numpy as np

from hil.vehicle.params import VehicleSimParams
from hil.vehicle.px4_controller import TrajectorySetpoint


def max_speed_from_distance_mps(
    jerk_mps3: float, accel_mps2: float, distance_m: float, final_speed_mps: float = 0.0
) -> float:
    """PX4 trajectory::computeMaxSpeedFromDistance: fastest speed that still stops in time.

    Solves v^2 + (4 a^2 / j) v - (2 a d + v_f^2) = 0 for v.
    """
    b = 4.0 * accel_mps2 * accel_mps2 / jerk_mps3
    c = -2.0 * accel_mps2 * max(distance_m, 0.0) - final_speed_mps * final_speed_mps
    return 0.5 * (-b + math.sqrt(b * b - 4.0 * c))


def braking_distance_m(jerk_mps3: float, accel_mps2: float, speed_mps: float) -> float:
    """The inverse of `max_speed_from_distance_mps`: distance to stop from `speed_mps`, m."""
    b = 4.0 * accel_mps2 * accel_mps2 / jerk_mps3
    return (speed_mps * speed_mps + b * speed_mps) / (2.0 * accel_mps2)


def _steer(
    velocity: np.ndarray,
    acceleration: np.ndarray,
    desired: np.ndarray,
    accel_max: float,
    jerk: float,
    dt_s: float,
) -> tuple[np.ndarray, np.ndarray]:
    """One jerk-limited step of (velocity, acceleration) towards `desired` velocity."""
    dv = desired - velocity
    norm = float(np.linalg.norm(dv))
    if norm > 1e-9:
        wanted = dv / norm * min(accel_max, math.sqrt(2.0 * jerk * norm))
    else:
        wanted = np.zeros_like(dv)
    da = wanted - acceleration
    da_norm = float(np.linalg.norm(da))
    step = jerk * dt_s
    acceleration = acceleration + (da * (step / da_norm) if da_norm > step else da)
    return velocity + acceleration * dt_s, acceleration


class AutoTrajectory:
    """PX4 FlightTaskAuto's smoothed setpoints towards a target position (or climb rate)."""

    def __init__(self, params: VehicleSimParams) -> None:
        self._p = params
        self.position_ned_m = np.zeros(3)
        self.velocity_ned_mps = np.zeros(3)
        self.acceleration_ned_mps2 = np.zeros(3)

    def reset(self, position_ned_m: np.ndarray, velocity_ned_mps: np.ndarray) -> None:
        """Start the trajectory at the vehicle's state (mode entry, on the ground)."""
        self.position_ned_m = np.array(position_ned_m, dtype=float)
        self.velocity_ned_mps = np.array(velocity_ned_mps, dtype=float)
        self.acceleration_ned_mps2 = np.zeros(3)

    def stopping_point(self) -> np.ndarray:
        """Where the trajectory stops if braked now (PX4 Loiter's braking position), NED m."""
        p = self._p
        v = self.velocity_ned_mps
        speed = float(np.hypot(v[0], v[1]))
        stop = self.position_ned_m.copy()
        if speed > 1e-3:
            d = braking_distance_m(p.jerk_auto_mps3, p.acc_hor_mps2, speed)
            stop[:2] += v[:2] / speed * d
        if abs(v[2]) > 1e-3:
            acc = p.acc_down_max_mps2 if v[2] > 0.0 else p.acc_up_max_mps2
            stop[2] += math.copysign(braking_distance_m(p.jerk_auto_mps3, acc, abs(v[2])), v[2])
        return stop

    def update(
        self,
        dt_s: float,
        target_ned_m: np.ndarray,
        yaw_rad: float,
        *,
        speed_xy_mps: float | None = None,
        speed_up_mps: float | None = None,
        speed_down_mps: float | None = None,
        climb_rate_mps: float | None = None,
        accel_z_mps2: float | None = None,
    ) -> TrajectorySetpoint:
        """Advance `dt_s` towards `target_ned_m` (z NaN: fly `climb_rate_mps`, down positive).

        `accel_z_mps2` replaces MPC_ACC_UP_MAX / MPC_ACC_DOWN_MAX (PX4's takeoff accelerates at
        MPC_TKO_SPEED / MPC_TKO_RAMP_T).
        """
        p = self._p
        acc_up = p.acc_up_max_mps2 if accel_z_mps2 is None else accel_z_mps2
        acc_down = p.acc_down_max_mps2 if accel_z_mps2 is None else accel_z_mps2
        xy_max = p.xy_cruise_mps if speed_xy_mps is None else speed_xy_mps
        up_max = p.z_vel_auto_up_mps if speed_up_mps is None else speed_up_mps
        down_max = p.z_vel_auto_dn_mps if speed_down_mps is None else speed_down_mps
        # horizontal: towards the target, slowing to stop on it
        to_target = target_ned_m[:2] - self.position_ned_m[:2]
        distance = float(np.hypot(*to_target))
        desired_xy = np.zeros(2)
        if distance > 1e-4:
            speed = min(
                xy_max, max_speed_from_distance_mps(p.jerk_auto_mps3, p.acc_hor_mps2, distance)
            )
            desired_xy = to_target / distance * speed
        vel_xy, acc_xy = _steer(
            self.velocity_ned_mps[:2],
            self.acceleration_ned_mps2[:2],
            desired_xy,
            p.acc_hor_mps2,
            p.jerk_auto_mps3,
            dt_s,
        )
        # vertical: to the target altitude, or at a climb rate
        vz = self.velocity_ned_mps[2]
        if math.isfinite(target_ned_m[2]):
            dz = target_ned_m[2] - self.position_ned_m[2]
            acc = acc_down if dz > 0.0 else acc_up
            limit = down_max if dz > 0.0 else up_max
            desired_z = math.copysign(
                min(limit, max_speed_from_distance_mps(p.jerk_auto_mps3, acc, abs(dz))), dz
            )
        else:
            desired_z = float(np.clip(climb_rate_mps or 0.0, -up_max, down_max))
        acc_z_max = acc_down if desired_z > vz else acc_up
        vel_z, acc_z = _steer(
            np.array([vz]),
            self.acceleration_ned_mps2[2:],
            np.array([desired_z]),
            acc_z_max,
            p.jerk_auto_mps3,
            dt_s,
        )
        velocity = np.array([*vel_xy, vel_z[0]])
        self.position_ned_m = self.position_ned_m + 0.5 * (self.velocity_ned_mps + velocity) * dt_s
        self.velocity_ned_mps = velocity
        self.acceleration_ned_mps2 = np.array([*acc_xy, acc_z[0]])
        position = self.position_ned_m.copy()
        if not math.isfinite(target_ned_m[2]):
            position[2] = math.nan
        return TrajectorySetpoint(
            position_ned_m=position,
            velocity_ned_mps=velocity.copy(),
            acceleration_ned_mps2=self.acceleration_ned_mps2.copy(),
            yaw_rad=yaw_rad,
        )
