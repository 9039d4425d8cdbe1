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
  recorded flown path (known free) for `rewind_distance_m`, as DROAN's descendants do, the
  nose towards the goal.
- ALIGNING: with the goal far off the nose at the start of a goal (or after a rewind), or
  closer than the tightest library turn could reach (no orbiting the goal): brake, then
  rotate towards it before choosing a trajectory.
- GOAL_BLOCKED: the goal seen in solid collision (located evidence, not the wire depth
  prior: `OccupancyQuery.solid`) for `unreachable_confirm_cycles` cycles from within
  `unreachable_range_m`: hold where the vehicle is and keep checking the goal. Seen free for
  as many cycles again, fly on (beyond 4.5: one view's false obstacle ends no mission); still
  blocked after `goal_blocked_timeout_s`, unreachable.
- ARRIVED / UNREACHABLE: hold. Unreachable: blocked past its timeout, or stuck again after
  `max_rewinds` rewinds.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from geometry.rotation import wrap_angle_rad
from mapping.query import OccupancyMap
from planning.library import TrajectoryLibrary
from planning.params import PlanningParams
from planning.selection import braking_distance_m, select_trajectory
from planning.tracker import sample_reference
from planning.types import PlannerOutput, PlannerState, Reference, VehicleState

_REWIND_GRACE_S = 3.0  # extra time a rewind may take past its reference's end
_APPROACH_STEP_M = 0.2  # spacing of the points checked along a final approach
_APPROACH_DT_S = 0.1  # time step of the final approach's reference
_APPROACH_MAX_SAMPLES = 600
_CREEP_MPS = 0.05  # the approach never stalls short of the goal


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
        self._escape: Reference | None = None  # the path checked free the vehicle is flying
        self._anchor: np.ndarray | None = None  # where the vehicle's own volume is, recovering
        self._plan_id = 0
        self._previous_index: int | None = None
        self._approach_id = -1  # plan id of the final approach's reference
        self._crumbs: list[np.ndarray] = []
        self._best_distance_m = np.inf
        self._last_progress_s = 0.0
        self._rewinds = 0
        self._goal_hits = 0
        self._goal_clears = 0
        self._blocked_since_s = 0.0
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
        self._reference = self._escape = self._anchor = None
        self._previous_index = None
        self._best_distance_m = np.inf
        self._last_progress_s = now_s
        self._rewinds = 0
        self._goal_hits = self._goal_clears = 0

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
        goal_blocked = (
            bool(goal_answer.solid[0])
            and bool(goal_answer.seen[0])
            and distance <= p.unreachable_range_m
        )
        self._goal_hits = self._goal_hits + 1 if goal_blocked else 0
        self._goal_clears = 0 if goal_blocked else self._goal_clears + 1
        if self._state is PlannerState.GOAL_BLOCKED:
            if now_s - self._blocked_since_s >= p.goal_blocked_timeout_s:
                return self._hold(now_s, vehicle, PlannerState.UNREACHABLE, position, distance, 1)
            if self._goal_clears < p.unreachable_confirm_cycles:
                return self._keep(now_s, distance, 0, 1, 1)
            self._state = PlannerState.IDLE  # seen free again: fly on
            self._last_progress_s = now_s
        elif self._goal_hits >= p.unreachable_confirm_cycles:
            self._blocked_since_s = now_s
            return self._hold(now_s, vehicle, PlannerState.GOAL_BLOCKED, position, distance, 1)

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
            return self._rewind_or_give_up(now_s, vehicle, position, distance, occupancy_map)

        if (
            self._anchor is not None
            and np.linalg.norm(position - self._anchor) > 2 * p.own_volume_m
        ):
            self._anchor = None  # flown away on seen ground: the volume moves with it again
        own_center = position if self._anchor is None else self._anchor
        to_goal = self._goal - position
        if float(np.hypot(to_goal[0], to_goal[1])) <= p.approach_distance_m and (
            self._approach_is_free(position, own_center, occupancy_map)
        ):
            return self._approach(now_s, vehicle, position, distance, commanded_velocity_ned_mps)

        speed, stopped, heading, positions, velocities = self._placed_library(
            vehicle, commanded_velocity_ned_mps
        )
        bearing = float(np.arctan2(to_goal[1], to_goal[0]))
        # a goal more below or above than ahead: its bearing is noise (the vehicle circled over
        # one, turning to each new bearing), and no turn brings it into the forward camera
        ahead = float(np.hypot(to_goal[0], to_goal[1])) >= abs(float(to_goal[2]))
        off_nose = ahead and abs(float(wrap_angle_rad(bearing - heading))) > p.align_heading_rad
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
                occupancy_map,
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
            own_center,
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
            self._escape = self._checked_path(
                self._reference, positions[index], velocities[index], end
            )
            cost = float(selection.cost[index])
            return self._output(now_s, self._library.labels[index], cost, distance, *counts)

        self._previous_index = None
        if self._state is PlannerState.RECOVERING:
            if self._turned_rad >= p.recovery_max_turn_rad:
                return self._rewind_or_give_up(now_s, vehicle, position, distance, occupancy_map)
            return self._keep(now_s, distance, *counts)
        if stopped:
            self._state = PlannerState.RECOVERING
            self._turned_rad = 0.0
            if self._anchor is None:
                self._anchor = position.copy()
            self._reference = self._static_reference(
                vehicle.stamp_s, position, yaw_rate=p.recovery_yaw_rate_radps
            )
            return self._output(now_s, "rotate", np.nan, distance, *counts)
        return self._brake(
            now_s,
            vehicle,
            commanded_velocity_ned_mps,
            positions,
            velocities,
            distance,
            counts,
            occupancy_map,
        )

    def stop(
        self, now_s: float, vehicle: VehicleState, commanded_velocity_ned_mps: np.ndarray
    ) -> PlannerOutput:
        """Brake (4.5) along the path checked free that the vehicle flies (else the library's
        stop trajectory) and hold where it ends.

        For stale inputs and holds the mission orders: the goal is kept, holding is not
        counted as being stuck, and the next `step` plans from where the vehicle stopped.
        """
        position = np.asarray(vehicle.position_ned_m, float)
        self._last_progress_s = now_s
        distance = np.nan if self._goal is None else float(np.linalg.norm(self._goal - position))
        if self._state is PlannerState.BRAKING and self._reference is not None:
            return self._output(now_s, "stop", np.nan, distance, 0, 0, 0)
        _, _, _, positions, velocities = self._placed_library(vehicle, commanded_velocity_ned_mps)
        return self._brake(
            now_s, vehicle, commanded_velocity_ned_mps, positions, velocities, distance, (0, 0, 0)
        )

    # --- helpers -------------------------------------------------------------------------

    def _approach_is_free(
        self, position: np.ndarray, own_center: np.ndarray, occupancy_map: OccupancyMap
    ) -> bool:
        """The straight segment to the goal is free, and seen beyond the vehicle's own volume
        around `own_center` (beyond the thesis: the library flies forward and cannot settle on
        a nearby goal), up to the arrival sphere: inside `arrival_tolerance_m` the vehicle has
        arrived and holds on the goal. A goal just above or below, where the forward camera
        cannot look, is reached so rather than circled until the planner gives up; so is one
        metres straight above or below (`approach_distance_m` is measured horizontally), which
        every trajectory of the library, flying forward, overshoots."""
        assert self._goal is not None
        p = self._params
        length = float(np.linalg.norm(self._goal - position))
        checked = max(length - p.arrival_tolerance_m, 0.0)
        arc = np.linspace(0.0, checked, max(2, int(np.ceil(checked / _APPROACH_STEP_M)) + 1))
        points = position + (arc / max(length, 1e-9))[:, None] * (self._goal - position)
        answer = occupancy_map.query(points)
        own = (arc < p.own_volume_m) & (
            np.linalg.norm(points - own_center, axis=1) < p.own_volume_m
        )
        unknown = ~np.asarray(answer.seen, bool) & ~own
        return not (np.asarray(answer.collision, bool).any() or unknown.any())

    def _approach_profile(
        self, position: np.ndarray, commanded_velocity_ned_mps: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(times (P,), positions (P, 3), velocities (P, 3)) along the segment to the goal:
        from the commanded speed along it, towards `approach_speed_mps` (its vertical part
        within `max_vertical_speed_mps`) within `max_accel_mps2`, slowing so that the tracker's
        stopping cap is never exceeded."""
        assert self._goal is not None
        p = self._params
        length = float(np.linalg.norm(self._goal - position))
        direction = (self._goal - position) / max(length, 1e-9)
        cruise = min(p.approach_speed_mps, p.max_vertical_speed_mps / max(abs(direction[2]), 1e-9))
        speed = max(float(commanded_velocity_ned_mps @ direction), 0.0)
        dt, a = _APPROACH_DT_S, p.max_accel_mps2
        arcs, speeds = [0.0], [speed]
        while arcs[-1] < length and len(arcs) < _APPROACH_MAX_SAMPLES:
            target = min(cruise, np.sqrt(a * (length - arcs[-1])))
            speed = max(speed + float(np.clip(target - speed, -a * dt, a * dt)), _CREEP_MPS)
            arcs.append(min(length, arcs[-1] + speed * dt))
            speeds.append(speed)
        speeds[-1] = 0.0
        arc = np.array(arcs)
        times = dt * np.arange(len(arc))
        return times, position + arc[:, None] * direction, np.array(speeds)[:, None] * direction

    def _approach(
        self,
        now_s: float,
        vehicle: VehicleState,
        position: np.ndarray,
        distance: float,
        commanded: np.ndarray,
    ) -> PlannerOutput:
        """Fly the free straight segment to the goal at `approach_speed_mps` and hold there.
        A segment longer than one reference holds (`_APPROACH_MAX_SAMPLES`: a climb of tens of
        metres) is flown in legs, the next planned when the last one ends."""
        ref = self._reference
        approaching = (
            ref is not None
            and ref.plan_id == self._approach_id
            and (vehicle.stamp_s < ref.end_s or np.allclose(ref.positions_ned_m[-1], self._goal))
        )
        if self._state is not PlannerState.TRACKING or not approaching:
            times, positions, velocities = self._approach_profile(position, commanded)
            self._plan_id += 1
            self._reference = self._escape = Reference(
                vehicle.stamp_s, times, positions, velocities, self._plan_id
            )
            self._approach_id = self._plan_id
        self._state = PlannerState.TRACKING
        self._previous_index = None
        return self._output(now_s, "approach", np.nan, distance, 0, 1, 1)

    def _placed_library(
        self, vehicle: VehicleState, commanded_velocity_ned_mps: np.ndarray
    ) -> tuple[float, bool, float, np.ndarray, np.ndarray]:
        """(speed, stopped, heading, positions, velocities) of the library set for the
        commanded speed, placed at the vehicle along its commanded heading (its nose when
        stopped or recovering)."""
        speed = float(np.hypot(*commanded_velocity_ned_mps[:2]))
        stopped = speed < self._params.hover_speed_mps
        if stopped or self._state is PlannerState.RECOVERING:
            heading = vehicle.yaw_rad
        else:
            heading = float(
                np.arctan2(commanded_velocity_ned_mps[1], commanded_velocity_ned_mps[0])
            )
        bin_index = self._library.bin_for_speed(speed)
        position = np.asarray(vehicle.position_ned_m, float)
        positions, velocities = self._library.to_world(bin_index, position, heading)
        return speed, stopped, heading, positions, velocities

    def _brake(
        self,
        now_s: float,
        vehicle: VehicleState,
        commanded_velocity_ned_mps: np.ndarray,
        positions: np.ndarray,
        velocities: np.ndarray,
        distance: float,
        counts: tuple[int, int, int],
        occupancy_map: OccupancyMap | None = None,
    ) -> PlannerOutput:
        """Stop (kept while already braking): along the path checked free that the vehicle
        is flying when it is on one, else the stop trajectory of the current bin.

        With `occupancy_map` (the map that made the planner brake) the stop along the path
        is checked against it first: that path was checked before the obstacle now in the
        way was mapped (a wire stereo places 2 m ahead), and where it runs into it while the
        bin's stop trajectory, level along the commanded heading, runs into it later or not
        at all, the vehicle brakes along the latter (beyond 4.5: a descending path would
        carry the brake down into a wire below)."""
        if self._state is not PlannerState.BRAKING:
            self._state = PlannerState.BRAKING
            stop = self._library.stop_index
            speed = float(np.linalg.norm(commanded_velocity_ned_mps))
            along = self._stop_on_escape(now_s, vehicle, speed)
            level = np.vstack([vehicle.position_ned_m, positions[stop]])
            if along is None or (
                occupancy_map is not None
                and _arc_to_collision_m(level, occupancy_map)
                > _arc_to_collision_m(along.positions_ned_m, occupancy_map)
            ):
                along = self._trajectory_reference(
                    vehicle.stamp_s,
                    vehicle.position_ned_m,
                    commanded_velocity_ned_mps,
                    positions[stop],
                    velocities[stop],
                    brake=True,
                )
            self._reference = along
            self._escape = None
        self._previous_index = None
        return self._output(now_s, "stop", np.nan, distance, *counts)

    def _checked_path(
        self, reference: Reference, positions: np.ndarray, velocities: np.ndarray, end: int
    ) -> Reference:
        """`reference` continued along its library trajectory (`positions`, `velocities`:
        (M, 3)) as far as selection checked it free: the braking distance at the speed of
        the followed end `end` plus `safety_margin_m` beyond it (`checked_waypoints`)."""
        arc = np.cumsum(
            np.linalg.norm(
                np.diff(positions, axis=0, prepend=reference.positions_ned_m[:1]), axis=1
            )
        )
        speed_end = float(np.linalg.norm(velocities[end]))
        needed = arc[end] + float(braking_distance_m(speed_end, self._params))
        last = int(min(np.searchsorted(arc, needed + self._params.safety_margin_m), len(arc) - 1))
        return replace(
            reference,
            times_s=np.concatenate([[0.0], self._library.times_s[: last + 1]]),
            positions_ned_m=np.vstack([reference.positions_ned_m[:1], positions[: last + 1]]),
            velocities_ned_mps=np.vstack(
                [reference.velocities_ned_mps[:1], velocities[: last + 1]]
            ),
        )

    def _stop_on_escape(
        self, now_s: float, vehicle: VehicleState, speed_mps: float
    ) -> Reference | None:
        """A stop from `speed_mps` along the escape path from where it is at `now_s`, or None
        when the vehicle is not on it (farther than `stop_path_max_gap_m`) or it has ended.

        Constant deceleration at `max_accel_mps2`, s(t) = v0 t - a t^2 / 2, harder when the
        path left is shorter than that stop: the vehicle stops on path that selection checked
        free (its braking distance included), where the library's own stop trajectory, placed
        along the commanded velocity, runs on unchecked ground.
        """
        escape, p = self._escape, self._params
        if escape is None or now_s - escape.start_s > escape.times_s[-1]:
            return None
        start, _ = sample_reference(escape, now_s - escape.start_s)
        if np.linalg.norm(start - vehicle.position_ned_m) > p.stop_path_max_gap_m:
            return None
        path = np.vstack([start, escape.positions_ned_m[escape.times_s > now_s - escape.start_s]])
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
        if speed_mps < p.hover_speed_mps or arc[-1] < 1e-6:
            return None
        decel = max(p.max_accel_mps2, speed_mps**2 / (2.0 * arc[-1]))
        duration = speed_mps / decel
        dt = float(self._library.times_s[1] - self._library.times_s[0])
        times = np.linspace(0.0, duration, max(2, int(np.ceil(duration / dt)) + 1))
        along = speed_mps * times - 0.5 * decel * times**2
        positions = np.column_stack([np.interp(along, arc, path[:, i]) for i in range(3)])
        velocities = np.gradient(positions, times, axis=0)
        velocities[-1] = 0.0
        self._plan_id += 1
        return Reference(vehicle.stamp_s, times, positions, velocities, self._plan_id, brake=True)

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
        self,
        now_s: float,
        vehicle: VehicleState,
        position: np.ndarray,
        distance: float,
        occupancy_map: OccupancyMap,
    ) -> PlannerOutput:
        """Start a rewind along the flown path, or declare the goal unreachable.

        The rewind backs off facing the goal: the camera keeps the obstacle that stopped the
        vehicle in view from ever farther off, whose changing rays triangulate the wire depth
        prior (4.4.3) into place, and no turn away and back (align) is spent; the flown path
        is known free whichever way the nose points.
        """
        p = self._params
        path = self._rewind_path(position)
        if self._rewinds >= p.max_rewinds or path is None:
            return self._hold(now_s, vehicle, PlannerState.UNREACHABLE, position, distance)
        path = self._climbing_rewind(path, occupancy_map)
        self._rewinds += 1
        self._state = PlannerState.REWINDING
        self._previous_index = None
        steps = np.linalg.norm(np.diff(path, axis=0), axis=1)
        times = np.concatenate([[0.0], np.cumsum(steps)]) / p.rewind_speed_mps
        velocities = np.zeros_like(path)
        velocities[:-1] = np.diff(path, axis=0) / np.maximum(np.diff(times), 1e-9)[:, None]
        self._plan_id += 1
        assert self._goal is not None
        to_goal = self._goal - position
        self._reference = self._escape = Reference(
            vehicle.stamp_s,
            times,
            path,
            velocities,
            self._plan_id,
            yaw_target_rad=float(np.arctan2(to_goal[1], to_goal[0])),
        )
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

    def _climbing_rewind(self, path: np.ndarray, occupancy_map: OccupancyMap) -> np.ndarray:
        """`path` (P, 3) with its height ramped by `rewind_climb_m` at its end, up on the
        first, third... rewind and down on the others (the other way, else level, where the
        map has not seen the ramped path free or it leaves the altitude band).

        Beyond the thesis: the wire depth prior (4.4.3) is triangulated by views from
        different places, and the views that tell most are from another height: a wire level
        with the camera lies on the horizon, where the CNN misses it against the tree line.
        The vehicle leaves the flown path only through space seen free.
        """
        p = self._params
        if p.rewind_climb_m <= 0:
            return path
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
        share = arc / max(arc[-1], 1e-9)
        samples = max(2, int(np.ceil(arc[-1] / _APPROACH_STEP_M)) + 1)
        along = np.linspace(0.0, arc[-1], samples)
        up_first = self._rewinds % 2 == 0  # this rewind is counted after it starts
        for up in (up_first, not up_first):
            ramped = path.copy()
            ramped[:, 2] -= (1.0 if up else -1.0) * p.rewind_climb_m * share
            heights = -ramped[:, 2]
            if heights.max() > p.max_altitude_m or heights.min() < p.min_altitude_m:
                continue
            ramp = np.column_stack([np.interp(along, arc, ramped[:, i]) for i in range(3)])
            # and the way back to the flown path that a later rewind takes from its end
            points = np.vstack([ramp, np.linspace(ramped[-1], path[-1], samples)])
            answer = occupancy_map.query(points)
            own = np.linalg.norm(points - path[0], axis=1) < p.own_volume_m
            unknown = ~np.asarray(answer.seen, bool) & ~own
            if not (np.asarray(answer.collision, bool).any() or unknown.any()):
                return ramped
        return path

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
        self._escape = None
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


def _arc_to_collision_m(points: np.ndarray, occupancy_map: OccupancyMap) -> float:
    """Path length along the (P, 3) path `points` to its first point in collision, m (inf:
    none)."""
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    hit = np.flatnonzero(np.asarray(occupancy_map.query(points).collision, bool))
    return float(arc[hit[0]]) if hit.size else np.inf
