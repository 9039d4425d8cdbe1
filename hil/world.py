"""The simulated 3D world of the SIL harness: ground, boxes, poles and wires (NED, m).

Geometry is analytic so the cameras can ray-cast it vectorised: the ground is the plane
z_ned = `ground_down_m`; boxes are axis-aligned in NED; wires are thin tubes of radius
`radius_m` around polylines (catenaries sampled between pole tops). Surfaces carry a procedural
texture fixed in the world (the same in both cameras of a stereo pair, so stereo matching works).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True, slots=True)
class Box:
    """Axis-aligned box `[min_ned_m, max_ned_m]`; `albedo` in [0, 1] scales its brightness."""

    min_ned_m: np.ndarray
    max_ned_m: np.ndarray
    albedo: float = 0.6

    def __post_init__(self) -> None:
        object.__setattr__(self, "min_ned_m", np.asarray(self.min_ned_m, dtype=np.float64))
        object.__setattr__(self, "max_ned_m", np.asarray(self.max_ned_m, dtype=np.float64))
        if np.any(self.max_ned_m <= self.min_ned_m):
            raise ValueError("box max must exceed min on every axis")


@dataclass(frozen=True, slots=True)
class Wire:
    """A wire: `(M, 3)` polyline of NED points (m) and its radius (m)."""

    points_ned_m: np.ndarray
    radius_m: float = 0.01

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


def catenary_wire(
    start_ned_m: np.ndarray,
    end_ned_m: np.ndarray,
    sag_m: float,
    radius_m: float = 0.01,
    samples: int = 64,
) -> Wire:
    """A wire hanging between two attachment points with mid-span sag `sag_m` (m, down).

    Shape: z(s) = a cosh((s - s_mid) / a) - a cosh(L / 2a) offset, with the catenary parameter
    a solved for the sag; the straight chord carries the height difference.
    """
    start, end = np.asarray(start_ned_m, float), np.asarray(end_ned_m, float)
    s = np.linspace(0.0, 1.0, samples)
    chord = start[None, :] + s[:, None] * (end - start)[None, :]
    span = float(np.linalg.norm((end - start)[:2]))
    if sag_m <= 0 or span <= 0:
        return Wire(chord, radius_m)
    # solve a cosh(span / 2a) - a = sag for a by bisection on log a
    lo, hi = np.log(span / 100.0), np.log(span * 1e4)
    for _ in range(80):
        a = np.exp(0.5 * (lo + hi))
        if a * np.cosh(span / (2 * a)) - a > sag_m:
            lo = np.log(a)
        else:
            hi = np.log(a)
    x = (s - 0.5) * span
    drop = a * np.cosh(span / (2 * a)) - a * np.cosh(x / a)  # 0 at the ends, sag mid-span
    chord[:, 2] += drop
    return Wire(chord, radius_m)


@dataclass(frozen=True, slots=True)
class Checkerboard:
    """A calibration board facing south (its normal along -north) in the plane
    north = `north_m`: `squares` (columns, rows) of `square_m`, top-left corner at
    (`east_m`, `down_m`), with a white margin of one square around the pattern.
    OpenCV sees `(columns - 1, rows - 1)` inner corners.
    """

    north_m: float
    east_m: float
    down_m: float
    squares: tuple[int, int] = (9, 6)
    square_m: float = 0.1

    def inner_corners_ned_m(self) -> np.ndarray:
        """`(K, 3)` inner corners, row-major from the top-left, NED, m."""
        cols, rows = self.squares
        j, i = np.mgrid[1:rows, 1:cols]
        return np.stack(
            [
                np.full(j.size, self.north_m),
                self.east_m + self.square_m * i.ravel(),
                self.down_m + self.square_m * j.ravel(),
            ],
            axis=1,
        )


@dataclass(frozen=True)
class World:
    """Ground plane, boxes, wires and calibration boards; `seed` fixes the textures."""

    boxes: list[Box] = field(default_factory=list)
    wires: list[Wire] = field(default_factory=list)
    boards: list[Checkerboard] = field(default_factory=list)
    ground_down_m: float = 0.0
    seed: int = 0

    def texture_table(self) -> np.ndarray:
        """`(256, 256) float32` in [0, 1], the random texture indexed by surface cells."""
        return np.random.default_rng(self.seed).random((256, 256), dtype=np.float32)

    def wire_points(self, spacing_m: float) -> np.ndarray:
        """`(K, 3)` points sampled along all wires, NED, m (ground truth)."""
        if not self.wires:
            return np.zeros((0, 3))
        return np.concatenate([w.sample(spacing_m) for w in self.wires])


def pole(north_m: float, east_m: float, height_m: float, ground_down_m: float = 0.0) -> Box:
    """A 0.3 m square pole of `height_m` standing on the ground."""
    half = 0.15
    return Box(
        [north_m - half, east_m - half, ground_down_m - height_m],
        [north_m + half, east_m + half, ground_down_m],
        albedo=0.45,
    )


def wire_crossing_world(distance_m: float = 12.0, seed: int = 0) -> World:
    """A power-line crossing ahead of a vehicle flying north from the origin: two poles
    `distance_m` north, 30 m apart, three stacked wires (4.6.2, Fig. 4.5), a building-like box
    to the left and a low box to the right.
    """
    heights = (6.0, 8.0, 10.0)
    poles = [pole(distance_m, -15.0, 11.0), pole(distance_m, 15.0, 11.0)]
    wires = [
        catenary_wire([distance_m, -15.0, -h], [distance_m, 15.0, -h], sag_m=0.6, radius_m=0.012)
        for h in heights
    ]
    boxes = [
        Box([distance_m - 4.0, -12.0, -9.0], [distance_m + 2.0, -6.0, 0.0], albedo=0.7),
        Box([distance_m - 6.0, 4.0, -2.5], [distance_m - 3.0, 9.0, 0.0], albedo=0.5),
    ]
    return World(boxes=poles + boxes, wires=wires, seed=seed)
