"""World files: a simulated world described in TOML (`docs/worlds.md` documents every key).

`load_world(path)` reads a file, `world_from_toml(text)` its text; both compile the objects
(buildings, poles, towers, ladders, fences, trees, wires, power lines) into a `World` with
`hil.world.parts`. Unknown keys, missing keys and out-of-range values are errors that name the
file, the line and the key (`ladder[1].height_m`). `world_to_toml(world)` writes a compiled
world back (boxes and wire polylines), which loads to the same world.
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)

from geometry.shapes import Box, Wire
from hil.faults import FaultSpec
from hil.world.materials import MATERIALS
from hil.world.model import Checkerboard, Lighting, Solid, World, catenary_wire
from hil.world.model import pole as pole_solid
from hil.world.parts import (
    WorldParts,
    box_on_ground,
    combined,
    fence,
    ladder,
    power_line,
    tree,
)

Vec3 = tuple[float, float, float]
Vec2 = tuple[float, float]


class WorldFileError(ValueError):
    """A world file that cannot be read; the message names the file, line and key."""


class _Entry(BaseModel):
    model_config = ConfigDict(extra="forbid")


def _known_material(name: str) -> str:
    if name not in MATERIALS:
        raise ValueError(f"unknown material {name!r}; one of {', '.join(sorted(MATERIALS))}")
    return name


MaterialName = Annotated[str, AfterValidator(_known_material)]


class StartEntry(_Entry):
    position_ned_m: Vec3 = (0.0, 0.0, 0.0)
    yaw_deg: float = Field(0.0, ge=-180, le=360)
    takeoff_altitude_m: float = Field(2.5, ge=0, le=100)


class GoalEntry(_Entry):
    position_ned_m: Vec3


class GroundEntry(_Entry):
    down_m: float = 0.0
    material: MaterialName = "grass"


class LightingEntry(_Entry):
    sun_azimuth_deg: float = Field(137.5, ge=-360, le=360)
    sun_elevation_deg: float = Field(40.0, gt=0, lt=90)
    cloud_cover: float = Field(0.3, ge=0, le=1)
    haze: float = Field(0.2, ge=0, le=1)


class BoxEntry(_Entry):
    min_ned_m: Vec3
    max_ned_m: Vec3
    material: MaterialName = "concrete"
    albedo: float = Field(0.6, gt=0, le=2)
    kind: str = "box"

    @model_validator(mode="after")
    def _ordered(self) -> BoxEntry:
        if any(hi <= lo for lo, hi in zip(self.min_ned_m, self.max_ned_m, strict=True)):
            raise ValueError("max_ned_m must exceed min_ned_m on every axis")
        return self


class BuildingEntry(_Entry):
    centre_ne_m: Vec2
    size_m: Vec3 = Field(description="north extent, east extent, height")
    material: MaterialName = "brick"
    albedo: float = Field(0.6, gt=0, le=2)

    @field_validator("size_m")
    @classmethod
    def _positive(cls, v: Vec3) -> Vec3:
        if min(v) <= 0:
            raise ValueError("every size must be > 0")
        return v


class PoleEntry(_Entry):
    position_ne_m: Vec2
    height_m: float = Field(gt=0, le=100)
    width_m: float = Field(0.3, gt=0, le=5)
    material: MaterialName = "wood"


class TreeEntry(_Entry):
    position_ne_m: Vec2
    height_m: float = Field(gt=0, le=60)
    crown_radius_m: float = Field(gt=0, le=20)


class LadderEntry(_Entry):
    position_ne_m: Vec2
    height_m: float = Field(gt=0.5, le=15)
    width_m: float = Field(0.5, gt=0.1, le=2)
    facing: Literal["north", "east"] = "north"


class FenceEntry(_Entry):
    from_ne_m: Vec2
    to_ne_m: Vec2
    height_m: float = Field(1.2, gt=0, le=10)
    post_spacing_m: float = Field(3.0, gt=0.2, le=50)
    kind: Literal["wire", "panel"] = "wire"
    strands: int = Field(3, ge=1, le=20)
    wire_radius_m: float = Field(0.0015, gt=0, le=0.1)


class WireEntry(_Entry):
    points_ned_m: list[Vec3] | None = None
    start_ned_m: Vec3 | None = None
    end_ned_m: Vec3 | None = None
    sag_m: float = Field(0.0, ge=0, le=50)
    radius_m: float = Field(0.005, gt=0, le=0.5)
    albedo: float = Field(0.2, gt=0, le=2)

    @model_validator(mode="after")
    def _one_shape(self) -> WireEntry:
        ends = self.start_ned_m is not None and self.end_ned_m is not None
        if (self.points_ned_m is None) == (not ends):
            raise ValueError("give either points_ned_m or both start_ned_m and end_ned_m")
        if self.points_ned_m is not None and len(self.points_ned_m) < 2:
            raise ValueError("points_ned_m needs at least two points")
        return self


class ConductorEntry(_Entry):
    offset_m: float = Field(0.0, ge=-20, le=20)
    height_m: float = Field(gt=0, le=100)


class PowerLineEntry(_Entry):
    supports_ne_m: list[Vec2] = Field(min_length=2)
    conductors: list[ConductorEntry] = Field(min_length=1)
    sag_m: float = Field(1.0, ge=0, le=50)
    radius_m: float = Field(0.012, gt=0, le=0.5)
    support: Literal["tower", "pole"] = "tower"
    support_height_m: float | None = Field(None, gt=0, le=150)
    albedo: float = Field(0.45, gt=0, le=2)


class CheckerboardEntry(_Entry):
    north_m: float
    east_m: float
    down_m: float
    squares: tuple[int, int] = (9, 6)
    square_m: float = Field(0.1, gt=0, le=2)


class WorldFile(_Entry):
    """The schema of a world file (top-level keys and tables); see `docs/worlds.md`."""

    name: str = "world"
    seed: int = 0
    start: StartEntry = Field(default_factory=StartEntry)
    goal: list[GoalEntry] = Field(default_factory=list)
    ground: GroundEntry = Field(default_factory=GroundEntry)
    lighting: LightingEntry = Field(default_factory=LightingEntry)
    box: list[BoxEntry] = Field(default_factory=list)
    building: list[BuildingEntry] = Field(default_factory=list)
    pole: list[PoleEntry] = Field(default_factory=list)
    tree: list[TreeEntry] = Field(default_factory=list)
    ladder: list[LadderEntry] = Field(default_factory=list)
    fence: list[FenceEntry] = Field(default_factory=list)
    wire: list[WireEntry] = Field(default_factory=list)
    power_line: list[PowerLineEntry] = Field(default_factory=list)
    checkerboard: list[CheckerboardEntry] = Field(default_factory=list)
    fault: list[FaultSpec] = Field(default_factory=list)  # injected by `wireavoid sim` (faults)


def _compiled_parts(doc: WorldFile) -> WorldParts:
    """Every object of the file as solids and wires, in file order per kind."""
    g = doc.ground.down_m
    parts = [
        WorldParts(
            tuple(
                Solid(Box(b.min_ned_m, b.max_ned_m), b.albedo, b.material, b.kind) for b in doc.box
            )
        )
    ]
    parts += [
        box_on_ground(*b.centre_ne_m, b.size_m, g, b.material, "building", b.albedo)
        for b in doc.building
    ]
    parts += [
        WorldParts((pole_solid(*p.position_ne_m, p.height_m, g, p.width_m, p.material),))
        for p in doc.pole
    ]
    parts += [tree(*t.position_ne_m, t.height_m, t.crown_radius_m, g) for t in doc.tree]
    parts += [
        ladder(*lad.position_ne_m, lad.height_m, g, lad.width_m, lad.facing) for lad in doc.ladder
    ]
    parts += [
        fence(
            f.from_ne_m,
            f.to_ne_m,
            f.height_m,
            g,
            f.post_spacing_m,
            f.kind,
            f.strands,
            f.wire_radius_m,
        )
        for f in doc.fence
    ]
    for w in doc.wire:
        if w.points_ned_m is not None:
            wire = Wire(np.array(w.points_ned_m), w.radius_m)
        else:
            wire = catenary_wire(w.start_ned_m, w.end_ned_m, w.sag_m, w.radius_m)
        parts.append(WorldParts((), (wire,), (w.albedo,)))
    parts += [
        power_line(
            np.array(p.supports_ne_m),
            tuple((c.offset_m, c.height_m) for c in p.conductors),
            p.sag_m,
            p.radius_m,
            p.support,
            p.support_height_m,
            g,
            p.albedo,
        )
        for p in doc.power_line
    ]
    return combined(parts)


def world_from_document(doc: WorldFile) -> World:
    """The `World` a parsed world file describes."""
    parts = _compiled_parts(doc)
    light = doc.lighting
    return World(
        solids=parts.solids,
        wires=parts.wires,
        boards=tuple(
            Checkerboard(c.north_m, c.east_m, c.down_m, c.squares, c.square_m)
            for c in doc.checkerboard
        ),
        ground_down_m=doc.ground.down_m,
        seed=doc.seed,
        name=doc.name,
        start_ned_m=np.array(doc.start.position_ned_m),
        start_yaw_rad=float(np.deg2rad(doc.start.yaw_deg)),
        takeoff_altitude_m=doc.start.takeoff_altitude_m,
        goals_ned_m=np.array([g.position_ned_m for g in doc.goal]).reshape(-1, 3),
        ground_material=doc.ground.material,
        lighting=Lighting(
            float(np.deg2rad(light.sun_azimuth_deg)),
            float(np.deg2rad(light.sun_elevation_deg)),
            light.cloud_cover,
            light.haze,
        ),
        wire_albedos=parts.wire_albedos,
    )


def _key_path(loc: tuple) -> str:
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out


def _line_of(text: str, loc: tuple) -> int | None:
    """1-based line of the key at `loc` (table, [index], key, ...) in TOML `text`: the key's
    line, else its table's header line; None when neither is found."""
    parts = list(loc)
    table = index = key = None
    if len(parts) >= 2 and isinstance(parts[1], int):
        table, index = parts[0], parts[1]
        key = parts[2] if len(parts) > 2 and isinstance(parts[2], str) else None
    elif len(parts) >= 2:
        table, key = parts[0], parts[1]
    elif parts:
        key = parts[0]
    current: tuple = (None, None)
    counts: dict[str, int] = {}
    header_line = None
    for number, line in enumerate(text.splitlines(), 1):
        stripped = line.strip()
        header = re.match(r"^\[\[\s*([\w-]+)\s*\]\]", stripped) or re.match(
            r"^\[\s*([\w-]+)\s*\]", stripped
        )
        if header:
            name = header.group(1)
            if stripped.startswith("[["):
                counts[name] = counts.get(name, -1) + 1
                current = (name, counts[name])
            else:
                current = (name, None)
            if current == (table, index):
                header_line = number
            continue
        if (
            current == (table, index)
            and key is not None
            and re.match(rf"^{re.escape(str(key))}\s*=", stripped)
        ):
            return number
    return header_line


