"""The built-in scenarios: the thesis' experiments as worlds, varied by a seed.

`build_scenario(name, seed)` returns a `World` (NED, m; the start on the ground at the origin,
the vehicle heading north). The seed varies what the thesis' runs varied, the start distance
from the obstacle, and also the wire's height, span and sag, the clutter, the ground, the
textures and the light. Every scenario is flyable by a 0.5 m-radius vehicle at 2 m/s with the
trajectory library (climbs of 1-3 m or turns around supports), and its obstacle blocks the
straight flight from the take-off point to the first goal (tests check both).
"""

from __future__ import annotations

import itertools
import zlib

import numpy as np

from geometry.shapes import Box
from hil.world.materials import GROUND_MATERIALS
from hil.world.model import Lighting, Solid, World, catenary_wire, pole
from hil.world.parts import (
    WorldParts,
    box_on_ground,
    combined,
    ladder,
    power_line,
    tree,
)

SCENARIOS: dict[str, str] = {
    "ladder-wire": (
        "thesis 4.6.2: a metal wire strung between two ladders straight across the path, the "
        "goal 10-15 m behind it; the start distance (8-14 m) varies with the seed"
    ),
    "ladder-wire-left": "Table 4.2 run 5: the ladder wire with the goal sent to the left",
    "ladder-wire-right": "Table 4.2 run 1: the ladder wire with the goal sent to the right",
    "stacked-wires": (
        "Fig. 4.5: three horizontal wires stacked 2.2-2.7 m apart between poles, the vehicle "
        "at the middle one's height"
    ),
    "curvy-corridor": (
        "Fig. 4.12: start and goal 10 m apart, two staggered pillars between side walls "
        "forcing a curvy path (stereo obstacles only, no wire)"
    ),
    "power-line-corridor": (
        "a transmission line on lattice towers (three conductors and a shield wire, 30 m "
        "spans) and a distribution line on poles behind it, crossed at conductor height"
    ),
    "random": (
        "a wire world drawn from the seed: one or two crossings (single wires, stacked "
        "wires or short power lines at any angle), trees and buildings beside the path"
    ),
}
"""Scenario name -> what it is (the `wireavoid sim --scenario` names)."""


def _rng(name: str, seed: int) -> np.random.Generator:
    return np.random.default_rng([zlib.crc32(name.encode()), int(seed)])


def _lighting(rng: np.random.Generator) -> Lighting:
    return Lighting(
        sun_azimuth_rad=float(rng.uniform(0.0, 2 * np.pi)),
        sun_elevation_rad=float(np.deg2rad(rng.uniform(20.0, 65.0))),
        cloud_cover=float(rng.uniform(0.0, 0.7)),
        haze=float(rng.uniform(0.0, 0.4)),
    )


