"""Fitted catenaries as wire obstacles for the collision check (thesis 3.7.2, beyond it).

A confident `CatenaryFit` becomes a `WireObstacle`: a tube around the observed span of the
curve whose radius is the robot radius plus k sigma of each sample's across-curve
uncertainty (the "6 sigma threshold" of 3.7.2 with k = 3). `CatenaryAwareMap` wraps any
`OccupancyMap` (the DROAN map) and adds those tubes; the wire pixels a confident catenary
explains are removed from the segmentation before DROAN turns them into its conservative
4-20 m slab (4.4.3) with `unexplained_wire_mask`, so the tube replaces the slab. All of it
sits behind `CatenaryParams.use_in_collision_check`, see `collision_map`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from geometry.camera import PinholeCamera
from geometry.pose import Pose
from geometry.shapes import distance_to_polyline_m
from mapping.catenary.fit import CatenaryFit
from mapping.catenary.params import CatenaryParams
from mapping.query import OccupancyMap, OccupancyQuery


@dataclass(frozen=True, slots=True)
class WireObstacle:
    """A tube around a polyline, NED.

    points_ned_m: `(K, 3)` samples along the observed span, NED, m (K >= 2).
    radius_m: `(K,)` tube radius at each sample (robot radius + k sigma), m.
    stamp_s: sample time of the newest keyframe behind the fit, s.
    """

    points_ned_m: np.ndarray
    radius_m: np.ndarray
    stamp_s: float


def wire_obstacle(
    fit: CatenaryFit, robot_radius_m: float, params: CatenaryParams
) -> WireObstacle | None:
    """The tube of a confident fit over its observed extent; None if the fit is not confident."""
    span = fit.observed_span
    if not fit.confident or span.sum() < 2:
        return None
    sigma_m = fit.uncertainty.point_sigma_m[span]
    return WireObstacle(
        fit.points_ned_m[span],
        robot_radius_m + params.tube_sigma_multiplier * sigma_m,
        fit.stamp_s,
    )


def inside_tube(points_ned_m: np.ndarray, obstacle: WireObstacle) -> np.ndarray:
    """`(N,) bool`: point within the tube (radius interpolated along the closest segment)."""
    distance, index, fraction = distance_to_polyline_m(points_ned_m, obstacle.points_ned_m)
    radius = obstacle.radius_m[index] + fraction * (
        obstacle.radius_m[index + 1] - obstacle.radius_m[index]
    )
    return distance <= radius


class CatenaryAwareMap:
    """`OccupancyMap` of a base map (DROAN) plus the tubes of confident catenaries.

    A point inside a tube is seen and in (solid) collision with occupancy at least `gamma`
    (`MappingParams.occupancy_threshold`, eq. 4.5); elsewhere the base map answers.
    """

    def __init__(
        self, base: OccupancyMap, obstacles: Sequence[WireObstacle], occupancy_threshold: float
    ) -> None:
        self.base = base
        self.obstacles = list(obstacles)
        self.occupancy_threshold = occupancy_threshold

    def query(self, points_ned_m: np.ndarray) -> OccupancyQuery:
        """Answers for `(N, 3)` NED points, m (see `mapping.query.OccupancyQuery`)."""
        answer = self.base.query(points_ned_m)
        in_wire = np.zeros(points_ned_m.shape[0], dtype=bool)
        for obstacle in self.obstacles:
            in_wire |= inside_tube(points_ned_m, obstacle)
        return OccupancyQuery(
            collision=answer.collision | in_wire,
            occupancy=np.where(
                in_wire, np.maximum(answer.occupancy, self.occupancy_threshold), answer.occupancy
            ),
            seen=answer.seen | in_wire,
            solid=answer.solid | in_wire,  # a reconstructed catenary is located (ch. 3)
        )


def collision_map(
    base: OccupancyMap,
    fits: Sequence[CatenaryFit],
    params: CatenaryParams,
    robot_radius_m: float,
    occupancy_threshold: float,
) -> OccupancyMap:
    """The map the collision check uses: `base` alone unless `use_in_collision_check` is on."""
    if not params.use_in_collision_check:
        return base
    obstacles = [o for f in fits if (o := wire_obstacle(f, robot_radius_m, params)) is not None]
    return CatenaryAwareMap(base, obstacles, occupancy_threshold)


def projected_curve_mask(
    camera: PinholeCamera,
    world_from_camera: Pose,
    points_ned_m: np.ndarray,
    thickness_px: int,
    min_depth_m: float = 0.3,
) -> np.ndarray:
    """`(h, w) bool` mask of the polyline through `(K, 3)` NED points drawn with cv2.

    Samples closer than `min_depth_m` are dropped and the polyline is split there.
    """
    points_cam_m = world_from_camera.inverse().apply(points_ned_m)
    mask = np.zeros(camera.shape, np.uint8)
    in_front = points_cam_m[:, 2] > min_depth_m
    if in_front.sum() < 2:
        return mask.astype(bool)
    uv_px, _ = camera.project(points_cam_m[in_front])
    limit = 4.0 * max(camera.width_px, camera.height_px)
    fixed = np.round(np.clip(uv_px, -limit, limit) * 16.0).astype(np.int32)
    breaks = np.nonzero(np.diff(np.nonzero(in_front)[0]) > 1)[0] + 1
    chunks = [c.reshape(-1, 1, 2) for c in np.split(fixed, breaks) if len(c) >= 2]
    cv2.polylines(mask, chunks, False, 255, thickness_px, cv2.LINE_8, shift=4)
    return mask.astype(bool)


def unexplained_wire_mask(
    wire_mask: np.ndarray,
    camera: PinholeCamera,
    world_from_camera: Pose,
    obstacles: Sequence[WireObstacle],
    params: CatenaryParams,
) -> np.ndarray:
    """`(h, w) bool` wire pixels not explained by any obstacle's projection.

    A pixel is explained when it lies within `explained_pixel_gate_px` of a confident
    catenary's projected observed span; DROAN builds its wire slab (4.4.3) from the rest.
    """
    thickness_px = max(1, round(2 * params.explained_pixel_gate_px) + 1)
    explained = np.zeros(wire_mask.shape, dtype=bool)
    for obstacle in obstacles:
        explained |= projected_curve_mask(
            camera, world_from_camera, obstacle.points_ned_m, thickness_px
        )
    return wire_mask & ~explained