def _document(text: str, source: str) -> WorldFile:
    """The validated document of world-file `text` (errors name `source`, line and key)."""
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise WorldFileError(f"{source}: {error}") from error
    try:
        return WorldFile.model_validate(raw)
    except ValidationError as error:
        lines = []
        for item in error.errors():
            line = _line_of(text, item["loc"])
            where = f"{source}:{line}" if line else source
            lines.append(f"{where}: {_key_path(item['loc'])}: {item['msg']}")
        raise WorldFileError("\n".join(lines)) from error


def world_from_toml(text: str, source: str = "<world>") -> World:
    """Parse and compile world-file `text`; errors raise `WorldFileError` naming `source`,
    the line and the key."""
    doc = _document(text, source)
    try:
        return world_from_document(doc)
    except ValueError as error:
        raise WorldFileError(f"{source}: {error}") from error


def load_world(path: str | Path) -> World:
    """The `World` described by the TOML world file at `path`."""
    path = Path(path)
    return world_from_toml(path.read_text(), str(path))


def load_faults(path: str | Path) -> list[FaultSpec]:
    """The `[[fault]]` tables of the world file at `path` (`hil.faults.FaultSpec`)."""
    path = Path(path)
    return list(_document(path.read_text(), str(path)).fault)


def _toml_value(value: object) -> str:
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | np.integer):
        return str(int(value))
    if isinstance(value, float | np.floating):
        return repr(float(value))
    if isinstance(value, np.ndarray):
        return _toml_value(value.tolist())
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise TypeError(f"cannot write {type(value).__name__} to TOML")


