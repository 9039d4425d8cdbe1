"""World files (hil.world.file) and the objects they compile to (hil.world.parts)."""

from pathlib import Path

import numpy as np
import pytest

from hil.judge import clearance_m
from hil.world.file import WorldFileError, load_world, world_from_toml, world_to_toml
from hil.world.model import World
from hil.world.parts import ladder, power_line

EXAMPLES = sorted((Path(__file__).parents[1] / "hil" / "world" / "examples").glob("*.toml"))


def assert_same_world(a, b) -> None:
    assert (a.name, a.seed, a.ground_material, a.lighting) == (
        b.name,
        b.seed,
        b.ground_material,
        b.lighting,
    )
    np.testing.assert_array_equal(a.start_ned_m, b.start_ned_m)
    np.testing.assert_array_equal(a.goals_ned_m, b.goals_ned_m)
    assert a.start_yaw_rad == pytest.approx(b.start_yaw_rad, abs=1e-12)
    assert a.takeoff_altitude_m == b.takeoff_altitude_m
    assert len(a.solids) == len(b.solids) and len(a.wires) == len(b.wires)
    for s, t in zip(a.solids, b.solids, strict=True):
        np.testing.assert_array_equal(s.box.min_ned_m, t.box.min_ned_m)
        np.testing.assert_array_equal(s.box.max_ned_m, t.box.max_ned_m)
        assert (s.material, s.albedo, s.kind) == (t.material, t.albedo, t.kind)
    for v, u in zip(a.wires, b.wires, strict=True):
        np.testing.assert_array_equal(v.points_ned_m, u.points_ned_m)
        assert v.radius_m == u.radius_m
    assert a.wire_albedos == b.wire_albedos
    assert len(a.boards) == len(b.boards)


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.stem for p in EXAMPLES])
def test_every_example_loads_and_round_trips(path: Path) -> None:
    world = load_world(path)
    assert world.name == path.stem
    assert len(world.goals_ned_m) >= 1 and world.solids and world.wires
    text = world_to_toml(world)
    again = world_from_toml(text)
    assert_same_world(world, again)
    assert world_to_toml(again) == text
    # the goals and the take-off point are clear of everything
    points = np.vstack([world.goals_ned_m, world.takeoff_point_ned_m])
    obstacle, wire = clearance_m(world, points)
    assert np.minimum(obstacle, wire).min() > 1.0


def test_three_examples_cover_every_kind_of_object() -> None:
    kinds = {s.kind for p in EXAMPLES for s in load_world(p).solids}
    assert {"ladder", "tower", "pole", "tree", "building", "fence"} <= kinds
    assert len(EXAMPLES) >= 3


def test_errors_name_the_file_line_and_key() -> None:
    text = """name = "x"
[[ladder]]
position_ne_m = [1, 2]
height_m = 3
[[ladder]]
position_ne_m = [5, 2]
hieght_m = 3
"""
    with pytest.raises(WorldFileError) as error:
        world_from_toml(text, "yard.toml")
    message = str(error.value)
    assert "yard.toml:7: ladder[1].hieght_m: Extra inputs are not permitted" in message
    assert "yard.toml:5: ladder[1].height_m: Field required" in message
    with pytest.raises(WorldFileError, match=r"w.toml:3: ground.material: .*unknown material"):
        world_from_toml('seed = 1\n[ground]\nmaterial = "lava"\n', "w.toml")
    bad_conductor = """[[power_line]]
supports_ne_m = [[0, 0], [0, 30]]
conductors = [{ offset_m = 0.0, height_m = -1 }]
"""
    with pytest.raises(WorldFileError, match=r":3: power_line\[0\].conductors\[0\].height_m"):
        world_from_toml(bad_conductor, "w.toml")
    with pytest.raises(WorldFileError, match=r"w.toml: .*line 1"):
        world_from_toml("[start\n", "w.toml")
    with pytest.raises(WorldFileError, match=r"wire\[0\]: .*either points_ned_m or both"):
        world_from_toml("[[wire]]\nradius_m = 0.01\n", "w.toml")
    with pytest.raises(WorldFileError, match=r"box\[0\]: .*max_ned_m must exceed"):
        world_from_toml("[[box]]\nmin_ned_m = [0, 0, 0]\nmax_ned_m = [1, 1, -1]\n", "w.toml")


def test_a_ladder_stands_on_the_ground_and_reaches_its_height() -> None:
    parts = ladder(10.0, -4.0, 3.5, ground_down_m=0.5, facing="north")
    lo = np.min([s.box.min_ned_m for s in parts.solids], axis=0)
    hi = np.max([s.box.max_ned_m for s in parts.solids], axis=0)
    assert lo[2] == pytest.approx(0.5 - 3.5) and hi[2] == pytest.approx(0.5)
    assert hi[1] - lo[1] == pytest.approx(0.5 + 0.06)  # the rungs span east
    assert {s.kind for s in parts.solids} == {"ladder"}


def test_a_power_line_hangs_one_catenary_per_conductor_and_span() -> None:
    supports = np.array([[0.0, -30.0], [0.0, 0.0], [0.0, 30.0]])
    parts = power_line(supports, ((-1.5, 10.0), (1.5, 10.0)), sag_m=1.0, support="tower")
    assert len(parts.wires) == 2 * 2
    first = parts.wires[0].points_ned_m
    # hung 0.3 m under the arm at the towers, 1 m lower mid-span, offset across the line
    assert -first[0, 2] == pytest.approx(9.7) and -first[-1, 2] == pytest.approx(9.7)
    assert -first[len(first) // 2, 2] == pytest.approx(8.7, abs=0.02)
    assert abs(first[0, 0]) == pytest.approx(1.5)
    # every conductor end lies within 0.5 m of its tower's cross-arm (hanging on insulators)
    ends = np.vstack([w.points_ned_m[[0, -1]] for w in parts.wires])
    obstacle, _ = clearance_m(World(solids=parts.solids), ends)
    assert obstacle.max() < 0.5
