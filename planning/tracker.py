"""Path tracking: a planner `Reference` in, flight-link `Setpoint`s out, at >= 20 Hz.

The velocity is the reference velocity `velocity_lead_s` ahead (feed-forward for the
vehicle's velocity-loop lag). In `setpoint_mode` 'trajectory' (the default) it goes out with
the reference position and acceleration as a TRAJECTORY setpoint (a stop manoeuvre: a BRAKE
with a position): the autopilot's own position loop corrects its lag behind the plan and
stops where the plan stops. In 'velocity' the tracker adds a bounded position-error
correction itself.
Across replans it cannot jump: when a new reference arrives (a new `plan_id`), the offset
between the last commanded velocity (and trajectory position) and the new reference's fades
out linearly over `blend_time_s`, and every change of the commanded velocity is limited to
`setpoint_accel_slack * max_accel_mps2 * dt`. Near a reference's end the speed is capped so
the vehicle can stop there; after its end the tracker holds its last point with a position
setpoint. The yaw follows the yaw policy (or the reference's rotate / align command) at no
more than `max_yaw_rate_radps`.
"""

from __future__ import annotations

import numpy as np

from geometry.rotation import wrap_angle_rad
from planning.params import PlanningParams, SetpointMode, YawPolicy
from planning.types import Reference, Setpoint, SetpointKind, VehicleState

_MAX_DT_S = 0.2  # longest step the limiters integrate over (a late call is not a licence to jump)
_ACCEL_STEP_S = 0.05  # half the span of the reference's acceleration difference, s


