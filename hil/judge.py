"""The judge of a simulated flight: clearances and collisions on the world's true geometry.

Never on the map: distances come from `geometry.shapes` (boxes and wire tubes) of the `World`
the cameras rendered. Clearance is the distance from the vehicle's centre to the nearest
surface, m (negative inside); a collision is an episode during which the clearance to a solid,
a wire or the ground is below the vehicle's radius. The ground counts only while the vehicle
is airborne (not landed or taking off). Frames: NED, m.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hil.world.model import World

_CHUNK = 4096
_RELEASE_M = 0.05  # clearance above the radius that ends a contact episode (no chattering)
_MAX_STEP_M = 0.05  # the flown path is judged at least this densely


def clearance_m(world: World, points_ned_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distances of `(N, 3)` NED points to the world's true surfaces, m (< 0 inside).

    Returns `(obstacle_m (N,), wire_m (N,))`: to the nearest solid surface (ground excluded,
    see `ground_clearance_m`) and to the nearest wire surface; inf where there is none.
    """
    points = np.asarray(points_ned_m, dtype=np.float64).reshape(-1, 3)
    obstacle = np.full(len(points), np.inf)
    wire = np.full(len(points), np.inf)
    for start in range(0, len(points), _CHUNK):
        chunk = points[start : start + _CHUNK]
        rows = slice(start, start + len(chunk))
        for solid in world.solids:
            obstacle[rows] = np.minimum(obstacle[rows], solid.box.distance_m(chunk))
        for w in world.wires:
            lo = w.points_ned_m.min(axis=0) - w.radius_m
            hi = w.points_ned_m.max(axis=0) + w.radius_m
            # a lower bound from the wire's bounding box skips far wires cheaply
            bound = np.linalg.norm(np.maximum(np.maximum(lo - chunk, chunk - hi), 0.0), axis=1)
            near = bound < wire[rows]
            if near.any():
                index = np.flatnonzero(near) + start
                wire[index] = np.minimum(wire[index], w.distance_m(points[index]))
    return obstacle, wire


def ground_clearance_m(world: World, points_ned_m: np.ndarray) -> np.ndarray:
    """`(N,)` height of NED points above the ground plane, m."""
    points = np.asarray(points_ned_m, dtype=np.float64).reshape(-1, 3)
    return world.ground_down_m - points[:, 2]


@dataclass(frozen=True, slots=True)
class FlightVerdict:
    """What a flight did, judged on the true geometry.

    collisions: distinct contact episodes (any kind), and per kind (solids, wires, ground).
    min_clearance_m / min_wire_clearance_m / min_ground_clearance_m: closest approach of the
        vehicle's centre to a solid / a wire / the ground while airborne, m (inf: none).
    path_length_m, duration_s: flown distance (m) and time from the first to the last sample.
    goals_reached: per goal, reached (within the goal radius, in order); goal_times_s: when
        (NaN if never).
    """

    collisions: int
    obstacle_collisions: int
    wire_collisions: int
    ground_collisions: int
    min_clearance_m: float
    min_wire_clearance_m: float
    min_ground_clearance_m: float
    path_length_m: float
    duration_s: float
    goals_reached: tuple[bool, ...]
    goal_times_s: tuple[float, ...]

    @property
    def success(self) -> bool:
        """Every goal reached and nothing hit."""
        return all(self.goals_reached) and self.collisions == 0


def contact_episodes(in_contact: np.ndarray, released: np.ndarray) -> int:
    """Number of episodes in a sampled signal: an episode starts at a sample `in_contact`
    and lasts until a sample `released` (in_contact implies not released)."""
    count, inside = 0, False
    for contact, free in zip(in_contact, released, strict=True):
        if contact and not inside:
            count += 1
            inside = True
        elif free:
            inside = False
    return count


