"""Export of the occupied volume of an `OccupancyMap` as voxels (Fig. 4.5, flight reports).

Pure: returns arrays or bytes; the caller writes files.
"""

from __future__ import annotations

import io

import numpy as np

from mapping.query import OccupancyMap


def grid_centres_ned_m(
    centre_ned_m: np.ndarray, extent_m: tuple[float, float, float], resolution_m: float
) -> np.ndarray:
    """`(K, 3)` voxel centres of a box of `extent_m` (north, east, down) around a centre, m."""
    axes = [
        np.arange(-e / 2 + resolution_m / 2, e / 2, resolution_m) + c
        for c, e in zip(np.asarray(centre_ned_m, float), extent_m, strict=True)
    ]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def occupied_voxels(
    occupancy_map: OccupancyMap,
    centre_ned_m: np.ndarray,
    extent_m: tuple[float, float, float] = (60.0, 40.0, 40.0),
    resolution_m: float = 0.5,
    batch: int = 200_000,
) -> tuple[np.ndarray, np.ndarray]:
    """Centres `(K, 3)` (NED, m) and occupancy M `(K,)` of the voxels whose centre collides.

    Defaults are the thesis' visualisation grid: 0.5 m, 60 x 40 x 40 m around the robot (4.7.1).
    """
    centres = grid_centres_ned_m(centre_ned_m, extent_m, resolution_m)
    keep_points, keep_m = [], []
    for start in range(0, len(centres), batch):
        chunk = centres[start : start + batch]
        answer = occupancy_map.query(chunk)
        keep_points.append(chunk[answer.collision])
        keep_m.append(answer.occupancy[answer.collision])
    return np.concatenate(keep_points), np.concatenate(keep_m)


def ply_bytes(points_ned_m: np.ndarray, colours_rgb: np.ndarray | None = None) -> bytes:
    """ASCII PLY of `(K, 3)` points (NED, m) with optional `(K, 3) uint8` colours."""
    points = np.asarray(points_ned_m, dtype=float).reshape(-1, 3)
    header = ["ply", "format ascii 1.0", f"element vertex {len(points)}"]
    header += ["property float x", "property float y", "property float z"]
    columns: list[np.ndarray] = [points]
    fmt = ["%.3f"] * 3
    if colours_rgb is not None:
        header += ["property uchar red", "property uchar green", "property uchar blue"]
        columns.append(np.asarray(colours_rgb, dtype=np.uint8).reshape(-1, 3).astype(float))
        fmt += ["%d"] * 3
    body = io.StringIO()
    np.savetxt(body, np.hstack(columns), fmt=fmt)
    return ("\n".join([*header, "end_header"]) + "\n" + body.getvalue()).encode()


def height_colours(points_ned_m: np.ndarray) -> np.ndarray:
    """`(K, 3) uint8` colours by height (blue low to red high), as in Fig. 4.5."""
    altitude = -np.asarray(points_ned_m, float)[:, 2]
    if altitude.size == 0:
        return np.zeros((0, 3), np.uint8)
    span = max(float(np.ptp(altitude)), 1e-6)
    t = (altitude - altitude.min()) / span
    return (np.stack([t, 1.0 - np.abs(2.0 * t - 1.0), 1.0 - t], axis=1) * 255).astype(np.uint8)
