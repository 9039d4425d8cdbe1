"""Obstacle shapes in world NED (m), and distances to them: the one home of `Box` and `Wire`.

The simulator's world (`hil.world`), the synthetic occupancy map of planner tests
(`planning.synthetic_occupancy`) and the judge of simulated flights all describe obstacles
with these two shapes: axis-aligned boxes, and wires as thin tubes around polylines.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, slots=True)
class Box:
    """Axis-aligned box between `min_ned_m` (3,) and `max_ned_m` (3,), NED, m."""

    min_ned_m: np.ndarray
    max_ned_m: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "min_ned_m", np.asarray(self.min_ned_m, dtype=np.float64))
        object.__setattr__(self, "max_ned_m", np.asarray(self.max_ned_m, dtype=np.float64))
        if self.min_ned_m.shape != (3,) or self.max_ned_m.shape != (3,):
            raise ValueError("a box needs (3,) corners")
        if np.any(self.max_ned_m <= self.min_ned_m):
            raise ValueError("box max must exceed min on every axis")

    def distance_m(self, points_ned_m: np.ndarray) -> np.ndarray:
        """`(N,)` signed distance of `(N, 3)` points to the box surface, m (< 0 inside)."""
        pts = np.asarray(points_ned_m, dtype=np.float64).reshape(-1, 3)
        below, above = self.min_ned_m - pts, pts - self.max_ned_m
        outside = np.linalg.norm(np.maximum(np.maximum(below, above), 0.0), axis=1)
        inside = np.minimum(np.max(np.maximum(below, above), axis=1), 0.0)
        return outside + inside


@dataclass(frozen=True, slots=True)
class Wire:
    """A wire: a thin tube of `radius_m` around an `(M, 3)` polyline of NED points, m."""

    points_ned_m: np.ndarray
    radius_m: float = 0.01

    def __post_init__(self) -> None:
        points = np.asarray(self.points_ned_m, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 3 or len(points) < 2:
            raise ValueError("a wire needs an (M >= 2, 3) polyline")
        object.__setattr__(self, "points_ned_m", points)

    @classmethod
    def straight(cls, start_ned_m: np.ndarray, end_ned_m: np.ndarray, radius_m: float = 0.01):
        """A taut straight wire from `start_ned_m` (3,) to `end_ned_m` (3,)."""
        return cls(
            np.stack([np.asarray(start_ned_m, float), np.asarray(end_ned_m, float)]), radius_m
        )

    def sample(self, spacing_m: float) -> np.ndarray:
        """`(K, 3)` points along the polyline at most `spacing_m` apart, NED, m."""
        p = self.points_ned_m
        lengths = np.linalg.norm(np.diff(p, axis=0), axis=1)
        out = [p[:1]]
        for a, b, length in zip(p[:-1], p[1:], lengths, strict=True):
            k = max(int(np.ceil(length / spacing_m)), 1)
            t = np.arange(1, k + 1)[:, None] / k
            out.append(a + t * (b - a))
        return np.concatenate(out)

    def distance_m(self, points_ned_m: np.ndarray) -> np.ndarray:
        """`(N,)` distance of `(N, 3)` points to the wire's surface, m (< 0 inside the tube)."""
        pts = np.asarray(points_ned_m, dtype=np.float64).reshape(-1, 3)
        return distance_to_polyline_m(pts, self.points_ned_m)[0] - self.radius_m


def distance_to_polyline_m(
    points_ned_m: np.ndarray, polyline_ned_m: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Distance of `(N, 3)` points to a `(K, 3)` polyline, with the closest segment.

    Returns `(N,)` distances (m), `(N,) int` segment indices and `(N,)` fractions along them.
    """
    start = polyline_ned_m[:-1]
    segment = polyline_ned_m[1:] - start
    length2 = np.maximum(np.einsum("kd,kd->k", segment, segment), 1e-12)
    offset = points_ned_m[:, None, :] - start[None, :, :]
    fraction = np.clip(np.einsum("nkd,kd->nk", offset, segment) / length2, 0.0, 1.0)
    closest = start[None] + fraction[..., None] * segment[None]
    distance = np.linalg.norm(points_ned_m[:, None, :] - closest, axis=2)
    index = np.argmin(distance, axis=1)
    rows = np.arange(points_ned_m.shape[0])
    return distance[rows, index], index, fraction[rows, index]
