"""The receding-horizon trajectory-library planner of thesis 4.5, with recovery and goals.

Call `LocalPlanner.step` at `rate_hz` (>= 10 Hz) with the vehicle state, the velocity the
tracker commanded last and the occupancy map; it returns a `PlannerOutput` whose
`reference` the `PathTracker` follows between cycles. States (`PlannerState`):

- TRACKING: the cheapest free trajectory of the library bin nearest the commanded speed,
  placed at the vehicle along its commanded heading (eq. 4.7, 4.8, 4.5 collision checks).
- BRAKING: no moving trajectory is free: follow the stop trajectory (4.5).
- RECOVERING: stopped and boxed in: hold and rotate in place, re-planning every cycle along
  the nose, until a trajectory is free (4.5) or a full turn found none.
- REWINDING: no progress for `stuck_timeout_s` or a fruitless full turn: fly back along the
  recorded flown path (known free) for `rewind_distance_m`, as DROAN's descendants do.
- ALIGNING: with the goal far off the nose at the start of a goal (or after a rewind), or
  closer than the tightest library turn could reach (no orbiting the goal): brake, then
  rotate towards it before choosing a trajectory.
- ARRIVED / UNREACHABLE: hold. Unreachable: the goal seen in collision for
  `unreachable_confirm_cycles` cycles, or stuck again after `max_rewinds` rewinds.
"""

from __future__ import annotations

import numpy as np

from mapping.query import OccupancyMap
from planning.library import TrajectoryLibrary
from planning.params import PlanningParams
from planning.selection import select_trajectory
from planning.tracker import wrap_angle_rad
from planning.types import PlannerOutput, PlannerState, Reference, VehicleState

_REWIND_GRACE_S = 3.0  # extra time a rewind may take past its reference's end


