"""A cascaded multicopter controller shaped like PX4's: position P -> velocity PID ->
acceleration -> thrust vector and attitude -> body rates -> angular acceleration.

Mirrors PX4's `PositionControl` (mc_pos_control), `AttitudeControl` (mc_att_control) and the
rate loop, with PX4's NaN semantics: a NaN position or velocity component means "this axis is
not controlled by that term". Frames: world NED, body FRD; thrust is normalised (1 = max).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from hil.attitude import (
    quaternion_conjugate,
    quaternion_multiply,
    wrap_pi,
)
from hil.params import VehicleSimParams
from mapping.pose import quaternion_from_rotation, rotation_from_quaternion

GRAVITY_MPS2 = 9.80665


def _nan3() -> np.ndarray:
    return np.full(3, np.nan)


@dataclass(frozen=True)
class TrajectorySetpoint:
    """What the controller tracks (PX4's trajectory_setpoint). NaN = not controlled.

    position_ned_m (3,) NED m; velocity_ned_mps (3,) NED m/s, a feed-forward when the position
    is set on that axis; yaw_rad NaN holds the current heading (or integrates yaw_rate_radps);
    the *_max_* fields tighten the configured velocity limits for auto modes (NaN: defaults).
    """

    position_ned_m: np.ndarray = field(default_factory=_nan3)
    velocity_ned_mps: np.ndarray = field(default_factory=_nan3)
    yaw_rad: float = math.nan
    yaw_rate_radps: float = math.nan
    speed_max_xy_mps: float = math.nan
    speed_max_up_mps: float = math.nan
    speed_max_down_mps: float = math.nan


@dataclass(frozen=True)
class ControlOutput:
    """Normalised collective thrust (0..1) and body angular acceleration command, FRD rad/s^2."""

    thrust: float
    angular_accel_frd_radps2: np.ndarray
    attitude_setpoint_wxyz: np.ndarray
    velocity_setpoint_ned_mps: np.ndarray


def _limit_tilt(body_z: np.ndarray, tilt_max_rad: float) -> np.ndarray:
    """body_z (unit, NED, pointing down through the body) tilted at most tilt_max from +z."""
    cos_tilt = float(np.clip(body_z[2], -1.0, 1.0))
    tilt = math.acos(cos_tilt)
    if tilt <= tilt_max_rad:
        return body_z
    horizontal = np.array([body_z[0], body_z[1], 0.0])
    norm = float(np.linalg.norm(horizontal))
    if norm < 1e-9:
        return np.array([0.0, 0.0, 1.0])
    return np.array(
        [
            math.sin(tilt_max_rad) * horizontal[0] / norm,
            math.sin(tilt_max_rad) * horizontal[1] / norm,
            math.cos(tilt_max_rad),
        ]
    )


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b of (3,) vectors (np.cross is slow for single vectors)."""
    return np.array(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )


def attitude_from_body_z(body_z: np.ndarray, yaw_rad: float) -> np.ndarray:
    """Quaternion (w, x, y, z) whose body z axis is `body_z` (NED) with heading `yaw_rad`.

    PX4 ControlMath::bodyzToAttitude: x_b = y_C × z_b with y_C the yaw direction turned 90°.
    """
    y_c = np.array([-math.sin(yaw_rad), math.cos(yaw_rad), 0.0])
    body_x = _cross(y_c, body_z)
    if body_z[2] < 0.0:
        body_x = -body_x
    body_x /= np.linalg.norm(body_x)
    body_y = _cross(body_z, body_x)
    return quaternion_from_rotation(np.column_stack([body_x, body_y, body_z]))


class PositionController:
    """PX4 PositionControl: position P, velocity PID with anti-windup, acceleration -> thrust.

    The velocity setpoint is slew-limited by MPC_ACC_HOR_MAX / MPC_ACC_UP_MAX /
    MPC_ACC_DOWN_MAX (the smoothing of PX4's flight tasks), so a step command never asks for
    more than those accelerations plus the tracking correction.
    """

    def __init__(self, params: VehicleSimParams) -> None:
        self._p = params
        self._vel_int = np.zeros(3)
        self._vel_sp_smooth = _nan3()
        self._acc_ff = np.zeros(3)

    def reset(self) -> None:
        """Forget integrators and the smoothed setpoint (after a reset or on the ground)."""
        self._vel_int[:] = 0.0
        self._vel_sp_smooth = _nan3()
        self._acc_ff = np.zeros(3)

    def velocity_setpoint(
        self, setpoint: TrajectorySetpoint, position_ned_m: np.ndarray
    ) -> np.ndarray:
        """(3,) velocity setpoint, NED m/s, NaN on uncontrolled axes, limited but not smoothed."""
        p = self._p
        gains = np.array([p.xy_pos_p, p.xy_pos_p, p.z_pos_p])
        error = setpoint.position_ned_m - position_ned_m
        from_position = error * gains
        # braking-aware cap: never faster than what stops on the target at MPC_ACC_HOR (auto)
        dist_xy = float(np.hypot(error[0], error[1]))
        if math.isfinite(dist_xy) and dist_xy > 1e-9:
            speed = float(np.hypot(from_position[0], from_position[1]))
            cap = math.sqrt(2.0 * p.acc_hor_mps2 * dist_xy)
            if speed > cap:
                from_position[:2] *= cap / speed
        if math.isfinite(error[2]):
            cap_z = math.sqrt(2.0 * min(p.acc_up_max_mps2, p.acc_down_max_mps2) * abs(error[2]))
            from_position[2] = np.clip(from_position[2], -cap_z, cap_z)
        ff = setpoint.velocity_ned_mps
        vel = np.where(np.isfinite(from_position), from_position, np.nan)
        vel = np.where(np.isfinite(vel) & np.isfinite(ff), vel + ff, vel)
        vel = np.where(np.isfinite(vel), vel, ff)
        xy_max = _min_finite(p.xy_vel_max_mps, setpoint.speed_max_xy_mps)
        up_max = _min_finite(p.z_vel_max_up_mps, setpoint.speed_max_up_mps)
        dn_max = _min_finite(p.z_vel_max_dn_mps, setpoint.speed_max_down_mps)
        if np.all(np.isfinite(vel[:2])):
            speed = float(np.hypot(vel[0], vel[1]))
            if speed > xy_max:
                vel[:2] *= xy_max / speed
        else:
            vel[:2] = np.clip(vel[:2], -xy_max, xy_max)
        vel[2] = np.clip(vel[2], -up_max, dn_max)
        return vel

    def _smoothed(
        self, vel_sp: np.ndarray, velocity_ned_mps: np.ndarray, dt_s: float
    ) -> np.ndarray:
        p = self._p
        previous = np.where(np.isfinite(self._vel_sp_smooth), self._vel_sp_smooth, velocity_ned_mps)
        out = vel_sp.copy()
        if np.all(np.isfinite(vel_sp[:2])):
            delta = vel_sp[:2] - previous[:2]
            norm = float(np.linalg.norm(delta))
            max_step = p.acc_hor_max_mps2 * dt_s
            out[:2] = previous[:2] + (delta * (max_step / norm) if norm > max_step else delta)
        if math.isfinite(vel_sp[2]):
            out[2] = previous[2] + np.clip(
                vel_sp[2] - previous[2], -p.acc_up_max_mps2 * dt_s, p.acc_down_max_mps2 * dt_s
            )
        self._acc_ff = np.where(np.isfinite(out), (out - previous) / dt_s, 0.0)
        self._vel_sp_smooth = out
        return out

    def update(
        self,
        dt_s: float,
        position_ned_m: np.ndarray,
        velocity_ned_mps: np.ndarray,
        acceleration_ned_mps2: np.ndarray,
        setpoint: TrajectorySetpoint,
    ) -> tuple[np.ndarray, np.ndarray]:
        """(thrust vector (3,) NED normalised, velocity setpoint (3,) NED m/s) for one step."""
        p = self._p
        vel_sp = self._smoothed(
            self.velocity_setpoint(setpoint, position_ned_m), velocity_ned_mps, dt_s
        )
        gain_p = np.array([p.xy_vel_p, p.xy_vel_p, p.z_vel_p])
        gain_i = np.array([p.xy_vel_i, p.xy_vel_i, p.z_vel_i])
        gain_d = np.array([p.xy_vel_d, p.xy_vel_d, p.z_vel_d])
        vel_error = vel_sp - velocity_ned_mps
        controlled = np.isfinite(vel_error)
        acc_sp = np.where(
            controlled,
            self._acc_ff + vel_error * gain_p + self._vel_int - acceleration_ned_mps2 * gain_d,
            0.0,
        )
        thrust, saturated_z = self._thrust_from_acceleration(acc_sp)
        # integrate only controlled axes; vertical anti-windup while thrust saturates (PX4)
        error = np.where(controlled, vel_error, 0.0)
        if saturated_z and error[2] * acc_sp[2] > 0.0:
            error[2] = 0.0
        self._vel_int += error * gain_i * dt_s
        self._vel_int[2] = np.clip(self._vel_int[2], -GRAVITY_MPS2, GRAVITY_MPS2)
        xy_int = float(np.linalg.norm(self._vel_int[:2]))
        xy_int_max = GRAVITY_MPS2 * math.tan(math.radians(p.tilt_max_air_deg))
        if xy_int > xy_int_max:
            self._vel_int[:2] *= xy_int_max / xy_int
        self._vel_int = np.where(controlled, self._vel_int, 0.0)
        return thrust, vel_sp

    def _thrust_from_acceleration(self, acc_sp: np.ndarray) -> tuple[np.ndarray, bool]:
        """PX4 _accelerationControl + thrust limits: (thrust vector, vertical saturated?)."""
        p = self._p
        body_z = np.array([-acc_sp[0], -acc_sp[1], GRAVITY_MPS2 - acc_sp[2]])
        norm = float(np.linalg.norm(body_z))
        body_z = body_z / norm if norm > 1e-9 else np.array([0.0, 0.0, 1.0])
        body_z = _limit_tilt(body_z, math.radians(p.tilt_max_air_deg))
        thrust_ned_z = acc_sp[2] * (p.hover_thrust / GRAVITY_MPS2) - p.hover_thrust
        collective = min(thrust_ned_z / body_z[2], -p.thr_min)
        thr = body_z * collective  # NED, pointing up (negative z) when hovering
        # vertical priority, horizontal takes the margin (PX4)
        saturated = False
        if -thr[2] > p.thr_max:
            thr[2] = -p.thr_max
            saturated = True
        elif -thr[2] < p.thr_min:
            thr[2] = -p.thr_min
            saturated = True
        xy_max = math.sqrt(max(p.thr_max**2 - thr[2] ** 2, 0.0))
        xy = float(np.hypot(thr[0], thr[1]))
        if xy > xy_max:
            thr[:2] *= xy_max / xy
        return thr, saturated


def _min_finite(default: float, override: float) -> float:
    return min(default, override) if math.isfinite(override) else default


class AttitudeController:
    """PX4 mc_att_control (quaternion P on the attitude error) and a rate P loop.

    The rate loop outputs an angular acceleration (torque / inertia) bounded by
    `max_angular_accel_radps2`, which is what the rigid body integrates.
    """

    def __init__(self, params: VehicleSimParams) -> None:
        self._p = params
        self._yaw_sp_rad = math.nan

    def reset(self, yaw_rad: float) -> None:
        """Latch the heading to hold when no yaw setpoint is given."""
        self._yaw_sp_rad = yaw_rad

    def yaw_setpoint(self, setpoint: TrajectorySetpoint, yaw_rad: float, dt_s: float) -> float:
        """Heading to track, rad: the commanded yaw, else the latched one advanced by yaw rate."""
        if not math.isfinite(self._yaw_sp_rad):
            self._yaw_sp_rad = yaw_rad
        if math.isfinite(setpoint.yaw_rad):
            self._yaw_sp_rad = setpoint.yaw_rad
        elif math.isfinite(setpoint.yaw_rate_radps):
            self._yaw_sp_rad = wrap_pi(self._yaw_sp_rad + setpoint.yaw_rate_radps * dt_s)
        return self._yaw_sp_rad

    def update(
        self,
        dt_s: float,
        attitude_wxyz: np.ndarray,
        angular_velocity_frd_radps: np.ndarray,
        thrust_ned: np.ndarray,
        setpoint: TrajectorySetpoint,
        yaw_rad: float,
    ) -> tuple[float, np.ndarray, np.ndarray]:
        """(collective thrust 0..1, angular accel FRD rad/s^2, attitude setpoint w,x,y,z)."""
        p = self._p
        yaw_sp = self.yaw_setpoint(setpoint, yaw_rad, dt_s)
        thrust_norm = float(np.linalg.norm(thrust_ned))
        body_z = -thrust_ned / thrust_norm if thrust_norm > 1e-9 else np.array([0.0, 0.0, 1.0])
        q_sp = attitude_from_body_z(body_z, yaw_sp)
        q_err = quaternion_multiply(quaternion_conjugate(attitude_wxyz), q_sp)
        sign = 1.0 if q_err[0] >= 0.0 else -1.0
        gains = np.array([p.roll_p, p.pitch_p, p.yaw_p])
        rate_sp = 2.0 * sign * q_err[1:] * gains
        yaw_rate_ff = setpoint.yaw_rate_radps if not math.isfinite(setpoint.yaw_rad) else 0.0
        if math.isfinite(yaw_rate_ff):
            # feed-forward about world down, expressed in body axes (PX4)
            rate_sp += rotation_from_quaternion(attitude_wxyz)[2, :] * yaw_rate_ff
        rp_max = math.radians(p.roll_rate_max_deg_s)
        yaw_max = math.radians(p.yaw_rate_max_deg_s)
        rate_sp = np.clip(rate_sp, [-rp_max, -rp_max, -yaw_max], [rp_max, rp_max, yaw_max])
        rate_gains = np.array([p.rate_p_rp, p.rate_p_rp, p.rate_p_yaw])
        ang_acc = np.clip(
            (rate_sp - angular_velocity_frd_radps) * rate_gains,
            -p.max_angular_accel_radps2,
            p.max_angular_accel_radps2,
        )
        return min(thrust_norm, p.thr_max), ang_acc, q_sp
