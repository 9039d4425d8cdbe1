"""PX4's SIH quadrotor flown by PX4's controllers, on simulated time.

Pure and synchronous (no MAVLink, no wall clock): `step(dt_s)` advances fixed physics steps of
1/`physics_rate_hz`, so the planner can fly it in lockstep and the MAVLink vehicle wraps it.
World frame NED with z = 0 the ground at home (down positive: the vehicle never goes below 0);
body frame FRD. The body tilts to accelerate, so cameras rigidly mounted on it tilt too.

Each step runs PX4's chain on the *estimate* (`hil.vehicle.estimator`): position control
(`px4_controller`), attitude and rate control and the quadrotor X mixer (`px4_attitude`), then
SIH's physics (simulator_sih): four rotors with a first-order lag (SIH_T_TAU), thrust SIH_T_MAX
and reaction torque SIH_Q_MAX each, arms SIH_L_ROLL/PITCH, linear drag SIH_KDV on the
air-relative velocity (optional wind: mean + first-order Gauss-Markov gusts), angular damping
SIH_KDW, Euler's rigid-body equation with SIH_IXX/IYY/IZZ; forward-Euler velocity, trapezoidal
position, as SIH integrates.

Flying it directly, in lockstep with a planner::

    vehicle = Multirotor(VehicleSimParams(), seed=0)
    vehicle.reset(np.array([0.0, 0.0, -5.0]), yaw_rad=0.0)  # hovering 5 m above home
    vehicle.set_velocity_setpoint(np.array([2.0, 0.0, 0.0]), yaw_rad=0.0)
    state = vehicle.step(0.05)  # RigidBodyState at t = 0.05 s (the truth)
    seen = vehicle.estimate  # what PX4's estimator would report
"""

from __future__ import annotations

import math

import numpy as np

from geometry.rotation import (
    quaternion_from_euler,
)
from hil.vehicle.estimator import EstimatorError
from hil.vehicle.params import VehicleSimParams
from hil.vehicle.px4_attitude import (
    AttitudeController,
    RateController,
    _attitude_from_body_z,
    _qmul,
    quad_x_motor_commands,
)
from hil.vehicle.px4_controller import (
    GRAVITY_MPS2,
    PositionController,
    ThrustSetpoint,
    TrajectorySetpoint,
)
from hil.vehicle.state import RigidBodyState, frozen

_MAX_BODY_RATE_RADPS = 6.0 * math.pi  # SIH's bound on the angular velocity


def true_hover_thrust(params: VehicleSimParams) -> float:
    """The collective command (0..1) whose thrust carries the weight."""
    return params.mass_kg * GRAVITY_MPS2 / (4.0 * params.rotor_thrust_max_n)


