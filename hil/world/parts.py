"""The objects of a world, compiled to what the renderer and the judge share: boxes and wires.

Every builder stands its object on the ground plane (`ground_down_m`, NED z) at a north/east
position (m) and returns `WorldParts`: axis-aligned `Solid`s and `geometry.shapes.Wire`s
(with their albedos). Ladders, towers and trees are approximated by a few boxes that enclose
them (the judge then errs on the safe side); power lines hang catenaries (eq. 3.1's model,
`hil.world.model.catenary_wire`) between the supports, span by span, one per conductor.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from geometry.shapes import Box, Wire
from hil.world.model import DEFAULT_WIRE_ALBEDO, Solid, catenary_wire, pole


@dataclass(frozen=True)
class WorldParts:
    """Solids and wires of one or more objects; `wire_albedos` runs parallel to `wires`."""

    solids: tuple[Solid, ...] = ()
    wires: tuple[Wire, ...] = ()
    wire_albedos: tuple[float, ...] = ()

    def __add__(self, other: WorldParts) -> WorldParts:
        return WorldParts(
            self.solids + other.solids,
            self.wires + other.wires,
            self.wire_albedos + other.wire_albedos,
        )


def combined(parts: list[WorldParts]) -> WorldParts:
    """All parts in one."""
    out = WorldParts()
    for p in parts:
        out = out + p
    return out


def _box(
    lo_ned_m: list[float], hi_ned_m: list[float], material: str, kind: str, albedo: float = 0.6
) -> Solid:
    return Solid(Box(lo_ned_m, hi_ned_m), albedo=albedo, material=material, kind=kind)


def box_on_ground(
    north_m: float,
    east_m: float,
    size_m: tuple[float, float, float],
    ground_down_m: float = 0.0,
    material: str = "concrete",
    kind: str = "building",
    albedo: float = 0.6,
) -> WorldParts:
    """A box centred at (north, east) of `size_m` = (north extent, east extent, height), m."""
    n, e, h = size_m
    return WorldParts(
        (
            _box(
                [north_m - n / 2, east_m - e / 2, ground_down_m - h],
                [north_m + n / 2, east_m + e / 2, ground_down_m],
                material,
                kind,
                albedo,
            ),
        )
    )


def ladder(
    north_m: float,
    east_m: float,
    height_m: float,
    ground_down_m: float = 0.0,
    width_m: float = 0.5,
    facing: str = "north",
    material: str = "metal",
) -> WorldParts:
    """A step ladder (A-frame) `height_m` tall: two rails `width_m` apart with rungs every
    0.3 m on the side facing `facing` ("north" or "east"), and a second pair of legs 0.8 m
    behind it reaching 90 % of the height. Its top is at (north, east, ground - height)."""
    if facing not in ("north", "east"):
        raise ValueError("a ladder faces 'north' or 'east'")
    across = 1 if facing == "north" else 0  # the axis the rungs span
    depth = 1 - across
    rail, rung = 0.06, 0.035
    centre = np.array([north_m, east_m])
    g = ground_down_m
    solids = []

    def upright(offset_across: float, offset_depth: float, top_m: float) -> None:
        c = centre.copy()
        c[across] += offset_across
        c[depth] += offset_depth
        lo = [c[0] - rail / 2, c[1] - rail / 2, g - top_m]
        hi = [c[0] + rail / 2, c[1] + rail / 2, g]
        solids.append(_box(lo, hi, material, "ladder"))

    for side in (-1.0, 1.0):
        upright(side * width_m / 2, 0.0, height_m)
        upright(side * width_m / 2, 0.8, 0.9 * height_m)
    for h in np.arange(0.3, height_m - 0.1, 0.3):
        lo, hi = centre.copy(), centre.copy()
        lo[across] -= width_m / 2
        hi[across] += width_m / 2
        lo[depth] -= rung / 2
        hi[depth] += rung / 2
        solids.append(
            _box(
                [lo[0], lo[1], g - h - rung / 2],
                [hi[0], hi[1], g - h + rung / 2],
                material,
                "ladder",
            )
        )
    return WorldParts(tuple(solids))


def tree(
    north_m: float,
    east_m: float,
    height_m: float,
    crown_radius_m: float,
    ground_down_m: float = 0.0,
) -> WorldParts:
    """A tree: a bark trunk to 45 % of `height_m` and a foliage crown of three stacked boxes
    narrowing upwards (radius `crown_radius_m` at the bottom), from 35 % of the height up."""
    g, h, r = ground_down_m, height_m, crown_radius_m
    trunk = float(np.clip(0.08 * r + 0.12, 0.15, 0.6)) / 2
    solids = [
        _box(
            [north_m - trunk, east_m - trunk, g - 0.45 * h],
            [north_m + trunk, east_m + trunk, g],
            "bark",
            "tree",
        )
    ]
    tiers = ((0.35, 0.75, r), (0.75, 0.92, 0.75 * r), (0.92, 1.0, 0.45 * r))
    return WorldParts(tuple(solids)) + _stack(north_m, east_m, g, h, tiers, "foliage", "tree")


def tower(
    north_m: float,
    east_m: float,
    height_m: float,
    arms: tuple[tuple[float, float], ...],
    arm_axis: int,
    ground_down_m: float = 0.0,
    base_width_m: float = 1.6,
) -> WorldParts:
    """A lattice transmission tower: a body of three stacked boxes tapering from
    `base_width_m` to a third of it, and cross-arms 0.25 m thick along NED axis `arm_axis`
    (0 north, 1 east), one per `(height above ground, half length)` in `arms`, m."""
    g, half = ground_down_m, base_width_m / 2
    tiers = ((0.0, 0.4, half), (0.4, 0.75, 0.6 * half), (0.75, 1.0, 0.35 * half))
    body = _stack(north_m, east_m, g, height_m, tiers, "metal", "tower")
    return body + cross_arms(north_m, east_m, arms, arm_axis, g, "tower")


def _stack(
    north_m: float,
    east_m: float,
    ground_down_m: float,
    height_m: float,
    tiers: tuple[tuple[float, float, float], ...],
    material: str,
    kind: str,
) -> WorldParts:
    """Square boxes centred on (north, east), one per `(bottom, top, half width)` tier, the
    bottom and top as fractions of `height_m` above the ground, the half width in m."""
    return WorldParts(
        tuple(
            _box(
                [north_m - half, east_m - half, ground_down_m - top * height_m],
                [north_m + half, east_m + half, ground_down_m - bottom * height_m],
                material,
                kind,
            )
            for bottom, top, half in tiers
        )
    )


def cross_arms(
    north_m: float,
    east_m: float,
    arms: tuple[tuple[float, float], ...],
    arm_axis: int,
    ground_down_m: float,
    kind: str,
) -> WorldParts:
    """Cross-arms 0.25 m thick along NED axis `arm_axis` centred on a support, one per
    `(height above ground, half length)`, m."""
    solids = []
    for arm_height_m, half_length_m in arms:
        lo = np.array([north_m - 0.15, east_m - 0.15, ground_down_m - arm_height_m - 0.05])
        hi = np.array([north_m + 0.15, east_m + 0.15, ground_down_m - arm_height_m + 0.2])
        lo[arm_axis] -= half_length_m
        hi[arm_axis] += half_length_m
        solids.append(_box(list(lo), list(hi), "metal", kind))
    return WorldParts(tuple(solids))


def power_line(
    supports_ne_m: np.ndarray,
    conductors: tuple[tuple[float, float], ...],
    sag_m: float,
    radius_m: float = 0.012,
    support: str = "tower",
    support_height_m: float | None = None,
    ground_down_m: float = 0.0,
    albedo: float = 0.45,
) -> WorldParts:
    """A power line over `(S, 2)` supports (north, east, m): S - 1 spans.

    conductors: `(lateral offset, height above ground)` per conductor, m; the offset is to the
    right of the line's direction at each support (the mean of its spans' directions). Each
    conductor hangs from support to support as a catenary with mid-span `sag_m`. Supports are
    towers with a cross-arm per conductor height (`support="tower"`) or poles with a cross-arm
    (`"pole"`); their height defaults to 1 m above the highest conductor. Cross-arms run along
    the NED axis closest to perpendicular to the line.
    """
    supports = np.asarray(supports_ne_m, dtype=np.float64).reshape(-1, 2)
    if len(supports) < 2:
        raise ValueError("a power line needs at least two supports")
    if support not in ("tower", "pole"):
        raise ValueError("support must be 'tower' or 'pole'")
    spans = np.diff(supports, axis=0)
    spans /= np.linalg.norm(spans, axis=1, keepdims=True)
    heights = np.array([c[1] for c in conductors])
    offsets = np.array([c[0] for c in conductors])
    top_m = float(heights.max()) + 1.0 if support_height_m is None else support_height_m
    g = ground_down_m
    solids: list[Solid] = []
    attach = np.zeros((len(supports), len(conductors), 3))
    for i, ne in enumerate(supports):
        direction = spans[max(i - 1, 0)] + spans[min(i, len(spans) - 1)]
        direction /= np.linalg.norm(direction)
        right = np.array([-direction[1], direction[0]])
        arm_axis = int(np.argmax(np.abs(right)))
        attach[i, :, :2] = ne + offsets[:, None] * right
        attach[i, :, 2] = g - heights + 0.3  # hanging 0.3 m below the arm on insulators
        arms = tuple(
            (float(h), float(np.abs(offsets[heights == h]).max() * abs(right[arm_axis]) + 0.3))
            for h in np.unique(heights)
        )
        if support == "tower":
            solids += tower(ne[0], ne[1], top_m, arms, arm_axis, g).solids
        else:
            solids.append(pole(ne[0], ne[1], top_m, g))
            solids += cross_arms(ne[0], ne[1], arms, arm_axis, g, "pole").solids
    wires = tuple(
        catenary_wire(attach[i, c], attach[i + 1, c], sag_m, radius_m)
        for i in range(len(supports) - 1)
        for c in range(len(conductors))
    )
    return WorldParts(tuple(solids), wires, (albedo,) * len(wires))


def fence(
    from_ne_m: tuple[float, float],
    to_ne_m: tuple[float, float],
    height_m: float,
    ground_down_m: float = 0.0,
    post_spacing_m: float = 3.0,
    kind: str = "wire",
    strands: int = 3,
    wire_radius_m: float = 0.0015,
) -> WorldParts:
    """A fence from one point to another: wooden posts every `post_spacing_m` and either
    `strands` taut wires evenly spaced up to `height_m` (`kind="wire"`, any direction) or a
    solid wooden panel (`kind="panel"`, along north or east only)."""
    a, b = np.asarray(from_ne_m, float), np.asarray(to_ne_m, float)
    length = float(np.linalg.norm(b - a))
    count = max(int(np.ceil(length / post_spacing_m)), 1) + 1
    g = ground_down_m
    posts = [
        replace(pole(*(a + t * (b - a)), height_m + 0.1, g, 0.1), kind="fence")
        for t in np.linspace(0, 1, count)
    ]
    if kind == "wire":
        wires = tuple(
            Wire.straight([a[0], a[1], g - h], [b[0], b[1], g - h], wire_radius_m)
            for h in np.linspace(height_m, height_m / (strands + 1), strands)
        )
        return WorldParts(tuple(posts), wires, (DEFAULT_WIRE_ALBEDO,) * len(wires))
    if kind != "panel":
        raise ValueError("fence kind must be 'wire' or 'panel'")
    if min(abs(b - a)) > 1e-9:
        raise ValueError("a panel fence must run along north or east")
    lo, hi = np.minimum(a, b) - 0.03, np.maximum(a, b) + 0.03
    panel = _box([lo[0], lo[1], g - height_m], [hi[0], hi[1], g], "wood", "fence")
    return WorldParts((*posts, panel))
