"""The simulated 3D world of the SIL harness: ground, solids, wires, start and goals (NED, m).

Geometry is analytic so the cameras can ray-cast it vectorised and the flight judge can measure
true clearances: the ground is the plane z_ned = `ground_down_m`; every obstacle compiles to
axis-aligned boxes (`Solid`: buildings, poles, towers, ladders, fences, trees) and to wires,
thin tubes of `radius_m` around polylines (catenaries sampled between supports). Surfaces carry
a material (`hil.world.materials`) whose texture is fixed in the world, so both cameras of a
stereo pair and every pose see the same surface point alike. A `World` is immutable.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from geometry.shapes import Box, Wire
from hil.world.materials import MATERIALS


@dataclass(frozen=True, slots=True)
class Solid:
    """A box-shaped obstacle and its look: `material` (a name of `hil.world.materials`),
    `albedo` scaling the material's brightness (0.6 = as catalogued), and `kind`, what it is
    part of (box, building, pole, tower, ladder, fence, tree) for plots and verdicts."""

    box: Box
    albedo: float = 0.6
    material: str = "concrete"
    kind: str = "box"

    def __post_init__(self) -> None:
        if self.material not in MATERIALS:
            raise ValueError(f"unknown material {self.material!r}; one of {sorted(MATERIALS)}")
        if not 0.0 < self.albedo <= 2.0:
            raise ValueError(f"albedo must lie in (0, 2], got {self.albedo}")


@dataclass(frozen=True, slots=True)
class Lighting:
    """Sun and sky: the sun's azimuth (from north towards east) and elevation (above the
    horizon), rad; `cloud_cover` in [0, 1] (1 = overcast: no direct sun); `haze` in [0, 1]
    (aerial perspective: 0 = clear air, visibility ~10 km, 1 = visibility ~300 m)."""

    sun_azimuth_rad: float = 2.4
    sun_elevation_rad: float = 0.7
    cloud_cover: float = 0.3
    haze: float = 0.2

    def __post_init__(self) -> None:
        if not 0.0 < self.sun_elevation_rad < np.pi / 2:
            raise ValueError("sun elevation must lie in (0, pi/2) rad")
        if not (0.0 <= self.cloud_cover <= 1.0 and 0.0 <= self.haze <= 1.0):
            raise ValueError("cloud_cover and haze must lie in [0, 1]")

    def sun_direction_ned(self) -> np.ndarray:
        """`(3,)` unit vector from the scene towards the sun, NED."""
        c = np.cos(self.sun_elevation_rad)
        return np.array(
            [
                c * np.cos(self.sun_azimuth_rad),
                c * np.sin(self.sun_azimuth_rad),
                -np.sin(self.sun_elevation_rad),
            ]
        )


def catenary_wire(
    start_ned_m: np.ndarray,
    end_ned_m: np.ndarray,
    sag_m: float,
    radius_m: float = 0.01,
    samples: int = 64,
) -> Wire:
    """A wire hanging between two attachment points with mid-span sag `sag_m` (m, down).

    Shape: the catenary of eq. 3.1, z = a (cosh(x / a) - 1) about the mid-span, with the
    parameter a solved for the sag; the straight chord carries the height difference.
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


DEFAULT_WIRE_ALBEDO = 0.2
"""Albedo of a wire whose world gives none: weathered steel or aluminium, darker than sky."""


@dataclass(frozen=True, eq=False)
class World:
    """Everything a simulated flight sees and can hit; immutable (compared by identity: its
    arrays have no single truth value; compare `world_to_toml` texts instead).

    solids, wires, boards: the obstacles (`Solid`, `geometry.shapes.Wire`, `Checkerboard`).
    ground_down_m: the ground plane, NED z, m. ground_material: its material name.
    seed: fixes the textures, backdrop and clouds (the sensor noise has its own seed).
    name: what the world is called (scenario or file name).
    start_ned_m: `(3,)` the take-off point on the ground, NED, m; start_yaw_rad: the heading
        there, rad from north. takeoff_altitude_m: the height above the start the vehicle
        takes off to before it flies to the goals, m.
    goals_ned_m: `(K, 3)` goals to fly to in order, NED, m.
    lighting: sun and sky. wire_albedos: per wire (in order; missing ones get
        `DEFAULT_WIRE_ALBEDO`), the wire's albedo in the colour camera.
    """

    solids: tuple[Solid, ...] = ()
    wires: tuple[Wire, ...] = ()
    boards: tuple[Checkerboard, ...] = ()
    ground_down_m: float = 0.0
    seed: int = 0
    name: str = "world"
    start_ned_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    start_yaw_rad: float = 0.0
    takeoff_altitude_m: float = 2.5
    goals_ned_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    ground_material: str = "grass"
    lighting: Lighting = field(default_factory=Lighting)
    wire_albedos: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "solids", tuple(self.solids))
        set_(self, "wires", tuple(self.wires))
        set_(self, "boards", tuple(self.boards))
        albedos = tuple(float(a) for a in self.wire_albedos)[: len(self.wires)]
        albedos += (DEFAULT_WIRE_ALBEDO,) * (len(self.wires) - len(albedos))
        set_(self, "wire_albedos", albedos)
        start = np.array(self.start_ned_m, dtype=np.float64)
        goals = np.array(self.goals_ned_m, dtype=np.float64).reshape(-1, 3)
        if start.shape != (3,):
            raise ValueError("start_ned_m must be a (3,) NED point")
        start.setflags(write=False)
        goals.setflags(write=False)
        set_(self, "start_ned_m", start)
        set_(self, "goals_ned_m", goals)
        if self.ground_material not in MATERIALS:
            raise ValueError(f"unknown ground material {self.ground_material!r}")
        if self.takeoff_altitude_m < 0:
            raise ValueError("takeoff_altitude_m must be >= 0")

    @property
    def takeoff_point_ned_m(self) -> np.ndarray:
        """`(3,)` where the take-off ends: `takeoff_altitude_m` above the start, NED, m."""
        return self.start_ned_m - np.array([0.0, 0.0, self.takeoff_altitude_m])

    def wire_points(self, spacing_m: float) -> np.ndarray:
        """`(K, 3)` points sampled along all wires, NED, m (ground truth)."""
        if not self.wires:
            return np.zeros((0, 3))
        return np.concatenate([w.sample(spacing_m) for w in self.wires])


def pole(
    north_m: float,
    east_m: float,
    height_m: float,
    ground_down_m: float = 0.0,
    width_m: float = 0.3,
    material: str = "wood",
) -> Solid:
    """A square pole `width_m` wide and `height_m` tall standing on the ground."""
    half = width_m / 2
    return Solid(
        Box(
            [north_m - half, east_m - half, ground_down_m - height_m],
            [north_m + half, east_m + half, ground_down_m],
        ),
        albedo=0.6,
        material=material,
        kind="pole",
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
        Solid(
            Box([distance_m - 4.0, -12.0, -9.0], [distance_m + 2.0, -6.0, 0.0]),
            albedo=0.7,
            material="brick",
            kind="building",
        ),
        Solid(Box([distance_m - 6.0, 4.0, -2.5], [distance_m - 3.0, 9.0, 0.0]), albedo=0.5),
    ]
    return World(
        solids=(*poles, *boxes),
        wires=tuple(wires),
        seed=seed,
        name="wire-crossing",
        goals_ned_m=[[distance_m + 12.0, 0.0, -8.0]],
    )
