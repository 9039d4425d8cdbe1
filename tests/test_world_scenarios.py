"""The built-in scenarios (hil.world.scenarios): deterministic, blocked straight ahead, flyable.

Flyable means: a path from the take-off point through every goal keeps the vehicle's 0.5 m
radius (plus 0.2 m) off the true geometry, within what the trajectory library flies at 2 m/s:
climbs no steeper than 0.4 (the library climbs at up to 1 m/s) of at most 4 m, or turns
around the obstacles at the flight altitude.
"""

import itertools

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import shortest_path

from hil.judge import clearance_m
from hil.world.file import world_from_toml, world_to_toml
from hil.world.scenarios import SCENARIOS, build_scenario

RADIUS_M = 0.5
MARGIN_M = 0.2
MAX_SLOPE = 0.4
MAX_CLIMB_M = 4.0
REQUIRED = {
    "ladder-wire",
    "ladder-wire-left",
    "ladder-wire-right",
    "stacked-wires",
    "curvy-corridor",
    "power-line-corridor",
    "random",
}


def test_the_scenarios_the_sim_command_names_exist_and_are_described() -> None:
    assert set(SCENARIOS) >= REQUIRED
    assert all(len(text) > 20 for text in SCENARIOS.values())
    with pytest.raises(ValueError, match="unknown scenario"):
        build_scenario("no-such-world", 0)


@pytest.mark.parametrize("name", sorted(REQUIRED))
def test_a_scenario_is_deterministic_and_the_seed_varies_it(name: str) -> None:
    text = world_to_toml(build_scenario(name, 3))
    assert world_to_toml(build_scenario(name, 3)) == text
    assert world_to_toml(build_scenario(name, 4)) != text
    assert world_to_toml(world_from_toml(text)) == text  # serialisable


def straight_line(world, steps: int = 400) -> np.ndarray:
    t = np.linspace(0.0, 1.0, steps)[:, None]
    return world.takeoff_point_ned_m + t * (world.goals_ned_m[0] - world.takeoff_point_ned_m)


@pytest.mark.parametrize("name", sorted(REQUIRED))
def test_the_obstacle_blocks_the_straight_flight_and_the_goals_are_clear(name: str) -> None:
    for seed in range(12):
        world = build_scenario(name, seed)
        obstacle, wire = clearance_m(world, straight_line(world))
        if name == "curvy-corridor":
            assert obstacle.min() < RADIUS_M, seed  # walls, no wire
            assert not world.wires
        else:
            assert wire.min() < RADIUS_M, seed  # a wire really is in the way
        ends = np.vstack([world.goals_ned_m, world.takeoff_point_ned_m])
        assert np.minimum(*clearance_m(world, ends)).min() > 1.5, seed
        legs = np.diff(world.goals_ned_m, axis=0, prepend=[world.takeoff_point_ned_m])
        length = np.linalg.norm(legs, axis=1).sum()
        assert 9.0 <= length <= 45.0, seed  # 20-40 s at 2 m/s with the climbs and turns


def test_the_ladder_wire_varies_the_start_distance_and_sends_goals_left_and_right() -> None:
    distances = [build_scenario("ladder-wire", s).wires[0].points_ned_m[0, 0] for s in range(20)]
    assert min(distances) >= 8.0 and max(distances) <= 14.0 and np.ptp(distances) > 4.0
    for name, side in (("ladder-wire-left", -1), ("ladder-wire-right", 1)):
        world = build_scenario(name, 0)
        goal = world.goals_ned_m[0]
        behind = goal[0] - world.wires[0].points_ned_m[0, 0]
        assert 10.0 <= behind <= 15.0 and np.sign(goal[1]) == side and abs(goal[1]) >= 6.0
    assert {s.kind for s in build_scenario("ladder-wire", 0).solids} >= {"ladder"}


def test_a_known_detour_over_the_ladder_wire_is_clear() -> None:
    world = build_scenario("ladder-wire", 0)
    wire_north = world.wires[0].points_ned_m[0, 0]
    top = -world.wires[0].points_ned_m[:, 2].max()  # the wire's highest point, m up
    start, goal = world.takeoff_point_ned_m, world.goals_ned_m[0]
    over = np.array([0.0, 0.0, -(top + 1.2)])
    waypoints = np.array(
        [start, [wire_north - 4, 0, over[2]], [wire_north + 2, 0, over[2]], goal], float
    )
    t = np.linspace(0, 1, 200)[:, None]
    path = np.vstack([a + t * (b - a) for a, b in itertools.pairwise(waypoints)])
    obstacle, wire = clearance_m(world, path)
    assert wire.min() > RADIUS_M + 0.5 and obstacle.min() > RADIUS_M
    assert -over[2] - world.takeoff_altitude_m < 2.5  # a climb of under 2.5 m