def sample_reference(reference: Reference, t_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Position (3,) and velocity (3,) of `reference` at `t_s` after its start (linear)."""
    t = float(np.clip(t_s, reference.times_s[0], reference.times_s[-1]))
    position = np.array(
        [np.interp(t, reference.times_s, reference.positions_ned_m[:, i]) for i in range(3)]
    )
    velocity = np.array(
        [np.interp(t, reference.times_s, reference.velocities_ned_mps[:, i]) for i in range(3)]
    )
    return position, velocity


class PathTracker:
    """Turns the planner's current `Reference` into smooth setpoints; call at >= 20 Hz."""

    def __init__(self, params: PlanningParams) -> None:
        self._params = params
        self._last: Setpoint | None = None
        self._plan_id = -1
        self._blend_offset = np.zeros(3)
        self._blend_position_offset = np.zeros(3)
        self._blend_start_s = 0.0
        self._followed: Reference | None = None  # the reference last flown as a TRAJECTORY

    @property
    def last_setpoint(self) -> Setpoint | None:
        """The setpoint returned last (None before the first call)."""
        return self._last

    def setpoint(
        self,
        now_s: float,
        vehicle: VehicleState,
        reference: Reference | None,
        goal_ned_m: np.ndarray | None = None,
    ) -> Setpoint:
        """The setpoint at `now_s` for `vehicle` following `reference`.

        reference None (no plan): a brake to zero velocity, marked invalid.
        goal_ned_m: (3,) NED, used by the yaw policy 'goal'.
        """
        p = self._params
        last_velocity = self._last.velocity_ned_mps if self._last else vehicle.velocity_ned_mps
        last_yaw = self._last.yaw_rad if self._last else vehicle.yaw_rad
        dt = float(np.clip(now_s - self._last.stamp_s, 0.0, _MAX_DT_S)) if self._last else 0.0

        tracked = False  # the position goes out with the velocity (a trajectory or its brake)
        if reference is None:
            kind, position, valid = SetpointKind.BRAKE, None, False
            target_velocity = np.zeros(3)
        else:
            valid = True
            t = now_s - reference.start_s
            ref_position, _ = sample_reference(reference, t)
            _, ref_velocity = sample_reference(reference, t + p.velocity_lead_s)
            if t >= reference.times_s[-1]:
                kind, position = SetpointKind.POSITION, reference.positions_ned_m[-1].copy()
                target_velocity = np.zeros(3)
            elif p.setpoint_mode is SetpointMode.TRAJECTORY:
                kind = SetpointKind.BRAKE if reference.brake else SetpointKind.TRAJECTORY
                position = ref_position
                target_velocity = self._stoppable(vehicle, reference, ref_velocity)
            else:
                kind = SetpointKind.BRAKE if reference.brake else SetpointKind.VELOCITY
                position = None
                target_velocity = self._tracking_velocity(
                    vehicle, reference, ref_position, ref_velocity
                )
            tracked = position is not None and kind is not SetpointKind.POSITION
            if reference.plan_id != self._plan_id:
                self._plan_id = reference.plan_id
                self._blend_offset = last_velocity - target_velocity
                previous = self._blended_position(now_s)
                self._blend_position_offset = (
                    previous - position if tracked and previous is not None else np.zeros(3)
                )
                self._blend_start_s = now_s
        if kind is not SetpointKind.POSITION and p.blend_time_s > 0:
            fade = max(0.0, 1.0 - (now_s - self._blend_start_s) / p.blend_time_s)
            target_velocity = target_velocity + fade * self._blend_offset
            if tracked:
                position = position + fade * self._blend_position_offset
        self._followed = reference if tracked else None
        step = target_velocity - last_velocity
        max_step = p.setpoint_accel_slack * p.max_accel_mps2 * dt
        norm = float(np.linalg.norm(step))
        velocity = last_velocity + (step * (max_step / norm) if norm > max_step else step)
        if kind is SetpointKind.POSITION:
            velocity = np.zeros(3)
        acceleration = (
            self._feed_forward_acceleration(reference, now_s) if tracked and reference else None
        )
        yaw, yaw_rate = self._yaw(vehicle, reference, velocity, last_yaw, dt, goal_ned_m)
        self._last = Setpoint(
            stamp_s=now_s,
            kind=kind,
            velocity_ned_mps=velocity,
            position_ned_m=position,
            yaw_rad=yaw,
            yaw_rate_radps=yaw_rate,
            valid=valid,
            acceleration_ned_mps2=acceleration,
        )
        return self._last

    def _tracking_velocity(
        self,
        vehicle: VehicleState,
        reference: Reference,
        ref_position: np.ndarray,
        ref_velocity: np.ndarray,
    ) -> np.ndarray:
        """Reference velocity + clipped P correction, capped to stop at the reference's end."""
        p = self._params
        correction = p.position_gain_per_s * (ref_position - vehicle.position_ned_m)
        norm = float(np.linalg.norm(correction))
        if norm > p.max_correction_mps:
            correction *= p.max_correction_mps / norm
        return self._stoppable(vehicle, reference, ref_velocity + correction)

    def _stoppable(
        self, vehicle: VehicleState, reference: Reference, velocity: np.ndarray
    ) -> np.ndarray:
        """`velocity` capped so the vehicle can stop at the reference's end (at half the
        maximum deceleration)."""
        remaining = float(np.linalg.norm(reference.positions_ned_m[-1] - vehicle.position_ned_m))
        cap = np.sqrt(self._params.max_accel_mps2 * remaining)
        speed = float(np.linalg.norm(velocity))
        return velocity * (cap / speed) if speed > cap else velocity

    def _feed_forward_acceleration(self, reference: Reference, now_s: float) -> np.ndarray:
        """The reference's acceleration `velocity_lead_s` ahead (central difference over
        `_ACCEL_STEP_S`), no larger than the tracker's own velocity rate limit."""
        p = self._params
        t = now_s - reference.start_s + p.velocity_lead_s
        _, ahead = sample_reference(reference, t + _ACCEL_STEP_S)
        _, behind = sample_reference(reference, t - _ACCEL_STEP_S)
        acceleration = (ahead - behind) / (2.0 * _ACCEL_STEP_S)
        limit = p.setpoint_accel_slack * p.max_accel_mps2
        norm = float(np.linalg.norm(acceleration))
        return acceleration * (limit / norm) if norm > limit else acceleration

    def _blended_position(self, now_s: float) -> np.ndarray | None:
        """Where the position sent would be at `now_s` on the reference followed so far (its
        blend included): a new plan blends in from there, so the position is continuous at
        the switch and a plan that starts on the old one (the planner's replan origin)
        blends nothing. None when the last setpoint was no TRAJECTORY."""
        followed = self._followed
        if followed is None:
            return None
        position, _ = sample_reference(followed, now_s - followed.start_s)
        blend_time = self._params.blend_time_s
        fade = max(0.0, 1.0 - (now_s - self._blend_start_s) / blend_time) if blend_time else 0.0
        return position + fade * self._blend_position_offset

    def _yaw(
        self,
        vehicle: VehicleState,
        reference: Reference | None,
        velocity: np.ndarray,
        last_yaw: float,
        dt: float,
        goal_ned_m: np.ndarray | None,
    ) -> tuple[float, float]:
        """Commanded yaw and its rate: policy target, rate-limited from the last command."""
        p = self._params
        if reference is not None and reference.yaw_rate_radps is not None:
            rate = float(
                np.clip(reference.yaw_rate_radps, -p.max_yaw_rate_radps, p.max_yaw_rate_radps)
            )
            return float(wrap_angle_rad(last_yaw + rate * dt)), rate
        if reference is not None and reference.yaw_target_rad is not None:
            target = reference.yaw_target_rad
        elif p.yaw_policy is YawPolicy.FIXED:
            target = p.fixed_yaw_rad
        elif p.yaw_policy is YawPolicy.GOAL and goal_ned_m is not None:
            to_goal = np.asarray(goal_ned_m) - vehicle.position_ned_m
            far = np.hypot(to_goal[0], to_goal[1]) > p.arrival_tolerance_m
            target = float(np.arctan2(to_goal[1], to_goal[0])) if far else last_yaw
        elif np.hypot(velocity[0], velocity[1]) > p.yaw_motion_min_speed_mps:
            target = float(np.arctan2(velocity[1], velocity[0]))
        else:
            target = last_yaw
        error = float(wrap_angle_rad(target - last_yaw))
        max_step = p.max_yaw_rate_radps * dt
        step = float(np.clip(error, -max_step, max_step))
        rate = step / dt if dt > 0 else 0.0
        return float(wrap_angle_rad(last_yaw + step)), rate