class LocalPlanner:
    """Stateful planner around the pure selection; one instance per flight."""

    def __init__(self, params: PlanningParams, library: TrajectoryLibrary) -> None:
        self._params = params
        self._library = library
        self._min_track_index = int(
            min(np.searchsorted(library.times_s, params.min_track_s), len(library.times_s) - 1)
        )
        self._max_turn_rate_radps = max(
            float(np.max(np.abs(library.yaw_rates_radps))), params.hover_speed_mps
        )
        moving = library.target_speeds_mps[library.target_speeds_mps > 0]
        self._slowest_speed_mps = float(np.min(moving)) if moving.size else params.max_speed_mps
        self._goal: np.ndarray | None = None
        self._state = PlannerState.IDLE
        self._reference: Reference | None = None
        self._plan_id = 0
        self._previous_index: int | None = None
        self._crumbs: list[np.ndarray] = []
        self._best_distance_m = np.inf
        self._last_progress_s = 0.0
        self._rewinds = 0
        self._goal_hits = 0
        self._turned_rad = 0.0
        self._last_yaw_rad: float | None = None

    @property
    def state(self) -> PlannerState:
        """The current state."""
        return self._state

    @property
    def goal_ned_m(self) -> np.ndarray | None:
        """The current goal (3,), local NED, m, or None."""
        return self._goal

    @property
    def flown_path_ned_m(self) -> np.ndarray:
        """(B, 3) recorded flown path (breadcrumbs), oldest first, local NED, m."""
        return np.array(self._crumbs).reshape(-1, 3)

    def set_goal(self, goal_ned_m: np.ndarray | None, now_s: float) -> None:
        """Fly to `goal_ned_m` (3,), local NED, m; None: stop and hold."""
        self._goal = None if goal_ned_m is None else np.asarray(goal_ned_m, float).copy()
        self._state = PlannerState.IDLE
        self._reference = None
        self._previous_index = None
        self._best_distance_m = np.inf
        self._last_progress_s = now_s
        self._rewinds = 0
        self._goal_hits = 0

    def step(
        self,
        now_s: float,
        vehicle: VehicleState,
        commanded_velocity_ned_mps: np.ndarray,
        occupancy_map: OccupancyMap,
    ) -> PlannerOutput:
        """One planning cycle at `now_s`; see the module docstring for the states."""
        p = self._params
        position = np.asarray(vehicle.position_ned_m, float)
        self._record_crumb(position)
        self._track_turn(vehicle.yaw_rad)
        if self._goal is None:
            return self._hold(now_s, vehicle, PlannerState.IDLE, position)
        distance = float(np.linalg.norm(self._goal - position))
        if self._state in (PlannerState.ARRIVED, PlannerState.UNREACHABLE):
            return self._keep(now_s, distance)
        if distance <= p.arrival_tolerance_m:
            return self._hold(now_s, vehicle, PlannerState.ARRIVED, self._goal, distance)

        goal_answer = occupancy_map.query(self._goal[None, :])
        goal_blocked = bool(goal_answer.collision[0]) and bool(goal_answer.seen[0])
        self._goal_hits = self._goal_hits + 1 if goal_blocked else 0
        if self._goal_hits >= p.unreachable_confirm_cycles:
            return self._hold(now_s, vehicle, PlannerState.UNREACHABLE, position, distance, 1)

        if distance < self._best_distance_m - p.progress_min_m:
            self._best_distance_m = distance
            self._last_progress_s = now_s
            self._rewinds = 0

        if self._state is PlannerState.REWINDING:
            ref = self._reference
            ended = now_s >= ref.end_s and (
                np.linalg.norm(ref.positions_ned_m[-1] - position) <= 2 * p.arrival_tolerance_m
                or now_s >= ref.end_s + _REWIND_GRACE_S
            )
            if not ended:
                return self._keep(now_s, distance, 0, 1, 1)
            self._last_progress_s = now_s
            self._state = PlannerState.IDLE  # aligning is allowed again
        elif now_s - self._last_progress_s > p.stuck_timeout_s:
            return self._rewind_or_give_up(now_s, vehicle, position, distance)

        speed = float(np.hypot(*commanded_velocity_ned_mps[:2]))
        stopped = speed < p.hover_speed_mps
        if stopped or self._state is PlannerState.RECOVERING:
            heading = vehicle.yaw_rad
        else:
            heading = float(
                np.arctan2(commanded_velocity_ned_mps[1], commanded_velocity_ned_mps[0])
            )
        bin_index = self._library.bin_for_speed(speed)
        positions, velocities = self._library.to_world(bin_index, position, heading)
        bearing = float(np.arctan2(*(self._goal - position)[[1, 0]]))
        off_nose = abs(float(wrap_angle_rad(bearing - heading))) > p.align_heading_rad
        # the goal lies inside the circle of the tightest turn the library flies from here
        turn_speed = max(speed, self._slowest_speed_mps)
        too_close = distance < 2.0 * turn_speed / self._max_turn_rate_radps
        may_align = self._state in (PlannerState.IDLE, PlannerState.ALIGNING) or too_close
        if off_nose and may_align and self._state is not PlannerState.RECOVERING:
            if stopped:
                self._state = PlannerState.ALIGNING
                self._reference = self._static_reference(
                    vehicle.stamp_s, position, yaw_target=bearing
                )
                return self._output(now_s, "align", np.nan, distance, 0, 1, 1)
            return self._brake(
                now_s,
                vehicle,
                commanded_velocity_ned_mps,
                positions,
                velocities,
                distance,
                (0, 1, 1),
            )

        forward = np.array([np.cos(heading), np.sin(heading), 0.0])
        selection = select_trajectory(
            positions,
            velocities,
            position,
            self._goal,
            forward,
            occupancy_map,
            p,
            self._library.stop_index,
            self._min_track_index,
            self._previous_index,
        )
        counts = (selection.checked, selection.queries + 1, selection.points + 1)
        index = selection.index
        if index is not None and index != self._library.stop_index:
            self._state = PlannerState.TRACKING
            self._previous_index = index
            end = int(selection.track_index[index])
            self._reference = self._trajectory_reference(
                vehicle.stamp_s,
                position,
                commanded_velocity_ned_mps,
                positions[index, : end + 1],
                velocities[index, : end + 1],
            )
            cost = float(selection.cost[index])
            return self._output(now_s, self._library.labels[index], cost, distance, *counts)

        self._previous_index = None
        if self._state is PlannerState.RECOVERING:
            if self._turned_rad >= p.recovery_max_turn_rad:
                return self._rewind_or_give_up(now_s, vehicle, position, distance)
            return self._keep(now_s, distance, *counts)
        if stopped:
            self._state = PlannerState.RECOVERING
            self._turned_rad = 0.0
            self._reference = self._static_reference(
                vehicle.stamp_s, position, yaw_rate=p.recovery_yaw_rate_radps
            )
            return self._output(now_s, "rotate", np.nan, distance, *counts)
        return self._brake(
            now_s, vehicle, commanded_velocity_ned_mps, positions, velocities, distance, counts
        )

    # --- helpers -------------------------------------------------------------------------

    def _brake(
        self,
        now_s: float,
        vehicle: VehicleState,
        commanded_velocity_ned_mps: np.ndarray,
        positions: np.ndarray,
        velocities: np.ndarray,
        distance: float,
        counts: tuple[int, int, int],
    ) -> PlannerOutput:
        """Follow the stop trajectory of the current bin (kept while already braking)."""
        if self._state is not PlannerState.BRAKING:
            self._state = PlannerState.BRAKING
            stop = self._library.stop_index
            self._reference = self._trajectory_reference(
                vehicle.stamp_s,
                vehicle.position_ned_m,
                commanded_velocity_ned_mps,
                positions[stop],
                velocities[stop],
                brake=True,
            )
        self._previous_index = None
        return self._output(now_s, "stop", np.nan, distance, *counts)

    def _record_crumb(self, position: np.ndarray) -> None:
        """Append the position to the flown path when it moved `breadcrumb_spacing_m`."""
        if self._state is PlannerState.REWINDING:
            return
        p = self._params
        if (
            not self._crumbs
            or np.linalg.norm(position - self._crumbs[-1]) >= p.breadcrumb_spacing_m
        ):
            self._crumbs.append(position.copy())
            del self._crumbs[: -p.breadcrumb_max]

    def _track_turn(self, yaw_rad: float) -> None:
        """Accumulate the yaw turned while recovering, rad."""
        if self._last_yaw_rad is not None and self._state is PlannerState.RECOVERING:
            self._turned_rad += abs(float(wrap_angle_rad(yaw_rad - self._last_yaw_rad)))
        self._last_yaw_rad = yaw_rad

    def _rewind_or_give_up(
        self, now_s: float, vehicle: VehicleState, position: np.ndarray, distance: float
    ) -> PlannerOutput:
        """Start a rewind along the flown path, or declare the goal unreachable."""
        p = self._params
        path = self._rewind_path(position)
        if self._rewinds >= p.max_rewinds or path is None:
            return self._hold(now_s, vehicle, PlannerState.UNREACHABLE, position, distance)
        self._rewinds += 1
        self._state = PlannerState.REWINDING
        self._previous_index = None
        steps = np.linalg.norm(np.diff(path, axis=0), axis=1)
        times = np.concatenate([[0.0], np.cumsum(steps)]) / p.rewind_speed_mps
        velocities = np.zeros_like(path)
        velocities[:-1] = np.diff(path, axis=0) / np.maximum(np.diff(times), 1e-9)[:, None]
        self._plan_id += 1
        self._reference = Reference(vehicle.stamp_s, times, path, velocities, self._plan_id)
        end = path[-1]
        cut = int(np.argmin([np.linalg.norm(c - end) for c in self._crumbs]))
        del self._crumbs[cut + 1 :]
        return self._output(now_s, "rewind", np.nan, distance, 0, 0, 0)

    def _rewind_path(self, position: np.ndarray) -> np.ndarray | None:
        """(P, 3) path from `position` back along the breadcrumbs for `rewind_distance_m`."""
        crumbs = self._crumbs[::-1]
        path, length = [position], 0.0
        for crumb in crumbs:
            step = float(np.linalg.norm(crumb - path[-1]))
            if step < 1e-6:
                continue
            path.append(crumb)
            length += step
            if length >= self._params.rewind_distance_m:
                break
        return np.array(path) if length >= self._params.breadcrumb_spacing_m else None

    def _trajectory_reference(
        self,
        stamp_s: float,
        origin: np.ndarray,
        velocity0: np.ndarray,
        positions: np.ndarray,
        velocities: np.ndarray,
        brake: bool = False,
    ) -> Reference:
        """A reference starting at `origin` with `velocity0`, then the waypoints."""
        self._plan_id += 1
        return Reference(
            start_s=stamp_s,
            times_s=np.concatenate([[0.0], self._library.times_s[: len(positions)]]),
            positions_ned_m=np.vstack([origin, positions]),
            velocities_ned_mps=np.vstack([velocity0, velocities]),
            plan_id=self._plan_id,
            brake=brake,
        )

    def _static_reference(
        self,
        stamp_s: float,
        position: np.ndarray,
        yaw_rate: float | None = None,
        yaw_target: float | None = None,
    ) -> Reference:
        """Hold `position`, optionally rotating or turning to a yaw."""
        self._plan_id += 1
        return Reference(
            start_s=stamp_s,
            times_s=np.zeros(1),
            positions_ned_m=np.asarray(position, float).reshape(1, 3).copy(),
            velocities_ned_mps=np.zeros((1, 3)),
            plan_id=self._plan_id,
            yaw_rate_radps=yaw_rate,
            yaw_target_rad=yaw_target,
        )

    def _hold(
        self,
        now_s: float,
        vehicle: VehicleState,
        state: PlannerState,
        position: np.ndarray,
        distance: float = np.nan,
        queries: int = 0,
    ) -> PlannerOutput:
        """Enter `state`, holding `position` (kept if already holding in that state)."""
        if self._state is not state or self._reference is None:
            self._reference = self._static_reference(vehicle.stamp_s, position)
        self._state = state
        self._previous_index = None
        return self._output(now_s, state.value, np.nan, distance, 0, queries, queries)

    def _keep(
        self, now_s: float, distance: float, checked: int = 0, queries: int = 0, points: int = 0
    ) -> PlannerOutput:
        """Report the current state and reference unchanged."""
        return self._output(now_s, "", np.nan, distance, checked, queries, points)

    def _output(
        self,
        now_s: float,
        label: str,
        cost: float,
        distance: float,
        checked: int,
        queries: int,
        points: int,
    ) -> PlannerOutput:
        return PlannerOutput(
            stamp_s=now_s,
            state=self._state,
            reference=self._reference,
            label=label,
            cost=cost,
            distance_to_goal_m=distance,
            checked=checked,
            queries=queries,
            points=points,
        )
