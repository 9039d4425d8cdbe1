"""What the live view draws besides the recorded channels (pure: arrays in, JSON out).

Foxglove's 3D panel in the `local_ned` frame (under the z-up `world` of the recording):
the DROAN map around the vehicle as a point cloud (the fused frames' disparity back-projected
by eq. 4.1-4.2 at the pose each was registered at; wire pixels red), the trajectory library
placed at the vehicle (grey) with the chosen trajectory (green), the goal (a sphere) and the
flown path (a line). The planner does not report which trajectories it pruned, so the library
is drawn whole.
"""

from __future__ import annotations

import base64
from typing import Any

import numpy as np

from companion.record.codec import foxglove_time
from geometry.camera import StereoRig
from geometry.pose import Pose
from planning.library import TrajectoryLibrary

_FLOAT32 = 7  # foxglove.NumericType
_UINT8 = 1


def _point(p: np.ndarray) -> dict[str, float]:
    return {"x": float(p[0]), "y": float(p[1]), "z": float(p[2])}


def frame_points_ned_m(
    rig: StereoRig,
    world_from_camera: Pose,
    disparity_px: np.ndarray,
    wire_mask: np.ndarray | None,
    stride_px: int = 4,
    max_range_m: float = 25.0,
) -> tuple[np.ndarray, np.ndarray]:
    """The returns of one frame as `(N, 3)` local NED points, m, and `(N,)` bool wire flags.

    Every `stride_px`-th pixel with a positive, finite disparity is back-projected at depth
    b f / d (eq. 4.1) along its ray (eq. 4.2); `wire_mask` (on the colour image, an integer
    down-scale of the disparity image) marks the wire pixels.
    """
    d = np.asarray(disparity_px, dtype=np.float64)[::stride_px, ::stride_px]
    v, u = np.mgrid[0 : disparity_px.shape[0] : stride_px, 0 : disparity_px.shape[1] : stride_px]
    valid = np.isfinite(d) & (d > 0)
    depth = np.where(valid, rig.depth_from_disparity(np.where(valid, d, 1.0)), np.inf)
    valid &= depth < max_range_m
    cam = rig.camera
    x = (u[valid] - cam.cx_px) / cam.fx_px * depth[valid]
    y = (v[valid] - cam.cy_px) / cam.fy_px * depth[valid]
    points = world_from_camera.apply(np.stack([x, y, depth[valid]], axis=1))
    wire = np.zeros(len(points), dtype=bool)
    if wire_mask is not None:
        scale = max(disparity_px.shape[1] // wire_mask.shape[1], 1)
        rows = np.clip(v[valid] // scale, 0, wire_mask.shape[0] - 1)
        cols = np.clip(u[valid] // scale, 0, wire_mask.shape[1] - 1)
        wire = np.asarray(wire_mask, dtype=bool)[rows, cols]
    return points, wire


def point_cloud(stamp_s: float, points_ned_m: np.ndarray, wire: np.ndarray) -> dict[str, Any]:
    """A `foxglove.PointCloud` (x, y, z float32 and rgba uint8 per point; wires red)."""
    n = len(points_ned_m)
    record = np.zeros(n, dtype=[("xyz", "<f4", 3), ("rgba", "u1", 4)])
    record["xyz"] = points_ned_m
    record["rgba"] = np.where(wire[:, None], [230, 30, 30, 255], [120, 170, 230, 200])
    return {
        "timestamp": foxglove_time(stamp_s),
        "frame_id": "local_ned",
        "pose": {
            "position": {"x": 0.0, "y": 0.0, "z": 0.0},
            "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
        },
        "point_stride": 16,
        "fields": [
            {"name": "x", "offset": 0, "type": _FLOAT32},
            {"name": "y", "offset": 4, "type": _FLOAT32},
            {"name": "z", "offset": 8, "type": _FLOAT32},
            {"name": "red", "offset": 12, "type": _UINT8},
            {"name": "green", "offset": 13, "type": _UINT8},
            {"name": "blue", "offset": 14, "type": _UINT8},
            {"name": "alpha", "offset": 15, "type": _UINT8},
        ],
        "data": base64.b64encode(record.tobytes()).decode("ascii"),
    }


def placed_library_ned_m(
    library: TrajectoryLibrary, position_ned_m: np.ndarray, yaw_rad: float, speed_mps: float
) -> np.ndarray:
    """The library's trajectories of the speed bin nearest `speed_mps`, rotated to `yaw_rad`
    and moved to `position_ned_m`: `(K, M, 3)` local NED, m."""
    s = int(np.argmin(np.abs(library.initial_speeds_mps - speed_mps)))
    local = library.positions_m[s]  # x forward, y right, z down
    c, si = np.cos(yaw_rad), np.sin(yaw_rad)
    rotation = np.array([[c, -si, 0.0], [si, c, 0.0], [0.0, 0.0, 1.0]])
    return local @ rotation.T + np.asarray(position_ned_m, dtype=np.float64)


def _line(entity_points: np.ndarray, rgba: tuple[float, float, float, float], width: float):
    return {
        "type": 0,  # LINE_STRIP
        "pose": {
            "position": {"x": 0.0, "y": 0.0, "z": 0.0},
            "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
        },
        "thickness": width,
        "scale_invariant": False,
        "points": [_point(p) for p in entity_points],
        "color": dict(zip(("r", "g", "b", "a"), rgba, strict=True)),
        "colors": [],
        "indices": [],
    }


def plan_scene(
    stamp_s: float,
    library_ned_m: np.ndarray | None,
    chosen_ned_m: np.ndarray,
    goal_ned_m: np.ndarray | None,
    path_ned_m: np.ndarray,
) -> dict[str, Any]:
    """A `foxglove.SceneUpdate`: the library (grey), the chosen trajectory (green), the goal
    (an orange sphere) and the flown path (white)."""
    lines = []
    if library_ned_m is not None:
        lines += [_line(t, (0.6, 0.6, 0.6, 0.35), 0.02) for t in library_ned_m]
    lines.append(_line(chosen_ned_m, (0.1, 0.9, 0.2, 1.0), 0.06))
    if len(path_ned_m) > 1:
        lines.append(_line(path_ned_m, (1.0, 1.0, 1.0, 0.8), 0.04))
    spheres = []
    if goal_ned_m is not None:
        spheres.append(
            {
                "pose": {
                    "position": _point(goal_ned_m),
                    "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
                },
                "size": {"x": 0.6, "y": 0.6, "z": 0.6},
                "color": {"r": 1.0, "g": 0.55, "b": 0.1, "a": 0.9},
            }
        )
    entity = {
        "timestamp": foxglove_time(stamp_s),
        "frame_id": "local_ned",
        "id": "plan",
        "lifetime": {"sec": 0, "nsec": 0},
        "frame_locked": False,
        "metadata": [],
        "arrows": [],
        "cubes": [],
        "spheres": spheres,
        "cylinders": [],
        "lines": lines,
        "triangles": [],
        "texts": [],
        "models": [],
    }
    return {"deletions": [], "entities": [entity]}