class Multirotor:
    """SIH rigid body + PX4's controllers. Not thread-safe: the MAVLink vehicle serialises calls.

    Setpoints persist until replaced. `motors_enabled` False (disarmed) cuts the rotors.
    `landed` (set by the commander's land detector) freezes the rate integrators, as in PX4.
    """

    def __init__(self, params: VehicleSimParams, seed: int | None = None) -> None:
        self.params = params
        self._dt_s = 1.0 / params.physics_rate_hz
        self._rng = np.random.default_rng(params.seed if seed is None else seed)
        self._estimator = EstimatorError(params, np.random.default_rng(self._rng.integers(2**32)))
        self._position_ctl = PositionController(params)
        self._attitude_ctl = AttitudeController(params)
        self._rate_ctl = RateController(params)
        self.motors_enabled = True
        self.landed = False
        self.last_control: ThrustSetpoint | None = None
        self.attitude_setpoint_wxyz: tuple[float, ...] = (1.0, 0.0, 0.0, 0.0)
        self.rate_setpoint_frd_radps: tuple[float, ...] = (0.0, 0.0, 0.0)
        self.reset(np.zeros(3), 0.0)

    # --- state --------------------------------------------------------------------------
    def reset(self, position_ned_m: np.ndarray, yaw_rad: float = 0.0) -> None:
        """Place the vehicle at rest, level, at `position_ned_m` (z clipped to the ground).

        In the air it starts hovering (rotors carrying the weight, the vertical integrator
        holding the difference to MPC_THR_HOVER) at that position and yaw.
        """
        self._state_cache: RigidBodyState | None = None
        self._estimate_cache: RigidBodyState | None = None
        self._time_s = 0.0
        self._p = [float(x) for x in position_ned_m]
        self._p[2] = min(self._p[2], 0.0)
        self._v = [0.0, 0.0, 0.0]
        self._a = [0.0, 0.0, 0.0]
        self._q = tuple(float(x) for x in quaternion_from_euler(0.0, 0.0, yaw_rad))
        self._w = (0.0, 0.0, 0.0)
        self._on_ground = self._p[2] >= 0.0
        self._gust = np.zeros(3)
        self._position_ctl.reset()
        self._rate_ctl.reset()
        hover = true_hover_thrust(self.params)
        self._u = [0.0 if self._on_ground else hover] * 4
        if not self._on_ground:
            h = self.params.hover_thrust
            self._position_ctl.seed_vertical_integral((h - hover) * GRAVITY_MPS2 / h)
        self._setpoint = TrajectorySetpoint(position_ned_m=np.array(self._p), yaw_rad=yaw_rad)

    @property
    def time_s(self) -> float:
        """Simulated time, s."""
        return self._time_s

    @property
    def state(self) -> RigidBodyState:
        """Ground truth now (built once per step)."""
        if self._state_cache is None:
            self._state_cache = self._snapshot()
        return self._state_cache

    @property
    def estimate(self) -> RigidBodyState:
        """The state as PX4's estimator reports it now (the truth without estimator error)."""
        if self._estimate_cache is None:
            self._estimate_cache = self._estimator.estimate(self.state)
        return self._estimate_cache

    def _snapshot(self) -> RigidBodyState:
        return RigidBodyState(
            time_s=self._time_s,
            position_ned_m=frozen(self._p),
            velocity_ned_mps=frozen(self._v),
            acceleration_ned_mps2=frozen(self._a),
            attitude_wxyz=frozen(self._q),
            angular_velocity_frd_radps=frozen(self._w),
            thrust_n=float(self.params.rotor_thrust_max_n * sum(self._u)),
            on_ground=self._on_ground,
            wind_ned_mps=frozen(self._wind()),
        )

    @property
    def setpoint(self) -> TrajectorySetpoint:
        """The setpoint being tracked."""
        return self._setpoint

    @property
    def rng(self) -> np.random.Generator:
        """The seeded generator of this vehicle (wind, quirks)."""
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

    def set_tilt_limit_deg(self, tilt_deg: float) -> None:
        """The position controller's tilt limit (PX4 lowers it to MPC_TILTMAX_LND for takeoff)."""
        self._position_ctl.tilt_limit_rad = math.radians(tilt_deg)

    def set_thrust_min(self, thrust_min: float | None) -> None:
        """Lower the minimum collective thrust (None: MPC_THR_MIN); PX4 uses 0 until flying."""
        self._position_ctl.thrust_min = thrust_min

    def reset_velocity_integral(self) -> None:
        """PX4 resetIntegral: before takeoff, no windup on the ground."""
        self._position_ctl.reset_integral()

    # --- simulation ---------------------------------------------------------------------
    def step(self, dt_s: float) -> RigidBodyState:
        """Advance `dt_s` seconds in fixed physics steps (the last one shorter if needed)."""
        remaining = float(dt_s)
        while remaining > 1e-9:
            h = min(self._dt_s, remaining)
            self._substep(h)
            remaining -= h
        return self.state

    def _wind(self) -> np.ndarray:
        return np.asarray(self.params.wind_ned_mps, dtype=float) + self._gust

    def _motor_commands(self, h: float) -> list[float]:
        """PX4's control chain on the estimate: motor commands (4) for this step."""
        if not self.motors_enabled:
            self._position_ctl.reset()
            self._rate_ctl.reset()
            self.last_control = None
            return [0.0, 0.0, 0.0, 0.0]
        position, velocity, attitude = self._estimator.apply(self._p, self._v, self._q)
        sp = self._setpoint
        control = self._position_ctl.update(h, position, velocity, sp)
        self.last_control = control
        tx, ty, tz = control.thrust_ned.tolist()
        collective = math.sqrt(tx * tx + ty * ty + tz * tz)
        body_z = (
            (-tx / collective, -ty / collective, -tz / collective)
            if collective > 1e-9
            else (0.0, 0.0, 1.0)
        )
        if math.isfinite(sp.yaw_rad):
            yaw_sp = sp.yaw_rad
        else:
            w, x, y, z = attitude
            yaw_sp = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
        yaw_rate_ff = sp.yaw_rate_radps if math.isfinite(sp.yaw_rate_radps) else 0.0
        q_sp = _attitude_from_body_z(body_z, yaw_sp)
        self.attitude_setpoint_wxyz = q_sp
        rate_sp = self._attitude_ctl.rates(attitude, q_sp, yaw_rate_ff)
        self.rate_setpoint_frd_radps = rate_sp
        torque = self._rate_ctl.update(h, self._w, rate_sp, self.landed or self._on_ground)
        motors, self._rate_ctl.saturation = quad_x_motor_commands(
            min(collective, self.params.thr_max), torque
        )
        return motors

    def _substep(self, h: float) -> None:
        p = self.params
        u_sp = self._motor_commands(h)
        alpha = min(h / p.motor_time_constant_s, 1.0)
        u = [self._u[i] + alpha * (u_sp[i] - self._u[i]) for i in range(4)]
        self._u = u
        self._estimator.step(h)
        self._state_cache = None
        self._estimate_cache = None
        if p.wind_gust_std_mps > 0.0:
            decay = math.exp(-h / p.wind_gust_time_constant_s)
            self._gust = self._gust * decay + self._rng.normal(
                0.0, p.wind_gust_std_mps * math.sqrt(1.0 - decay * decay), 3
            )
        wind = self._wind().tolist() if p.wind_gust_std_mps > 0.0 or any(p.wind_ned_mps) else None

        thrust_n = p.rotor_thrust_max_n * (u[0] + u[1] + u[2] + u[3])
        w, x, y, z = self._q
        # thrust acts along -z body: the third column of R(q), negated
        bz = (2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y))
        kdv, m = p.drag_coefficient_nspm, p.mass_kg
        v = self._v
        rel = v if wind is None else [v[i] - wind[i] for i in range(3)]
        accel = [
            (-bz[0] * thrust_n - kdv * rel[0]) / m,
            (-bz[1] * thrust_n - kdv * rel[1]) / m,
            (-bz[2] * thrust_n - kdv * rel[2]) / m + GRAVITY_MPS2,
        ]
        if self._on_ground and accel[2] >= 0.0:
            # resting on the ground: the normal force and friction cancel everything, level
            yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
            self._v = [0.0, 0.0, 0.0]
            self._a = [0.0, 0.0, 0.0]
            self._w = (0.0, 0.0, 0.0)
            self._q = (math.cos(0.5 * yaw), 0.0, 0.0, math.sin(0.5 * yaw))
            self._p[2] = 0.0
            self._time_s += h
            return

        arm_t = p.rotor_thrust_max_n
        moment = (
            p.roll_arm_m * arm_t * (-u[0] + u[1] + u[2] - u[3]),
            p.pitch_arm_m * arm_t * (u[0] - u[1] + u[2] - u[3]),
            p.rotor_torque_max_nm * (u[0] + u[1] - u[2] - u[3]),
        )
        ix, iy, iz = p.inertia_xx_kgm2, p.inertia_yy_kgm2, p.inertia_zz_kgm2
        wx, wy, wz = self._w
        kdw = p.angular_drag_nmsprad
        # Euler: I w_dot = M - kdw w - w x (I w)
        w_dot = (
            (moment[0] - kdw * wx - (wy * iz * wz - wz * iy * wy)) / ix,
            (moment[1] - kdw * wy - (wz * ix * wx - wx * iz * wz)) / iy,
            (moment[2] - kdw * wz - (wx * iy * wy - wy * ix * wx)) / iz,
        )
        v_new = [v[i] + accel[i] * h for i in range(3)]
        self._p = [self._p[i] + 0.5 * (v[i] + v_new[i]) * h for i in range(3)]
        self._v = v_new
        # q <- q * exp(w h / 2), SIH's quaternion update with the old rate
        angle = math.sqrt(wx * wx + wy * wy + wz * wz) * h
        if angle > 1e-12:
            k = math.sin(0.5 * angle) / (angle / h)
            dq = (math.cos(0.5 * angle), wx * k, wy * k, wz * k)
        else:
            dq = (1.0, 0.5 * wx * h, 0.5 * wy * h, 0.5 * wz * h)
        q = _qmul(self._q, dq)
        n = math.sqrt(q[0] ** 2 + q[1] ** 2 + q[2] ** 2 + q[3] ** 2)
        self._q = (q[0] / n, q[1] / n, q[2] / n, q[3] / n)
        limit = _MAX_BODY_RATE_RADPS
        self._w = tuple(min(max(self._w[i] + w_dot[i] * h, -limit), limit) for i in range(3))
        self._a = accel
        self._on_ground = False
        if self._p[2] >= 0.0:
            # touchdown: stop on the ground (no falling through it)
            self._p[2] = 0.0
            self._v[2] = min(self._v[2], 0.0)
            self._a[2] = min(self._a[2], 0.0)
            self._on_ground = True
        self._time_s += h