def _table(header: str, values: dict[str, object]) -> str:
    return "\n".join([header, *(f"{k} = {_toml_value(v)}" for k, v in values.items())]) + "\n"


def world_to_toml(world: World) -> str:
    """The compiled `world` as world-file text: every solid a `[[box]]`, every wire a
    `[[wire]]` polyline; `world_from_toml` reads it back to the same world."""
    light = world.lighting
    out = [
        f"name = {_toml_value(world.name)}\nseed = {world.seed}\n",
        _table(
            "[start]",
            {
                "position_ned_m": world.start_ned_m,
                "yaw_deg": float(np.rad2deg(world.start_yaw_rad)),
                "takeoff_altitude_m": float(world.takeoff_altitude_m),
            },
        ),
        _table(
            "[ground]",
            {"down_m": float(world.ground_down_m), "material": world.ground_material},
        ),
        _table(
            "[lighting]",
            {
                "sun_azimuth_deg": float(np.rad2deg(light.sun_azimuth_rad)),
                "sun_elevation_deg": float(np.rad2deg(light.sun_elevation_rad)),
                "cloud_cover": float(light.cloud_cover),
                "haze": float(light.haze),
            },
        ),
    ]
    out += [_table("[[goal]]", {"position_ned_m": g}) for g in world.goals_ned_m]
    out += [
        _table(
            "[[box]]",
            {
                "min_ned_m": s.box.min_ned_m,
                "max_ned_m": s.box.max_ned_m,
                "material": s.material,
                "albedo": float(s.albedo),
                "kind": s.kind,
            },
        )
        for s in world.solids
    ]
    out += [
        _table(
            "[[wire]]",
            {"points_ned_m": w.points_ned_m, "radius_m": float(w.radius_m), "albedo": a},
        )
        for w, a in zip(world.wires, world.wire_albedos, strict=True)
    ]
    out += [
        _table(
            "[[checkerboard]]",
            {
                "north_m": float(b.north_m),
                "east_m": float(b.east_m),
                "down_m": float(b.down_m),
                "squares": list(b.squares),
                "square_m": float(b.square_m),
            },
        )
        for b in world.boards
    ]
    return "\n".join(out)
