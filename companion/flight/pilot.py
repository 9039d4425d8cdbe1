"""The planning stage: the trajectory-library planner (thesis 4.5) and the path tracker.

`plan` runs one receding-horizon cycle towards the mission's goal, or brakes along the
library's stop trajectory and holds when the mission says hold (stale perception, operator
hold, end of mission). `setpoint` samples the current plan at the setpoint rate.
"""

from __future__ import annotations

import numpy as np

from mapping.query import OccupancyMap
from planning.library import generate_library
from planning.params import PlanningParams
from planning.planner import LocalPlanner
from planning.tracker import PathTracker
from planning.types import PlannerOutput, Setpoint, VehicleState


class Pilot:
    """Planner + tracker for one flight; `plan` on the map's worker, `setpoint` on the loop."""

    def __init__(self, params: PlanningParams) -> None:
        self._base = params
        self._speed_mps = params.max_speed_mps
        self._build(params)

    def _build(self, params: PlanningParams) -> None:
        self.params = params
        self.planner = LocalPlanner(params, generate_library(params))
        self.tracker = PathTracker(params)

    def adopt(self, params: PlanningParams) -> None:
        """Plan with `params` from now on (the vehicle's own limits): a new library, the goal
        and the cruise speed kept."""
        goal = self.planner.goal_ned_m
        self._base = params
        self._speed_mps = params.max_speed_mps
        self._build(params)
        if goal is not None:
            self.planner.set_goal(goal, 0.0)

    def reset(self) -> None:
        """Forget the flown path, the plan and the tracker's blend (the local frame moved)."""
        self._build(self.params)

    def set_speed(self, speed_mps: float | None, now_s: float) -> None:
        """Fly the library generated for `speed_mps` (None: `planning.max_speed_mps`)."""
        speed = self._base.max_speed_mps if speed_mps is None else speed_mps
        if speed == self._speed_mps:
            return
        goal = self.planner.goal_ned_m
        self._speed_mps = speed
        self._build(self._base.model_copy(update={"max_speed_mps": speed}))
        self.planner.set_goal(goal, now_s)

    def plan(
        self,
        now_s: float,
        vehicle: VehicleState,
        occupancy_map: OccupancyMap,
        goal_ned_m: np.ndarray | None,
        hold: bool,
        commanded_velocity_ned_mps: np.ndarray | None = None,
    ) -> PlannerOutput:
        """One planning cycle: towards `goal_ned_m`, or brake and hold when `hold` or no goal.

        commanded_velocity_ned_mps: the velocity the library starts from, (3,) NED m/s (None:
        `commanded_velocity(vehicle)` now; the process passes the one it read at the cycle's
        start, so a replay can pass the same).
        """
        current = self.planner.goal_ned_m
        if goal_ned_m is not None and (current is None or not np.array_equal(current, goal_ned_m)):
            self.planner.set_goal(goal_ned_m, now_s)
        commanded = (
            self.commanded_velocity(vehicle)
            if commanded_velocity_ned_mps is None
            else commanded_velocity_ned_mps
        )
        if hold or goal_ned_m is None:
            return self.planner.stop(now_s, vehicle, commanded)
        return self.planner.step(now_s, vehicle, commanded, occupancy_map)

    def setpoint(self, now_s: float, vehicle: VehicleState, plan: PlannerOutput | None) -> Setpoint:
        """The tracker's setpoint at `now_s` for `plan` (None: an invalid brake)."""
        reference = None if plan is None else plan.reference
        return self.tracker.setpoint(now_s, vehicle, reference, self.planner.goal_ned_m)

    def commanded_velocity(self, vehicle: VehicleState) -> np.ndarray:
        """The tracker's last commanded velocity, (3,) NED m/s (the vehicle's before any)."""
        last = self.tracker.last_setpoint
        return vehicle.velocity_ned_mps if last is None else last.velocity_ned_mps
