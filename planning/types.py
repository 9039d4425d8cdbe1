"""Messages in and out of the planner and the path tracker. Frames: local NED, m, rad."""

from __future__ import annotations

from dataclasses import dataclass
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
    UNREACHABLE = "unreachable"  # goal inside an obstacle, or stuck after every rewind: hold


class SetpointKind(StrEnum):
    """How the flight link must send a `Setpoint`."""

    VELOCITY = "velocity"  # velocity_ned_mps + yaw
    POSITION = "position"  # position_ned_m + yaw (hold, arrival, rotate in place)
    BRAKE = "brake"  # velocity_ned_mps decelerating to zero + yaw


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
    """One setpoint for the flight link, sampled at `stamp_s`.

    velocity_ned_mps: (3,) NED, m/s (zero for a position hold).
    position_ned_m: (3,) NED, m, or None when the link must fly the velocity.
    yaw_rad: nose heading from north, rad. yaw_rate_radps: its feed-forward rate, rad/s.
    valid: False when the setpoint was built without a plan; the link must brake and hold.
    """

    stamp_s: float
    kind: SetpointKind
    velocity_ned_mps: np.ndarray
    position_ned_m: np.ndarray | None
    yaw_rad: float
    yaw_rate_radps: float
    valid: bool = True


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