def _distance_to_segment_m(points_ne: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ab = b - a
    t = np.clip(((points_ne - a) @ ab) / max(float(ab @ ab), 1e-12), 0.0, 1.0)
    return np.linalg.norm(points_ne - (a + t[:, None] * ab), axis=1)


def _clutter(
    rng: np.random.Generator,
    path_ne_m: np.ndarray,
    keep_out_ne_m: list[np.ndarray],
    trees: int,
    buildings: int,
) -> WorldParts:
    """Trees and buildings around the flight, none within 7 m of the straight path
    (`(2, 2)` start and end, north/east) or within 5 m of `keep_out_ne_m` polylines."""
    start, end = path_ne_m
    lo = np.minimum(start, end) + np.array([-5.0, -28.0])
    hi = np.maximum(start, end) + np.array([20.0, 28.0])
    parts, placed = [], []
    for k in range(trees + buildings):
        is_tree = k < trees
        reach = 3.0 if is_tree else 7.0
        for _ in range(50):
            ne = rng.uniform(lo, hi)
            clear = _distance_to_segment_m(ne[None], start, end)[0] > 7.0 + reach
            for line in keep_out_ne_m:
                d = min(
                    _distance_to_segment_m(ne[None], a, b)[0] for a, b in itertools.pairwise(line)
                )
                clear &= d > 5.0 + reach
            clear &= all(np.linalg.norm(ne - p) > reach + r for p, r in placed)
            if clear:
                break
        else:
            continue
        placed.append((ne, reach))
        if is_tree:
            parts.append(tree(ne[0], ne[1], rng.uniform(5.0, 12.0), rng.uniform(1.2, 2.8)))
        else:
            size = (rng.uniform(5.0, 10.0), rng.uniform(5.0, 10.0), rng.uniform(4.0, 9.0))
            material = str(rng.choice(["brick", "concrete", "plaster", "wood"]))
            parts.append(box_on_ground(ne[0], ne[1], size, 0.0, material, "building"))
    return combined(parts)


def _world(
    name: str,
    seed: int,
    rng: np.random.Generator,
    parts: WorldParts,
    altitude_m: float,
    goals_ne_m: list[tuple[float, float]],
) -> World:
    return World(
        solids=parts.solids,
        wires=parts.wires,
        wire_albedos=parts.wire_albedos,
        seed=int(rng.integers(2**31)),
        name=f"{name}#{seed}",
        takeoff_altitude_m=altitude_m,
        goals_ned_m=[[n, e, -altitude_m] for n, e in goals_ne_m],
        ground_material=str(rng.choice(GROUND_MATERIALS[:4])),
        lighting=_lighting(rng),
    )


def _ladder_wire(name: str, seed: int, goal_side: float) -> World:
    """The wire between two ladders (4.6.2); `goal_side` -1 left, 0 straight, +1 right."""
    rng = _rng(name, seed)
    wire_north = rng.uniform(8.0, 14.0)  # the varied start distance
    goal_north = wire_north + rng.uniform(10.0, 15.0)
    goal_east = goal_side * rng.uniform(6.0, 9.0)
    crossing_east = goal_east * wire_north / goal_north
    half_span = rng.uniform(3.5, 5.0)
    centre_east = crossing_east + rng.uniform(-0.25, 0.25) * half_span
    height = rng.uniform(3.0, 4.5)
    sag = rng.uniform(0.02, 0.15)
    ends = [centre_east - half_span, centre_east + half_span]
    parts = [ladder(wire_north, e, height, facing="north") for e in ends]
    radius = rng.uniform(0.005, 0.008)
    wire = catenary_wire(
        [wire_north, ends[0], -height], [wire_north, ends[1], -height], sag, radius
    )
    fraction = (crossing_east - ends[0]) / (2 * half_span)
    wire_height_at_crossing = height - sag * 4 * fraction * (1 - fraction)
    parts.append(WorldParts((), (wire,), (float(rng.uniform(0.08, 0.35)),)))
    # just below the wire, as the thesis' runs approached it (it shows above the horizon)
    altitude = wire_height_at_crossing - rng.uniform(0.05, 0.4)
    path = np.array([[0.0, 0.0], [goal_north, goal_east]])
    lines = [np.array([[wire_north, ends[0]], [wire_north, ends[1]]])]
    parts.append(_clutter(rng, path, lines, int(rng.integers(3, 7)), int(rng.integers(0, 2))))
    return _world(name, seed, rng, combined(parts), altitude, [(goal_north, goal_east)])


def _stacked_wires(name: str, seed: int) -> World:
    """Three horizontal wires stacked 2.2-2.7 m apart (Fig. 4.5), crossed at the middle one."""
    rng = _rng(name, seed)
    wire_north = rng.uniform(10.0, 14.0)
    goal_north = wire_north + rng.uniform(10.0, 15.0)
    middle = rng.uniform(5.0, 6.0)
    spacing = rng.uniform(2.2, 2.7)
    half_span = 15.0
    parts = [pole(wire_north, e, middle + spacing + 1.0) for e in (-half_span, half_span)]
    radius = rng.uniform(0.006, 0.01)
    wires = tuple(
        catenary_wire(
            [wire_north, -half_span, -h], [wire_north, half_span, -h], rng.uniform(0.1, 0.3), radius
        )
        for h in (middle - spacing, middle, middle + spacing)
    )
    albedo = float(rng.uniform(0.1, 0.4))
    stack = WorldParts(tuple(parts), wires, (albedo,) * 3)
    sag_mid = float(-wires[1].points_ned_m[len(wires[1].points_ned_m) // 2, 2])
    path = np.array([[0.0, 0.0], [goal_north, 0.0]])
    lines = [np.array([[wire_north, -half_span], [wire_north, half_span]])]
    clutter = _clutter(rng, path, lines, int(rng.integers(3, 7)), int(rng.integers(0, 2)))
    altitude = sag_mid + rng.uniform(-0.2, 0.2)
    return _world(name, seed, rng, stack + clutter, altitude, [(goal_north, 0.0)])


def _curvy_corridor(name: str, seed: int) -> World:
    """Fig. 4.12: start and goal 10 m apart, between side walls 9-11 m apart two staggered
    6 m-tall pillars, each 1.6 m wide and offset 0.2-0.5 m to either side of the straight
    line, so the way to the goal weaves around them."""
    rng = _rng(name, seed)
    wall_height = 6.0
    side = rng.uniform(4.5, 5.5)
    first = rng.uniform(2.5, 3.0), rng.uniform(0.2, 0.5)  # (north, east of the centre), m
    second = rng.uniform(6.0, 6.5), -rng.uniform(0.2, 0.5)
    materials = rng.choice(["wood", "brick", "concrete"], size=4)
    boxes = [([n, e - 0.8, -wall_height], [n + 0.8, e + 0.8, 0.0]) for n, e in (first, second)]
    boxes += [
        ([-3.0, -side - 0.5, -wall_height], [13.0, -side, 0.0]),
        ([-3.0, side, -wall_height], [13.0, side + 0.5, 0.0]),
    ]
    solids = tuple(
        Solid(Box(lo, hi), float(rng.uniform(0.5, 0.8)), str(m), "wall")
        for (lo, hi), m in zip(boxes, materials, strict=True)
    )
    altitude = rng.uniform(1.5, 2.0)
    return _world(name, seed, rng, WorldParts(solids), altitude, [(10.0, 0.0)])


def _power_line_corridor(name: str, seed: int) -> World:
    """A tower line and a pole line across the path, crossed mid-span at conductor height."""
    rng = _rng(name, seed)
    line_north = rng.uniform(10.0, 13.0)
    second_north = line_north + rng.uniform(9.0, 12.0)
    goal_north = second_north + rng.uniform(8.0, 12.0)
    offset = rng.uniform(-4.0, 4.0)
    sag = rng.uniform(0.8, 1.5)
    conductor_m = rng.uniform(9.0, 10.5)
    towers = np.array([[line_north, offset + e] for e in (-45.0, -15.0, 15.0, 45.0)])
    transmission = power_line(
        towers,
        ((-1.8, conductor_m), (0.0, conductor_m), (1.8, conductor_m), (0.0, conductor_m + 2.2)),
        sag,
        radius_m=rng.uniform(0.012, 0.016),
        support="tower",
        support_height_m=conductor_m + 2.6,
        albedo=float(rng.uniform(0.35, 0.6)),
    )
    # mid-span height of the conductors at the crossing (east = 0): chord minus parabolic sag
    fraction = (0.0 - (offset - 15.0)) / 30.0
    crossing_m = conductor_m - 0.3 - sag * 4 * fraction * (1 - fraction)
    altitude = crossing_m - rng.uniform(0.05, 0.4)
    pole_m = altitude + rng.uniform(-0.3, 0.5)
    poles = np.array([[second_north, rng.uniform(-3.0, 3.0) + e] for e in (-40.0, -10.0, 20.0)])
    distribution = power_line(
        poles,
        ((-0.8, pole_m), (0.8, pole_m), (0.0, pole_m - 1.8)),
        rng.uniform(0.3, 0.8),
        radius_m=rng.uniform(0.006, 0.01),
        support="pole",
        albedo=float(rng.uniform(0.15, 0.5)),
    )
    path = np.array([[0.0, 0.0], [goal_north, 0.0]])
    clutter = _clutter(rng, path, [towers, poles], int(rng.integers(2, 6)), 0)
    mid = (line_north + second_north) / 2
    return _world(
        name,
        seed,
        rng,
        transmission + distribution + clutter,
        altitude,
        [(mid, 0.0), (goal_north, 0.0)],
    )


def _random_crossing(
    rng: np.random.Generator, north_m: float, goal_ne_m: np.ndarray, altitude_m: float
) -> tuple[WorldParts, np.ndarray]:
    """One wire obstacle across the straight path at `north_m`: a single wire, stacked wires
    or a short power line, at a random angle, at the flight altitude where the path crosses."""
    kind = rng.choice(["single", "stacked", "power"], p=[0.5, 0.25, 0.25])
    crossing = goal_ne_m * north_m / goal_ne_m[0]
    angle = np.deg2rad(rng.uniform(-35.0, 35.0))
    along = np.array([np.sin(angle), np.cos(angle)])  # the line's direction, roughly east
    span = rng.uniform(12.0, 30.0)
    fraction = rng.uniform(0.3, 0.7)
    a = crossing - fraction * span * along
    b = a + span * along
    sag = rng.uniform(0.05, 0.8)
    bulge = sag * 4 * fraction * (1 - fraction)
    radius = rng.uniform(0.004, 0.012)
    albedo = float(rng.uniform(0.08, 0.5))
    height = altitude_m + bulge + rng.uniform(0.05, 0.4)
    if kind == "power":
        parts = power_line(
            np.array([a, b]),
            ((-0.9, height + 0.3), (0.9, height + 0.3)),
            sag,
            radius_m=max(radius, 0.008),
            support="pole",
            albedo=albedo,
        )
        return parts, np.array([a, b])
    spacing = rng.uniform(2.0, 2.5)
    heights = [height] if kind == "single" else [height - spacing, height, height + spacing]
    heights = [h for h in heights if h > 1.5]
    supports = tuple(pole(*p, max(heights) + 0.5) for p in (a, b))
    wires = tuple(catenary_wire([a[0], a[1], -h], [b[0], b[1], -h], sag, radius) for h in heights)
    return WorldParts(supports, wires, (albedo,) * len(wires)), np.array([a, b])


def _random(name: str, seed: int) -> World:
    """A wire world drawn from the seed (see `SCENARIOS["random"]`)."""
    rng = _rng(name, seed)
    altitude = rng.uniform(3.0, 6.0)
    crossings = int(rng.integers(1, 3))
    norths = [rng.uniform(8.0, 13.0)]
    if crossings == 2:
        norths.append(norths[0] + rng.uniform(8.0, 12.0))
    goal = np.array([norths[-1] + rng.uniform(8.0, 14.0), rng.uniform(-6.0, 6.0)])
    parts, lines = [], []
    for north in norths:
        part, line = _random_crossing(rng, north, goal, altitude)
        parts.append(part)
        lines.append(line)
    path = np.array([[0.0, 0.0], goal])
    parts.append(_clutter(rng, path, lines, int(rng.integers(2, 8)), int(rng.integers(0, 3))))
    return _world(name, seed, rng, combined(parts), altitude, [tuple(goal)])


def build_scenario(name: str, seed: int) -> World:
    """The built-in scenario `name` (a key of `SCENARIOS`) drawn with `seed`."""
    builders = {
        "ladder-wire": lambda s: _ladder_wire("ladder-wire", s, 0.0),
        "ladder-wire-left": lambda s: _ladder_wire("ladder-wire-left", s, -1.0),
        "ladder-wire-right": lambda s: _ladder_wire("ladder-wire-right", s, 1.0),
        "stacked-wires": lambda s: _stacked_wires("stacked-wires", s),
        "curvy-corridor": lambda s: _curvy_corridor("curvy-corridor", s),
        "power-line-corridor": lambda s: _power_line_corridor("power-line-corridor", s),
        "random": lambda s: _random("random", s),
    }
    if name not in builders:
        raise ValueError(f"unknown scenario {name!r}; one of {', '.join(SCENARIOS)}")
    return builders[name](seed)
