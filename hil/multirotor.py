"""A compact rigid-body multirotor with a PX4-like cascaded controller, on simulated time.

Pure and synchronous (no MAVLink, no wall clock): `step(dt_s)` advances fixed physics steps of
1/`physics_rate_hz`, so the planner can fly it in lockstep and the MAVLink vehicle wraps it.
World frame NED with z = 0 the ground at home (down positive: the vehicle never goes below 0);
body frame FRD. The body tilts to accelerate, so cameras rigidly mounted on it tilt too.

Forces: thrust along -z_body (first-order motor lag), gravity, linear drag on the air-relative
velocity (optional wind: mean + first-order Gauss-Markov gusts from the seeded generator).

Flying it directly, in lockstep with a planner::

    vehicle = Multirotor(VehicleSimParams(), seed=0)
    vehicle.reset(np.array([0.0, 0.0, -5.0]), yaw_rad=0.0)  # hovering 5 m above home
    vehicle.set_velocity_setpoint(np.array([2.0, 0.0, 0.0]), yaw_rad=0.0)
    state = vehicle.step(0.05)  # VehicleState at t = 0.05 s
    r_ned_from_frd = state.rotation_ned_from_frd()
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hil.attitude import (
    euler_from_quaternion,
    quaternion_from_euler,
    quaternion_from_rotation_vector,
    quaternion_multiply,
)
from hil.params import VehicleSimParams
from hil.px4_controller import (
    GRAVITY_MPS2,
    AttitudeController,
    PositionController,
    TrajectorySetpoint,
)
from mapping.pose import rotation_from_quaternion


@dataclass(frozen=True)
class VehicleState:
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


def _frozen(a: np.ndarray) -> np.ndarray:
    out = np.array(a, dtype=float)
    out.flags.writeable = False
    return out


class Multirotor:
    """Rigid body + PX4-like controller. Not thread-safe: the MAVLink vehicle serialises calls.

    Setpoints persist until replaced. `motors_enabled` False (disarmed) cuts thrust.
    """

    def __init__(self, params: VehicleSimParams, seed: int | None = None) -> None:
        self.params = params
        self._dt_s = 1.0 / params.physics_rate_hz
        self._mass_kg = params.mass_kg
        self._max_thrust_n = params.mass_kg * GRAVITY_MPS2 / params.hover_thrust
        self._rng = np.random.default_rng(params.seed if seed is None else seed)
        self._position_ctl = PositionController(params)
        self._attitude_ctl = AttitudeController(params)
        self.motors_enabled = True
        self.reset(np.zeros(3), 0.0)

    # --- state --------------------------------------------------------------------------
    def reset(self, position_ned_m: np.ndarray, yaw_rad: float = 0.0) -> None:
        """Place the vehicle at rest, level, at `position_ned_m` (z clipped to the ground).

        In the air it starts hovering (thrust = weight) holding that position and yaw.
        """
        self._state_cache: VehicleState | None = None
        self._time_s = 0.0
        self._p = np.array(position_ned_m, dtype=float)
        self._p[2] = min(self._p[2], 0.0)
        self._v = np.zeros(3)
        self._a = np.zeros(3)
        self._q = quaternion_from_euler(0.0, 0.0, yaw_rad)
        self._w = np.zeros(3)
        self._on_ground = self._p[2] >= 0.0
        self._thrust_n = 0.0 if self._on_ground else self._mass_kg * GRAVITY_MPS2
        self._gust = np.zeros(3)
        self._position_ctl.reset()
        self._attitude_ctl.reset(yaw_rad)
        self._setpoint = TrajectorySetpoint(position_ned_m=self._p.copy(), yaw_rad=yaw_rad)

    @property
    def time_s(self) -> float:
        """Simulated time, s."""
        return self._time_s

    @property
    def state(self) -> VehicleState:
        """Ground truth now (built once per step)."""
        if self._state_cache is None:
            self._state_cache = self._snapshot()
        return self._state_cache

    def _snapshot(self) -> VehicleState:
        return VehicleState(
            time_s=self._time_s,
            position_ned_m=_frozen(self._p),
            velocity_ned_mps=_frozen(self._v),
            acceleration_ned_mps2=_frozen(self._a),
            attitude_wxyz=_frozen(self._q),
            angular_velocity_frd_radps=_frozen(self._w),
            thrust_n=self._thrust_n,
            on_ground=self._on_ground,
            wind_ned_mps=_frozen(self._wind()),
        )

    @property
    def setpoint(self) -> TrajectorySetpoint:
        """The setpoint being tracked."""
        return self._setpoint

    @property
    def rng(self) -> np.random.Generator:
        """The seeded generator of this vehicle (wind, sensor noise, quirks)."""
        return self._rng

    # --- setpoints ----------------------------------------------------------------------
    def set_setpoint(self, setpoint: TrajectorySetpoint) -> None:
        """Track `setpoint` from the next step on."""
        self._setpoint = setpoint

    def set_velocity_setpoint(
        self,
        velocity_ned_mps: np.ndarray,
        yaw_rad: float | None = None,
        yaw_rate_radps: float | None = None,
    ) -> None:
        """Track a velocity (3,) NED m/s (NaN components uncontrolled); yaw or yaw rate, rad(/s)."""
        self._setpoint = TrajectorySetpoint(
            velocity_ned_mps=np.array(velocity_ned_mps, dtype=float),
            yaw_rad=math.nan if yaw_rad is None else float(yaw_rad),
            yaw_rate_radps=math.nan if yaw_rate_radps is None else float(yaw_rate_radps),
        )

    def set_position_setpoint(
        self,
        position_ned_m: np.ndarray,
        yaw_rad: float | None = None,
        velocity_ff_ned_mps: np.ndarray | None = None,
    ) -> None:
        """Fly to a position (3,) NED m (NaN components uncontrolled), optional feed-forward."""
        self._setpoint = TrajectorySetpoint(
            position_ned_m=np.array(position_ned_m, dtype=float),
            velocity_ned_mps=(
                np.full(3, np.nan)
                if velocity_ff_ned_mps is None
                else np.array(velocity_ff_ned_mps, dtype=float)
            ),
            yaw_rad=math.nan if yaw_rad is None else float(yaw_rad),
        )

    # --- simulation ---------------------------------------------------------------------
    def step(self, dt_s: float) -> VehicleState:
        """Advance `dt_s` seconds in fixed physics steps (the last one shorter if needed)."""
        remaining = float(dt_s)
        while remaining > 1e-9:
            h = min(self._dt_s, remaining)
            self._substep(h)
            remaining -= h
        return self.state

    def _wind(self) -> np.ndarray:
        return np.asarray(self.params.wind_ned_mps, dtype=float) + self._gust

    def _substep(self, h: float) -> None:
        self._state_cache = None
        p = self.params
        yaw = euler_from_quaternion(self._q)[2]
        if self.motors_enabled:
            thrust_vec, _ = self._position_ctl.update(h, self._p, self._v, self._a, self._setpoint)
            thrust_cmd, ang_acc, _ = self._attitude_ctl.update(
                h, self._q, self._w, thrust_vec, self._setpoint, yaw
            )
        else:
            self._position_ctl.reset()
            self._attitude_ctl.reset(yaw)
            thrust_cmd, ang_acc = 0.0, -self._w / max(h, 1e-6)
        if self._on_ground:
            self._attitude_ctl.reset(yaw)

        alpha = 1.0 - math.exp(-h / p.motor_time_constant_s)
        self._thrust_n += (thrust_cmd * self._max_thrust_n - self._thrust_n) * alpha

        if p.wind_gust_std_mps > 0.0:
            tau = p.wind_gust_time_constant_s
            decay = math.exp(-h / tau)
            self._gust = self._gust * decay + self._rng.normal(
                0.0, p.wind_gust_std_mps * math.sqrt(1.0 - decay * decay), 3
            )

        rot = rotation_from_quaternion(self._q)
        force = (
            rot[:, 2] * -self._thrust_n
            + np.array([0.0, 0.0, self._mass_kg * GRAVITY_MPS2])
            - p.drag_coefficient_nspm * (self._v - self._wind())
        )
        accel = force / self._mass_kg

        if self._on_ground and accel[2] >= 0.0:
            # resting on the ground: the normal force and friction cancel everything, level
            self._v[:] = 0.0
            self._a[:] = 0.0
            self._w[:] = 0.0
            self._q = quaternion_from_euler(0.0, 0.0, yaw)
            self._p[2] = 0.0
            self._time_s += h
            return

        self._v += accel * h
        self._p += self._v * h
        self._w = self._w + np.clip(ang_acc, -1e3, 1e3) * h
        self._q = quaternion_multiply(self._q, quaternion_from_rotation_vector(self._w * h))
        self._q /= np.linalg.norm(self._q)
        self._a = accel
        self._on_ground = False
        if self._p[2] >= 0.0:
            # touchdown: stop on the ground (no falling through it)
            self._p[2] = 0.0
            self._v[2] = min(self._v[2], 0.0)
            self._a[2] = min(self._a[2], 0.0)
            self._on_ground = True
        self._time_s += h
