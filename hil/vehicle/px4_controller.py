"""PX4's multicopter position control (mc_pos_control), as PX4-Autopilot main runs it.

`PositionController` is PX4's `PositionControl`: position P -> velocity PID (the D term on the
low-passed derivative of the estimated velocity, MPC_VELD_LP) -> acceleration -> thrust vector
with tilt, thrust and horizontal-margin limits, vertical anti-windup and the horizontal tracking
anti-windup (Rundqwist). Setpoints are used as they come: PX4 does not smooth an offboard
setpoint, so a velocity step is a step of the PID's input. `TakeoffRamp` is PX4's
`TakeoffHandling` (spool-up, then the climb-speed limit ramped from idle thrust over
MPC_TKO_RAMP_T). NaN semantics as in PX4: a NaN position or velocity component is not
controlled by that term. Frames: world NED, body FRD; thrust normalised (1 = full).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np

from hil.vehicle.params import VehicleSimParams

GRAVITY_MPS2 = 9.80665


def _nan3() -> np.ndarray:
    return np.full(3, np.nan)


@dataclass(frozen=True)
class TrajectorySetpoint:
    """What the controller tracks (PX4's trajectory_setpoint). NaN = not controlled.

    position_ned_m (3,) NED m; velocity_ned_mps (3,) NED m/s, a feed-forward when the position
    is set on that axis; acceleration_ned_mps2 (3,) a feed-forward added to the PID's output
    (PX4 commands idle thrust on the ground with (0, 0, 100)); yaw_rad NaN holds the current
    heading, yaw_rate_radps is fed forward; the *_max_* fields tighten the configured velocity
    limits for auto modes (NaN: defaults).
    """

    position_ned_m: np.ndarray = field(default_factory=_nan3)
    velocity_ned_mps: np.ndarray = field(default_factory=_nan3)
    acceleration_ned_mps2: np.ndarray = field(default_factory=_nan3)
    yaw_rad: float = math.nan
    yaw_rate_radps: float = math.nan
    speed_max_xy_mps: float = math.nan
    speed_max_up_mps: float = math.nan
    speed_max_down_mps: float = math.nan


def _limit_tilt(bx: float, by: float, bz: float, tilt_max_rad: float) -> tuple[float, float, float]:
    """PX4 ControlMath::limitTilt: unit body_z (NED, down through the body) within tilt_max."""
    if math.acos(min(max(bz, -1.0), 1.0)) <= tilt_max_rad:
        return bx, by, bz
    horizontal = math.hypot(bx, by)
    if horizontal < 1e-9:
        return 0.0, 0.0, 1.0
    s = math.sin(tilt_max_rad) / horizontal
    return bx * s, by * s, math.cos(tilt_max_rad)


def _constrain_xy(
    v0x: float, v0y: float, v1x: float, v1y: float, max_norm: float
) -> tuple[float, float]:
    """PX4 ControlMath::constrainXY: v0 + v1 within max_norm, keeping v0 (the position term)."""
    tx, ty = v0x + v1x, v0y + v1y
    if math.hypot(tx, ty) <= max_norm:
        return tx, ty
    n0 = math.hypot(v0x, v0y)
    if n0 >= max_norm:
        return v0x * max_norm / n0, v0y * max_norm / n0
    if math.hypot(v1x, v1y) < 1e-3:
        return v0x, v0y
    # the largest s with |v0 + s v1| = max_norm
    a = v1x * v1x + v1y * v1y
    b = 2.0 * (v0x * v1x + v0y * v1y)
    c = n0 * n0 - max_norm * max_norm
    s = (-b + math.sqrt(max(b * b - 4.0 * a * c, 0.0))) / (2.0 * a)
    return v0x + s * v1x, v0y + s * v1y


class LowPassDerivative:
    """PX4's BlockDerivative: finite difference through a first-order low-pass (per axis)."""

    def __init__(self, cutoff_hz: float) -> None:
        self.cutoff_hz = cutoff_hz
        self._last: list[float] | None = None
        self._value = [0.0, 0.0, 0.0]

    def reset(self) -> None:
        """Forget the history (the next update returns zero)."""
        self._last = None
        self._value = [0.0, 0.0, 0.0]

    def update(self, x: list[float], dt_s: float) -> list[float]:
        """The filtered derivative of `x` (3 floats)."""
        last, self._last = self._last, list(x)
        if last is None:
            return list(self._value)
        alpha = dt_s / (dt_s + 1.0 / (2.0 * math.pi * self.cutoff_hz))
        v = self._value
        self._value = [v[i] + alpha * ((x[i] - last[i]) / dt_s - v[i]) for i in range(3)]
        return list(self._value)


@dataclass(frozen=True)
class ThrustSetpoint:
    """Output of one position-control step: thrust vector and what led to it (NED)."""

    thrust_ned: np.ndarray  # (3,) normalised, pointing up (negative z) when hovering
    velocity_setpoint_ned_mps: np.ndarray  # (3,) after limits, NaN where uncontrolled
    acceleration_setpoint_ned_mps2: np.ndarray  # (3,)

    @property
    def collective(self) -> float:
        """Length of the thrust vector, 0..1."""
        x, y, z = self.thrust_ned
        return math.sqrt(x * x + y * y + z * z)


class PositionController:
    """PX4 PositionControl with MulticopterPositionControl's state handling around it."""

    def __init__(self, params: VehicleSimParams) -> None:
        self._p = params
        self._vel_int = [0.0, 0.0, 0.0]
        self._vel_dot = LowPassDerivative(params.vel_deriv_cutoff_hz)
        self.tilt_limit_rad = math.radians(params.tilt_max_air_deg)
        self.thrust_min: float | None = None  # None: MPC_THR_MIN (PX4 ramps from 0 on takeoff)

    def reset(self) -> None:
        """Forget integrators and the derivative filter (after a reset or on the ground)."""
        self._vel_int = [0.0, 0.0, 0.0]
        self._vel_dot.reset()

    def seed_vertical_integral(self, acceleration_mps2: float) -> None:
        """Start the vertical integrator at `acceleration_mps2` (a vehicle placed hovering)."""
        self._vel_int[2] = acceleration_mps2

    def reset_integral(self) -> None:
        """PX4 resetIntegral (before takeoff, to prevent windup)."""
        self._vel_int = [0.0, 0.0, 0.0]

    @property
    def vertical_integral_mps2(self) -> float:
        """The vertical velocity integrator, m/s^2 (positive down)."""
        return self._vel_int[2]

    def velocity_setpoint(
        self, setpoint: TrajectorySetpoint, position_ned_m: np.ndarray
    ) -> np.ndarray:
        """PX4 _positionControl: (3,) velocity setpoint, NED m/s, NaN on uncontrolled axes."""
        return np.array(self._velocity_setpoint(setpoint, position_ned_m.tolist()))

    def _velocity_setpoint(self, setpoint: TrajectorySetpoint, pos: list[float]) -> list[float]:
        p = self._p
        gains = (p.xy_pos_p, p.xy_pos_p, p.z_pos_p)
        sp_pos = setpoint.position_ned_m.tolist()
        vel = setpoint.velocity_ned_mps.tolist()
        term = [0.0, 0.0, 0.0]
        for i in range(3):
            from_position = (sp_pos[i] - pos[i]) * gains[i]
            if math.isfinite(from_position):
                term[i] = from_position
                # feed-forward + position term; a NaN feed-forward is replaced by the term
                vel[i] = vel[i] + from_position if math.isfinite(vel[i]) else from_position
        xy_max = _min_finite(p.xy_vel_max_mps, setpoint.speed_max_xy_mps)
        up_max = _min_finite(p.z_vel_max_up_mps, setpoint.speed_max_up_mps)
        down_max = _min_finite(p.z_vel_max_dn_mps, setpoint.speed_max_down_mps)
        if math.isfinite(vel[0]) and math.isfinite(vel[1]):
            vel[0], vel[1] = _constrain_xy(
                term[0], term[1], vel[0] - term[0], vel[1] - term[1], xy_max
            )
        if math.isfinite(vel[2]):
            # math::constrain(v, -up, down): the lower bound wins when the takeoff ramp's
            # upward limit is negative (a descent that commands idle thrust)
            vel[2] = -up_max if vel[2] < -up_max else min(vel[2], down_max)
        return vel

    def update(
        self,
        dt_s: float,
        position_ned_m: np.ndarray | list[float],
        velocity_ned_mps: np.ndarray | list[float],
        setpoint: TrajectorySetpoint,
        hover_thrust: float | None = None,
    ) -> ThrustSetpoint:
        """One PX4 position-control step on the estimated state (NED m, m/s)."""
        p = self._p
        hover = p.hover_thrust if hover_thrust is None else hover_thrust
        vel = _floats(velocity_ned_mps)
        vel_dot = self._vel_dot.update(vel, dt_s)
        vel_sp = self._velocity_setpoint(setpoint, _floats(position_ned_m))
        # PX4 _velocityControl
        gain_p = (p.xy_vel_p, p.xy_vel_p, p.z_vel_p)
        gain_i = (p.xy_vel_i, p.xy_vel_i, p.z_vel_i)
        gain_d = (p.xy_vel_d, p.xy_vel_d, p.z_vel_d)
        acc_ff = setpoint.acceleration_ned_mps2.tolist()
        error = [0.0, 0.0, 0.0]
        acc = [0.0, 0.0, 0.0]
        vint = self._vel_int
        for i in range(3):
            e = vel_sp[i] - vel[i]
            a = acc_ff[i] if math.isfinite(acc_ff[i]) else 0.0
            if math.isfinite(e):
                error[i] = e
                a += e * gain_p[i] + vint[i] - vel_dot[i] * gain_d[i]
            acc[i] = a
        thr_min = p.thr_min if self.thrust_min is None else max(self.thrust_min, 1e-3)
        tx, ty, tz = self._acceleration_control(acc, hover, thr_min)
        # vertical anti-windup while the thrust saturates
        if (tz >= -thr_min and error[2] >= 0.0) or (tz <= -p.thr_max and error[2] <= 0.0):
            error[2] = 0.0
        # vertical priority, keeping a horizontal margin
        thr_xy = math.hypot(tx, ty)
        margin = min(thr_xy, p.thr_xy_margin)
        tz = max(tz, -math.sqrt(max(p.thr_max**2 - margin**2, 0.0)))
        xy_max = math.sqrt(max(p.thr_max**2 - tz * tz, 0.0))
        if thr_xy > xy_max:
            tx, ty = tx * xy_max / thr_xy, ty * xy_max / thr_xy
        # horizontal tracking anti-windup (Rundqwist 1990)
        px, py = tx * GRAVITY_MPS2 / hover, ty * GRAVITY_MPS2 / hover
        lx, ly = (px, py) if acc[0] ** 2 + acc[1] ** 2 > px * px + py * py else (acc[0], acc[1])
        arw = 2.0 / p.xy_vel_p
        error[0] -= arw * (acc[0] - lx)
        error[1] -= arw * (acc[1] - ly)
        for i in range(3):
            vint[i] += error[i] * gain_i[i] * dt_s
        vint[2] = math.copysign(min(abs(vint[2]), GRAVITY_MPS2), vint[2])
        return ThrustSetpoint(np.array([tx, ty, tz]), np.array(vel_sp), np.array(acc))

    def _acceleration_control(
        self, acc: list[float], hover: float, thr_min: float
    ) -> tuple[float, float, float]:
        """PX4 _accelerationControl (MPC_ACC_DECOUPLE: tilt from the horizontal part only)."""
        norm = math.sqrt(acc[0] ** 2 + acc[1] ** 2 + GRAVITY_MPS2**2)
        bx, by, bz = _limit_tilt(
            -acc[0] / norm, -acc[1] / norm, GRAVITY_MPS2 / norm, self.tilt_limit_rad
        )
        collective = min((acc[2] * (hover / GRAVITY_MPS2) - hover) / bz, -thr_min)
        return bx * collective, by * collective, bz * collective


def _floats(x: np.ndarray | list[float]) -> list[float]:
    return x.tolist() if isinstance(x, np.ndarray) else list(x)


def _min_finite(default: float, override: float) -> float:
    return min(default, override) if math.isfinite(override) else default


class TakeoffState(IntEnum):
    """PX4 TakeoffState."""

    DISARMED = 0
    SPOOLUP = 1
    READY_FOR_TAKEOFF = 2
    RAMPUP = 3
    FLIGHT = 4


class TakeoffRamp:
    """PX4 TakeoffHandling: spool-up after arming, then ramp the climb-speed limit.

    Before the ramp the upward limit is -g / MPC_Z_VEL_P_ACC (a *descent* that commands idle
    thrust); over MPC_TKO_RAMP_T it rises to the desired climb speed, so thrust builds smoothly.
    """

    def __init__(self, params: VehicleSimParams) -> None:
        self._p = params
        self.state = TakeoffState.DISARMED
        self._armed_since_s: float | None = None
        self._progress = 0.0

    def skip(self) -> None:
        """Already flying (a vehicle placed in the air)."""
        self.state = TakeoffState.FLIGHT

    def update(self, now_s: float, armed: bool, landed: bool, want_takeoff: bool) -> TakeoffState:
        """PX4 updateTakeoffState."""
        if not armed:
            self.state = TakeoffState.DISARMED
            self._armed_since_s = None
            return self.state
        if self._armed_since_s is None:
            self._armed_since_s = now_s
        if self.state is TakeoffState.DISARMED:
            self.state = TakeoffState.SPOOLUP
        if self.state is TakeoffState.SPOOLUP and now_s - self._armed_since_s >= self._p.spoolup_s:
            self.state = TakeoffState.READY_FOR_TAKEOFF
        if self.state is TakeoffState.READY_FOR_TAKEOFF and want_takeoff:
            self.state = TakeoffState.RAMPUP
            self._progress = 0.0
        if self.state is TakeoffState.RAMPUP and self._progress >= 1.0:
            self.state = TakeoffState.FLIGHT
        if self.state is TakeoffState.FLIGHT and landed:
            self.state = TakeoffState.READY_FOR_TAKEOFF
        return self.state

    def upward_speed_limit(self, dt_s: float, desired_mps: float) -> float:
        """PX4 updateRamp: the upward velocity limit now, m/s (negative: must descend)."""
        init = -GRAVITY_MPS2 / max(self._p.z_vel_p, 0.01)
        if self.state < TakeoffState.RAMPUP:
            return init
        if self.state is TakeoffState.RAMPUP:
            ramp_s = self._p.takeoff_ramp_s
            self._progress = self._progress + dt_s / ramp_s if ramp_s > dt_s else 1.0
            if self._progress < 1.0:
                return init + self._progress * (desired_mps - init)
        return desired_mps