def legs(world, spacing_m: float = 0.1) -> np.ndarray:
    """`(N, 3)` points along the straight legs take-off point -> goal 1 -> goal 2 ..."""
    corners = np.vstack([world.takeoff_point_ned_m, world.goals_ned_m])
    out = []
    for a, b in itertools.pairwise(corners):
        count = int(np.ceil(np.linalg.norm(b - a) / spacing_m)) + 1
        out.append(a + np.linspace(0.0, 1.0, count)[:, None] * (b - a))
    return np.vstack(out)


def climb_over(world) -> np.ndarray:
    """The legs raised 1 m over everything within 1.5 m of them, slope-limited (see module)."""
    path = legs(world)
    distance = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
    needed = -path[:, 2]
    for solid in world.solids:
        lo, hi = solid.box.min_ned_m[:2] - 1.5, solid.box.max_ned_m[:2] + 1.5
        near = np.all((path[:, :2] >= lo) & (path[:, :2] <= hi), axis=1)
        needed = np.where(near, np.maximum(needed, -solid.box.min_ned_m[2] + 1.0), needed)
    for wire in world.wires:
        points = wire.sample(0.1)
        horizontal = np.linalg.norm(path[:, None, :2] - points[None, :, :2], axis=2)
        tops = np.where(horizontal < 1.5, -points[None, :, 2] + 1.0, -np.inf).max(axis=1)
        needed = np.maximum(needed, tops)
    # the upper envelope of climb/descent cones of slope MAX_SLOPE under every requirement
    profile = (needed[None, :] - MAX_SLOPE * np.abs(distance[:, None] - distance[None, :])).max(1)
    return np.column_stack([path[:, :2], -profile])


def around(world, resolution_m: float = 0.25) -> np.ndarray:
    """The shortest 8-connected path at the take-off altitude through cells with clearance,
    over a grid covering the legs with 6 m of margin (Dijkstra)."""
    corners = np.vstack([world.takeoff_point_ned_m, world.goals_ned_m])
    lo, hi = corners[:, :2].min(axis=0) - 6.0, corners[:, :2].max(axis=0) + 6.0
    n, e = np.meshgrid(*(np.arange(a, b, resolution_m) for a, b in zip(lo, hi, strict=True)))
    cells = np.column_stack([n.ravel(), e.ravel(), np.full(n.size, corners[0, 2])])
    free = np.minimum(*clearance_m(world, cells)) > RADIUS_M + MARGIN_M + 0.1
    shape = n.shape
    index = np.arange(n.size).reshape(shape)
    rows, cols, weights = [], [], []
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
        a = index[max(0, -dr) : shape[0] - max(0, dr), max(0, -dc) : shape[1] - max(0, dc)]
        b = index[max(0, dr) :, max(0, dc) :][: a.shape[0], : a.shape[1]]
        if dc < 0:
            a = index[: shape[0] - dr, 1:]
            b = index[dr:, : shape[1] - 1]
        ok = free[a.ravel()] & free[b.ravel()]
        rows.append(a.ravel()[ok])
        cols.append(b.ravel()[ok])
        weights.append(np.full(int(ok.sum()), np.hypot(dr, dc)))
    graph = coo_matrix(
        (np.concatenate(weights), (np.concatenate(rows), np.concatenate(cols))), (n.size, n.size)
    )
    route = [int(np.argmin(np.linalg.norm(cells[:, :2] - corners[0, :2], axis=1)))]
    for goal in corners[1:]:
        target = int(np.argmin(np.linalg.norm(cells[:, :2] - goal[:2], axis=1)))
        _, previous = shortest_path(
            graph, directed=False, indices=route[-1], return_predecessors=True
        )
        assert previous[target] >= 0, "no way around"
        back = [target]
        while back[-1] != route[-1]:
            back.append(int(previous[back[-1]]))
        route += back[::-1][1:]
    return cells[route]


@pytest.mark.parametrize("name", sorted(REQUIRED))
def test_a_known_detour_is_clear_and_within_the_librarys_reach(name: str) -> None:
    for seed in range(3):
        world = build_scenario(name, seed)
        path = around(world) if name == "curvy-corridor" else climb_over(world)
        obstacle, wire = clearance_m(world, path)
        assert np.minimum(obstacle, wire).min() > RADIUS_M + MARGIN_M, seed
        climb = -path[:, 2].min() - world.takeoff_altitude_m
        assert climb <= MAX_CLIMB_M, (seed, climb)
        for goal in world.goals_ned_m:  # it passes every goal
            assert np.linalg.norm(path - goal, axis=1).min() < 0.5 + abs(climb), seed