class FlightJudge:
    """Accumulates a flown truth path and judges it against `world` (see module docstring).

    vehicle_radius_m: the vehicle's radius (collision below it), m.
    goal_radius_m: a goal counts as reached within this distance of the vehicle's centre, m.
    """

    def __init__(self, world: World, vehicle_radius_m: float, goal_radius_m: float) -> None:
        self.world = world
        self.vehicle_radius_m = float(vehicle_radius_m)
        self.goal_radius_m = float(goal_radius_m)
        self._stamps: list[float] = []
        self._points: list[np.ndarray] = []
        self._on_ground: list[bool] = []

    def add(self, stamp_s: float, position_ned_m: np.ndarray, on_ground: bool = False) -> None:
        """One true position `(3,)` NED (m) at `stamp_s` (s); `on_ground` while landed or
        taking off (ground contact is then no collision)."""
        self._stamps.append(float(stamp_s))
        self._points.append(np.asarray(position_ned_m, dtype=np.float64).reshape(3).copy())
        self._on_ground.append(bool(on_ground))

    @property
    def path_ned_m(self) -> np.ndarray:
        """`(N, 3)` positions added so far, NED, m."""
        return np.array(self._points).reshape(-1, 3)

    def _dense(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions, stamps and on-ground flags interpolated <= 5 cm apart."""
        path = self.path_ned_m
        stamps = np.array(self._stamps)
        ground = np.array(self._on_ground)
        if len(path) < 2:
            return path, stamps, ground
        steps = np.linalg.norm(np.diff(path, axis=0), axis=1)
        counts = np.maximum(np.ceil(steps / _MAX_STEP_M).astype(int), 1)
        segment = np.repeat(np.arange(len(steps)), counts)
        fraction = np.concatenate([np.arange(c) / c for c in counts])
        dense = path[segment] + fraction[:, None] * (path[segment + 1] - path[segment])
        times = stamps[segment] + fraction * (stamps[segment + 1] - stamps[segment])
        flags = ground[segment] & ground[segment + 1]
        return (
            np.vstack([dense, path[-1:]]),
            np.append(times, stamps[-1]),
            np.append(flags, ground[-1]),
        )

    def verdict(self) -> FlightVerdict:
        """The verdict on the path added so far."""
        path, stamps, on_ground = self._dense()
        if len(path) == 0:
            nothing = tuple(False for _ in self.world.goals_ned_m)
            return FlightVerdict(
                0, 0, 0, 0, np.inf, np.inf, np.inf, 0.0, 0.0, nothing, (np.nan,) * len(nothing)
            )
        obstacle, wire = clearance_m(self.world, path)
        ground = np.where(on_ground, np.inf, ground_clearance_m(self.world, path))
        r = self.vehicle_radius_m
        kinds = [contact_episodes(d < r, d >= r + _RELEASE_M) for d in (obstacle, wire, ground)]
        nearest = np.minimum(np.minimum(obstacle, wire), ground)
        total = contact_episodes(nearest < r, nearest >= r + _RELEASE_M)
        reached, times = [], []
        first = 0
        for goal in self.world.goals_ned_m:
            near = np.flatnonzero(np.linalg.norm(path[first:] - goal, axis=1) <= self.goal_radius_m)
            if near.size and (not reached or reached[-1]):
                first += int(near[0])
                reached.append(True)
                times.append(float(stamps[first]))
            else:
                reached.append(False)
                times.append(float("nan"))
        airborne = ~on_ground
        return FlightVerdict(
            collisions=total,
            obstacle_collisions=kinds[0],
            wire_collisions=kinds[1],
            ground_collisions=kinds[2],
            min_clearance_m=float(obstacle.min()),
            min_wire_clearance_m=float(wire.min()),
            min_ground_clearance_m=float(ground[airborne].min()) if airborne.any() else np.inf,
            path_length_m=float(np.linalg.norm(np.diff(self.path_ned_m, axis=0), axis=1).sum()),
            duration_s=float(self._stamps[-1] - self._stamps[0]),
            goals_reached=tuple(reached),
            goal_times_s=tuple(times),
        )


def plot_flight(
    world: World,
    path_ned_m: np.ndarray,
    out_png: str | Path,
    goals: np.ndarray | None = None,
    title: str | None = None,
) -> Path:
    """Write a PNG with a top view (east right, north up) and a side view (north right,
    height up) of the flown `(N, 3)` NED path, the solids, the wires, the start and the
    `(K, 3)` goals (default the world's); returns the path written."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt
    from matplotlib.patches import Rectangle

    path = np.asarray(path_ned_m, dtype=np.float64).reshape(-1, 3)
    goals = world.goals_ned_m if goals is None else np.asarray(goals, float).reshape(-1, 3)
    g = world.ground_down_m
    fig, (top, side) = plt.subplots(1, 2, figsize=(13, 5.5))
    colours = {"tree": "#3a7d2c", "building": "#a0522d", "ladder": "#7f8c8d", "tower": "#555"}
    for solid in world.solids:
        lo, hi = solid.box.min_ned_m, solid.box.max_ned_m
        colour = colours.get(solid.kind, "#8899aa")
        top.add_patch(Rectangle((lo[1], lo[0]), hi[1] - lo[1], hi[0] - lo[0], color=colour))
        side.add_patch(Rectangle((lo[0], g - hi[2]), hi[0] - lo[0], hi[2] - lo[2], color=colour))
    for k, wire in enumerate(world.wires):
        p = wire.points_ned_m
        label = "wires" if k == 0 else None
        top.plot(p[:, 1], p[:, 0], color="black", lw=1.0, label=label)
        side.plot(p[:, 0], g - p[:, 2], color="black", lw=1.0, label=label)
    for ax, x, y in ((top, path[:, 1], path[:, 0]), (side, path[:, 0], g - path[:, 2])):
        ax.plot(x, y, color="tab:red", lw=1.5, label="flight")
    start = world.start_ned_m
    top.plot(start[1], start[0], "g^", ms=9, label="start")
    side.plot(start[0], g - start[2], "g^", ms=9)
    if len(goals):
        top.plot(goals[:, 1], goals[:, 0], "b*", ms=12, label="goals")
        side.plot(goals[:, 0], g - goals[:, 2], "b*", ms=12)
    top.set(xlabel="east, m", ylabel="north, m", title="top view", aspect="equal")
    side.set(xlabel="north, m", ylabel="height above ground, m", title="side view")
    side.set_aspect("equal", adjustable="datalim")
    side.axhline(0.0, color="#6b4f2a", lw=1)
    top.legend(loc="best", fontsize=8)
    for ax in (top, side):
        ax.grid(alpha=0.3)
        ax.autoscale_view()
    fig.suptitle(title or world.name)
    fig.tight_layout()
    out = Path(out_png)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
