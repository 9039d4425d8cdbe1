"""A synthetic `OccupancyMap`: boxes and wires, seen only inside recorded camera views.

Stands in for the DROAN map in planner tests and in `wireavoid bench planning` when no
DROAN map is available. Obstacles are axis-aligned boxes (walls, canyons, the goal's
building) and thin cylinders (wires), both grown by `inflation_m` (the configuration space
of 4.4.3). A point is seen when it lies inside the frustum of one of the last `max_views`
views (a pose graph of views, 4.4.6), occlusion ignored; only seen points can be in
collision, as in a real map. Frames: local NED, m; a view's camera looks along its yaw.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from geometry.shapes import Box, Wire
from mapping.query import OccupancyQuery


@dataclass(frozen=True, slots=True)
class View:
    """A camera view: position (3,) NED, m; yaw from north, rad; level camera."""

    position_ned_m: np.ndarray
    yaw_rad: float


@dataclass
class SyntheticOccupancyMap:
    """Boxes and wires, observed through views; implements `mapping.query.OccupancyMap`.

    horizontal_fov_rad, vertical_fov_rad, max_range_m: the frustum of every view.
    omniscient: every point counts as seen (no views needed).
    """

    boxes: list[Box] = field(default_factory=list)
    wires: list[Wire] = field(default_factory=list)
    inflation_m: float = 0.5
    horizontal_fov_rad: float = 1.6
    vertical_fov_rad: float = 1.2
    max_range_m: float = 15.0
    max_views: int = 20
    omniscient: bool = False
    views: list[View] = field(default_factory=list)

    def add_view(self, position_ned_m: np.ndarray, yaw_rad: float) -> None:
        """Record a view (oldest dropped beyond `max_views`)."""
        self.views.append(View(np.asarray(position_ned_m, float).copy(), float(yaw_rad)))
        del self.views[: -self.max_views]

    def occupied(self, points_ned_m: np.ndarray) -> np.ndarray:
        """(N,) True where a point lies inside an inflated obstacle (seen or not)."""
        pts = np.asarray(points_ned_m, float).reshape(-1, 3)
        hit = np.zeros(len(pts), bool)
        r = self.inflation_m
        for box in self.boxes:
            hit |= np.all((pts >= box.min_ned_m - r) & (pts <= box.max_ned_m + r), axis=1)
        for wire in self.wires:
            hit |= wire.distance_m(pts) <= r
        return hit

    def seen(self, points_ned_m: np.ndarray) -> np.ndarray:
        """(N,) True where a point lies in the frustum of a recorded view."""
        pts = np.asarray(points_ned_m, float).reshape(-1, 3)
        if self.omniscient:
            return np.ones(len(pts), bool)
        if not self.views:
            return np.zeros(len(pts), bool)
        origins = np.array([v.position_ned_m for v in self.views])  # (V, 3)
        yaws = np.array([v.yaw_rad for v in self.views])  # (V,)
        rel = pts[None, :, :] - origins[:, None, :]  # (V, N, 3)
        c, s = np.cos(yaws)[:, None], np.sin(yaws)[:, None]
        forward = c * rel[..., 0] + s * rel[..., 1]
        right = -s * rel[..., 0] + c * rel[..., 1]
        in_view = (
            (forward > 0.0)
            & (np.abs(np.arctan2(right, forward)) <= self.horizontal_fov_rad / 2)
            & (np.abs(np.arctan2(rel[..., 2], forward)) <= self.vertical_fov_rad / 2)
            & (np.linalg.norm(rel, axis=-1) <= self.max_range_m)
        )
        return in_view.any(axis=0)

    def query(self, points_ned_m: np.ndarray) -> OccupancyQuery:
        """`OccupancyMap.query`: collision only where seen; occupancy 1 there, else 0."""
        seen = self.seen(points_ned_m)
        collision = self.occupied(points_ned_m) & seen
        return OccupancyQuery(
            collision=collision, occupancy=collision.astype(float), seen=seen, solid=collision
        )


def wall(
    distance_m: float, half_width_m: float, top_altitude_m: float, thickness_m: float = 0.3
) -> Box:
    """A wall across the north axis at `distance_m`, from the ground to `top_altitude_m`."""
    return Box(
        np.array([distance_m, -half_width_m, -top_altitude_m]),
        np.array([distance_m + thickness_m, half_width_m, 0.0]),
    )


def wire_across(distance_m: float, altitude_m: float, half_span_m: float = 30.0) -> Wire:
    """A horizontal wire across the north axis at `distance_m`, `altitude_m` above home."""
    return Wire.straight(
        np.array([distance_m, -half_span_m, -altitude_m]),
        np.array([distance_m, half_span_m, -altitude_m]),
    )


def corridor(start_m: float, end_m: float, half_width_m: float, height_m: float) -> list[Box]:
    """Two walls along the north axis, `half_width_m` either side of it, 0.3 m thick."""
    return [
        Box(
            np.array([start_m, -half_width_m - 0.3, -height_m]),
            np.array([end_m, -half_width_m, 0.0]),
        ),
        Box(
            np.array([start_m, half_width_m, -height_m]), np.array([end_m, half_width_m + 0.3, 0.0])
        ),
    ]


def box_canyon(
    start_m: float, end_m: float, half_width_m: float, height_m: float, roof: bool = True
) -> list[Box]:
    """A corridor closed at its north end (and roofed at `height_m`): a dead end."""
    boxes = [
        *corridor(start_m, end_m, half_width_m, height_m),
        Box(
            np.array([end_m, -half_width_m - 0.3, -height_m]),
            np.array([end_m + 0.3, half_width_m + 0.3, 0.0]),
        ),
    ]
    if roof:
        boxes.append(
            Box(
                np.array([start_m, -half_width_m - 0.3, -height_m - 0.3]),
                np.array([end_m + 0.3, half_width_m + 0.3, -height_m]),
            )
        )
    return boxes
