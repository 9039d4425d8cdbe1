"""Trajectory selection of thesis 4.5: prune (eq. 4.7), cost (eq. 4.8), batched collision check.

Every cycle the library bin for the current speed is placed in the world, each trajectory is
pruned at its best waypoint and costed, and trajectories are checked for collision in
ascending cost (eq. 4.5 per waypoint, answered by an `OccupancyMap`) until one is free.
The stop manoeuvre is always checked last: it is the brake of 4.5, not a way to the goal.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mapping.query import OccupancyMap
from planning.params import CheckMode, PlanningParams, UnknownPolicy

_MIN_DIRECTION_SPEED_MPS = 0.05


@dataclass(frozen=True, slots=True)
class Selection:
    """Outcome of one selection.

    index: chosen trajectory in K, or None when none is free (not even the stop).
    prune_index: (K,) waypoint i of eq. 4.7 per trajectory (0-based).
    track_index: (K,) last waypoint to follow: the prune index, stretched to
        `min_track_s` unless the goal lies closer than that.
    cost: (K,) eq. 4.8 cost plus descent, switch and (where checked) unknown-space terms.
    free: (K,) True where checked and collision-free; False where in collision or unchecked.
    checked: trajectories checked. queries: `query` calls. points: points queried.
    """

    index: int | None
    prune_index: np.ndarray
    track_index: np.ndarray
    cost: np.ndarray
    free: np.ndarray
    checked: int
    queries: int
    points: int


def waypoint_costs(
    positions_ned_m: np.ndarray,
    velocities_ned_mps: np.ndarray,
    goal_ned_m: np.ndarray,
    heading_ned: np.ndarray,
    params: PlanningParams,
) -> np.ndarray:
    """(K, M) per-waypoint cost alpha * dx_n + (1 - alpha) * dtheta_n (eq. 4.7/4.8 summand).

    dx_n: distance from waypoint n to the goal over `distance_scale_m`; dtheta_n: angle, rad,
    between the direction of travel at n and the direction from n to the goal (3D, so a
    climb away from the goal's altitude pays too). Where a trajectory has (almost) stopped,
    its direction is `heading_ned` (3,), the library's forward axis.
    """
    to_goal = np.asarray(goal_ned_m, float) - positions_ned_m
    distance = np.linalg.norm(to_goal, axis=-1)
    speed = np.linalg.norm(velocities_ned_mps, axis=-1)
    direction = np.where(
        (speed > _MIN_DIRECTION_SPEED_MPS)[..., None],
        velocities_ned_mps / np.maximum(speed, _MIN_DIRECTION_SPEED_MPS)[..., None],
        np.asarray(heading_ned, float),
    )
    cos = np.einsum("kmi,kmi->km", direction, to_goal) / np.maximum(distance, 1e-9)
    angle = np.arccos(np.clip(cos, -1.0, 1.0))
    return params.alpha * distance / params.distance_scale_m + (1.0 - params.alpha) * angle


def pruned_costs(costs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Prune index (K,) by eq. 4.7 and trajectory cost (K,) by eq. 4.8, from (K, M) costs.

    eq. 4.7: i = argmin_n c_n. eq. 4.8 sums c_1..c_i; the plain sum grows with i and so
    favours trajectories pruned early, i.e. those turning away from the goal. We divide it
    by i (the mean over the kept waypoints), which keeps the thesis' ranking intent.
    """
    prune = np.argmin(costs, axis=1)
    kept = np.arange(costs.shape[1])[None, :] <= prune[:, None]
    return prune, np.sum(costs * kept, axis=1) / (prune + 1)


def braking_distance_m(speed_mps: np.ndarray | float, params: PlanningParams) -> np.ndarray:
    """Distance to stop from `speed_mps` at max acceleration with the jerk ramp, m."""
    v = np.asarray(speed_mps, float)
    a, j = params.max_accel_mps2, params.max_jerk_mps3
    return v * v / (2.0 * a) + v * a / (2.0 * j)


def checked_waypoints(
    positions_ned_m: np.ndarray,
    velocities_ned_mps: np.ndarray,
    origin_ned_m: np.ndarray,
    end_index: np.ndarray,
    params: PlanningParams,
    own_center_ned_m: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Masks (K, M): waypoints to check, and the near ones that must be seen.

    Checked: up to the followed end `end_index` (K,) plus the braking distance at the speed
    there plus `safety_margin_m` (capped at the trajectory's end), so the vehicle can always
    stop on known-free path. Near: within the braking distance at the start speed plus the margin,
    beyond the first `own_volume_m` of arc, which the vehicle itself occupies now (no camera sees
    that close, and nothing else can be there). `own_center_ned_m` (default: the origin)
    anchors that volume: only waypoints within `own_volume_m` of it are exempt, so a vehicle
    that stopped and creeps on (recovery) cannot carry its exemption into unseen space.
    """
    origin = np.broadcast_to(np.asarray(origin_ned_m, float), positions_ned_m[:, :1].shape)
    steps = np.diff(positions_ned_m, axis=1, prepend=origin)
    arc = np.cumsum(np.linalg.norm(steps, axis=-1), axis=1)
    k = np.arange(len(end_index))
    end_speed = np.linalg.norm(velocities_ned_mps[k, end_index], axis=-1)
    needed = arc[k, end_index] + braking_distance_m(end_speed, params) + params.safety_margin_m
    checked = arc <= needed[:, None]
    # the first waypoint past the needed length closes the gap to it
    first_beyond = np.minimum(np.sum(checked, axis=1), arc.shape[1] - 1)
    checked[k, first_beyond] = True
    start_speed = np.linalg.norm(velocities_ned_mps[:, 0], axis=-1)
    near = arc <= (braking_distance_m(start_speed, params) + params.safety_margin_m)[:, None]
    center = origin if own_center_ned_m is None else np.asarray(own_center_ned_m, float)
    own = np.linalg.norm(positions_ned_m - center, axis=-1) < params.own_volume_m
    near &= ~((arc < params.own_volume_m) & own)
    return checked, near


def select_trajectory(
    positions_ned_m: np.ndarray,
    velocities_ned_mps: np.ndarray,
    origin_ned_m: np.ndarray,
    goal_ned_m: np.ndarray,
    heading_ned: np.ndarray,
    occupancy_map: OccupancyMap,
    params: PlanningParams,
    stop_index: int,
    min_track_index: int = 0,
    previous_index: int | None = None,
    own_center_ned_m: np.ndarray | None = None,
) -> Selection:
    """The cheapest collision-free trajectory of one library bin placed in the world.

    positions_ned_m, velocities_ned_mps: (K, M, 3) from `TrajectoryLibrary.to_world`.
    origin_ned_m: (3,) where they start. goal_ned_m: (3,). heading_ned: (3,) library forward.
    min_track_index: waypoint reached after `min_track_s`; previous_index: last cycle's choice.
    own_center_ned_m: where the vehicle's own volume is anchored (`checked_waypoints`).
    Trajectories are checked in ascending cost (eq. 4.8 + descent + switch terms; the switch
    term grows with the distance to last cycle's manoeuvre, against dithering), batched
    into one query (`check_mode` all) or cost-ordered chunks (chunked); with the unknown
    policy 'cost' the unseen share of the checked segment is added before picking, within
    the batch that holds the first free trajectory.
    """
    n_traj = positions_ned_m.shape[0]
    prune, cost = pruned_costs(
        waypoint_costs(positions_ned_m, velocities_ned_mps, goal_ned_m, heading_ned, params)
    )
    k = np.arange(n_traj)
    # descent below both the start and the goal: a goal below is flown down to freely
    floor_m = max(float(origin_ned_m[2]), float(np.asarray(goal_ned_m)[2]))
    descent_m = np.maximum(positions_ned_m[k, prune, 2] - floor_m, 0.0)
    cost = cost + params.descent_cost_per_m * descent_m
    if previous_index is not None:
        gap = np.linalg.norm(positions_ned_m - positions_ned_m[previous_index], axis=-1)
        reach = params.max_speed_mps * params.horizon_s
        cost = cost + params.switch_cost * gap.mean(axis=1) / reach
    goal_distance = float(np.linalg.norm(np.asarray(goal_ned_m) - origin_ned_m))
    reach = np.linalg.norm(positions_ned_m[:, min_track_index] - origin_ned_m, axis=-1)
    track = np.where(reach < goal_distance, np.maximum(prune, min_track_index), prune)
    checked, near = checked_waypoints(
        positions_ned_m, velocities_ned_mps, origin_ned_m, track, params, own_center_ned_m
    )
    floor_z = max(-params.min_altitude_m, float(origin_ned_m[2]))
    ceiling_z = min(-params.max_altitude_m, float(origin_ned_m[2]))
    z = positions_ned_m[..., 2]
    out_of_band = (z > floor_z + 1e-6) | (z < ceiling_z - 1e-6)

    order = np.argsort(np.where(k == stop_index, np.inf, cost), kind="stable")
    chunk = n_traj if params.check_mode is CheckMode.ALL else params.check_chunk_size
    free = np.zeros(n_traj, bool)
    total = cost.copy()
    queries = points = done = 0
    for start in range(0, n_traj, chunk):
        batch = order[start : start + chunk]
        mask = checked[batch]
        answer = occupancy_map.query(positions_ned_m[batch][mask])
        queries += 1
        points += int(mask.sum())
        done += len(batch)
        collide = np.zeros(mask.shape, bool)
        unseen = np.zeros(mask.shape, bool)
        collide[mask] = np.asarray(answer.collision, bool)
        unseen[mask] = ~np.asarray(answer.seen, bool)
        collide |= out_of_band[batch] & mask
        if params.unknown_policy is UnknownPolicy.COLLISION:
            collide |= unseen
        elif params.unknown_policy is UnknownPolicy.COST:
            collide |= unseen & near[batch]
            share = unseen.sum(axis=1) / np.maximum(mask.sum(axis=1), 1)
            total[batch] = cost[batch] + params.unknown_cost * share
        free[batch] = ~collide.any(axis=1)
        if free[batch].any():
            moving = free[batch] & (batch != stop_index)
            pool = batch[moving] if moving.any() else batch[free[batch]]
            best = int(pool[np.argmin(total[pool])])
            return Selection(best, prune, track, total, free, done, queries, points)
    return Selection(None, prune, track, total, free, done, queries, points)
