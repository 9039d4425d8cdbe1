"""Messages in and out of the planner and the path tracker: the one home of `VehicleState` and
`Setpoint`, which travel unchanged from the planner to the flight link. Frames: local NED, m, rad.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from enum import StrEnum

import numpy as np


class PlannerState(StrEnum):
    """What the planner is doing; reported to the mission manager every cycle."""

    IDLE = "idle"  # no goal: hold position
    TRACKING = "tracking"  # following a collision-free library trajectory
    ALIGNING = "aligning"  # stopped with the goal far off the nose: rotate towards it first
    BRAKING = "braking"  # no moving trajectory is free: follow the stop trajectory (4.5)
    RECOVERING = "recovering"  # stopped and boxed in: rotate in place to look for a way (4.5)
    REWINDING = "rewinding"  # stuck: back off along the flown path
    ARRIVED = "arrived"  # within the arrival tolerance: hold at the goal
    GOAL_BLOCKED = "goal_blocked"  # goal seen in solid collision: hold, re-checking it
    UNREACHABLE = "unreachable"  # goal inside an obstacle, or stuck after every rewind: hold


class SetpointKind(StrEnum):
    """How the flight link must send a `Setpoint`."""

    VELOCITY = "velocity"  # velocity_ned_mps + yaw
    POSITION = "position"  # position_ned_m + yaw (hold, arrival, rotate in place)
    BRAKE = "brake"  # velocity_ned_mps decelerating to zero + yaw (+ position: the stop curve)
    TRAJECTORY = "trajectory"  # position_ned_m to track, velocity_ned_mps its feed-forward + yaw


@dataclass(frozen=True, slots=True)
class VehicleState:
    """The vehicle estimate the planner works from, sampled at `stamp_s`.

    position_ned_m: (3,) local NED, m. velocity_ned_mps: (3,) NED, m/s. yaw_rad: heading of
    the body x axis from north, rad.
    """

    stamp_s: float
    position_ned_m: np.ndarray
    velocity_ned_mps: np.ndarray
    yaw_rad: float


@dataclass(frozen=True, slots=True)
class Reference:
    """A timed path for the tracker: waypoints from `start_s`, then hold at the last one.

    times_s: (P,) times after `start_s`, first 0, ascending, s.
    positions_ned_m: (P, 3) and velocities_ned_mps: (P, 3), local NED.
    yaw_rate_radps: not None: rotate in place at this rate (recovery), the yaw policy aside.
    yaw_target_rad: not None: turn the nose to this yaw (aligning), the yaw policy aside.
    brake: True when this is a stop manoeuvre (sent as `SetpointKind.BRAKE`).
    plan_id: increases with every new reference, so the tracker sees a replan.
    """

    start_s: float
    times_s: np.ndarray
    positions_ned_m: np.ndarray
    velocities_ned_mps: np.ndarray
    plan_id: int
    yaw_rate_radps: float | None = None
    yaw_target_rad: float | None = None
    brake: bool = False

    @property
    def end_s(self) -> float:
        """Time the reference ends and the hold at its last point begins, s."""
        return self.start_s + float(self.times_s[-1])


@dataclass(frozen=True, slots=True)
class Setpoint:
    """One setpoint for the flight link, produced at `stamp_s` (the process clock, s).

    The one setpoint type from the tracker to MAVLink: the link streams it as it is.
    kind: VELOCITY and BRAKE fly `velocity_ned_mps`; POSITION flies `position_ned_m`;
        TRAJECTORY (and a BRAKE with a position, along a planned stop) fly `position_ned_m`
        with `velocity_ned_mps` as its feed-forward (the autopilot's position loop then
        corrects its own lag, PX4's trajectory_setpoint).
    acceleration_ned_mps2: (3,) NED, m/s^2, the acceleration feed-forward of a setpoint with
        a position (the turn's centripetal part the velocity loop would otherwise lag), or None.
    velocity_ned_mps: (3,) NED, m/s (zero for a position hold).
    position_ned_m: (3,) NED, m, or None when the link must fly the velocity.
    yaw_rad: nose heading from north, rad; NaN keeps the current heading (the link fills in
        the measured yaw). yaw_rate_radps: its feed-forward rate, rad/s.
    valid: False when the setpoint was built without a plan (or from stale inputs): the
        link brakes and then holds instead of flying it.
    Vectors are finite, read-only copies.
    """

    stamp_s: float
    kind: SetpointKind
    velocity_ned_mps: np.ndarray
    position_ned_m: np.ndarray | None
    yaw_rad: float
    yaw_rate_radps: float = 0.0
    valid: bool = True
    acceleration_ned_mps2: np.ndarray | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "velocity_ned_mps", _finite_vec3(self.velocity_ned_mps))
        if self.acceleration_ned_mps2 is not None:
            if self.position_ned_m is None:
                raise ValueError("an acceleration feed-forward needs position_ned_m")
            object.__setattr__(
                self, "acceleration_ned_mps2", _finite_vec3(self.acceleration_ned_mps2)
            )
        if self.position_ned_m is not None:
            object.__setattr__(self, "position_ned_m", _finite_vec3(self.position_ned_m))
        elif self.kind in (SetpointKind.POSITION, SetpointKind.TRAJECTORY):
            raise ValueError(f"a {self.kind.value.upper()} setpoint needs position_ned_m")

    @classmethod
    def velocity(cls, velocity_ned_mps: np.ndarray, yaw_rad: float, stamp_s: float) -> Setpoint:
        """A velocity + yaw setpoint."""
        return cls(stamp_s, SetpointKind.VELOCITY, velocity_ned_mps, None, float(yaw_rad))

    @classmethod
    def position(cls, position_ned_m: np.ndarray, yaw_rad: float, stamp_s: float) -> Setpoint:
        """A position + yaw setpoint (hold there)."""
        return cls(stamp_s, SetpointKind.POSITION, np.zeros(3), position_ned_m, float(yaw_rad))

    @classmethod
    def trajectory(
        cls,
        position_ned_m: np.ndarray,
        velocity_ned_mps: np.ndarray,
        yaw_rad: float,
        stamp_s: float,
        acceleration_ned_mps2: np.ndarray | None = None,
    ) -> Setpoint:
        """A point of a trajectory: its position with its velocity (and acceleration) as
        feed-forward, + yaw."""
        return cls(
            stamp_s,
            SetpointKind.TRAJECTORY,
            velocity_ned_mps,
            position_ned_m,
            float(yaw_rad),
            acceleration_ned_mps2=acceleration_ned_mps2,
        )

    @classmethod
    def brake(cls, yaw_rad: float, stamp_s: float, valid: bool = True) -> Setpoint:
        """Zero velocity, holding `yaw_rad`."""
        return cls(stamp_s, SetpointKind.BRAKE, np.zeros(3), None, float(yaw_rad), valid=valid)

    def with_yaw(self, yaw_rad: float) -> Setpoint:
        """This setpoint with its yaw replaced when it is NaN."""
        if not math.isnan(self.yaw_rad):
            return self
        return replace(self, yaw_rad=float(yaw_rad))

    def age_s(self, now_s: float) -> float:
        """How old this output is at `now_s`, s."""
        return now_s - self.stamp_s


def _finite_vec3(v: np.ndarray) -> np.ndarray:
    out = np.array(v, dtype=np.float64).reshape(3)
    if not np.all(np.isfinite(out)):
        raise ValueError(f"setpoint vector must be finite, got {out}")
    out.setflags(write=False)
    return out


@dataclass(frozen=True, slots=True)
class PlannerOutput:
    """The result of one planning cycle, stamped with the cycle's `now_s`.

    label: chosen manoeuvre ("straight", "left-1 climb-2", "stop", "rewind", ...) or "".
    cost: its eq. 4.8 cost (NaN when no library trajectory was chosen).
    distance_to_goal_m: NaN without a goal. checked: trajectories collision-checked.
    queries: occupancy queries issued. points: points queried in total.
    """

    stamp_s: float
    state: PlannerState
    reference: Reference
    label: str
    cost: float
    distance_to_goal_m: float
    checked: int
    queries: int
    points: int
