"""Selection of thesis 4.5 on a hand-made library: eq. 4.7 pruning, eq. 4.8 cost, checks."""

import numpy as np
import pytest

from mapping.query import OccupancyQuery
from planning.params import CheckMode, PlanningParams, UnknownPolicy
from planning.selection import (
    braking_distance_m,
    checked_waypoints,
    pruned_costs,
    select_trajectory,
    waypoint_costs,
)

ORIGIN = np.array([0.0, 0.0, -3.0])
GOAL = np.array([10.0, 0.0, -3.0])
FORWARD = np.array([1.0, 0.0, 0.0])
PARAMS = PlanningParams(
    alpha=0.5,
    distance_scale_m=1.0,
    descent_cost_per_m=0.0,
    safety_margin_m=0.0,
    unknown_policy=UnknownPolicy.FREE,
    check_mode=CheckMode.CHUNKED,
    check_chunk_size=1,
)
# K = 4 trajectories of m = 3 waypoints (NED, z = -3 m): straight towards the goal, a turn
# away from it, a dash past the goal's line that turns (best at its middle waypoint), a stop.
A, B, C, STOP = 0, 1, 2, 3
POSITIONS = (
    np.array(
        [
            [[1, 0, 0], [2, 0, 0], [3, 0, 0]],
            [[0, 1, 0], [0, 2, 0], [0, 3, 0]],
            [[4, 0, 0], [8, 0, 0], [8, 4, 0]],
            [[0, 0, 0], [0, 0, 0], [0, 0, 0]],
        ],
        float,
    )
    + ORIGIN
)
VELOCITIES = np.array(
    [
        [[1, 0, 0], [1, 0, 0], [1, 0, 0]],
        [[0, 1, 0], [0, 1, 0], [0, 1, 0]],
        [[1, 0, 0], [0, 1, 0], [0, 1, 0]],
        [[0, 0, 0], [0, 0, 0], [0, 0, 0]],
    ],
    float,
)


class PointMap:
    """Collision inside given spheres, seen where `seen_fn` says; records every query."""

    def __init__(self, centres=(), radius_m: float = 0.5, seen_fn=None) -> None:
        self.centres = np.array(centres, float).reshape(-1, 3)
        self.radius_m = radius_m
        self.seen_fn = seen_fn or (lambda pts: np.ones(len(pts), bool))
        self.queries: list[np.ndarray] = []

    def query(self, points_ned_m: np.ndarray) -> OccupancyQuery:
        self.queries.append(points_ned_m.copy())
        gaps = np.linalg.norm(points_ned_m[:, None] - self.centres[None], axis=-1)
        seen = self.seen_fn(points_ned_m)
        hit = (gaps <= self.radius_m).any(axis=1) & seen
        return OccupancyQuery(hit, hit.astype(float), seen, hit)


def select(occupancy_map, params=PARAMS, **kwargs):
    return select_trajectory(
        POSITIONS, VELOCITIES, ORIGIN, GOAL, FORWARD, occupancy_map, params, STOP, **kwargs
    )


def test_waypoint_costs_and_eq_4_7_4_8_match_hand_computed_values() -> None:
    costs = waypoint_costs(POSITIONS, VELOCITIES, GOAL, FORWARD, PARAMS)
    half_pi = np.pi / 2
    expected = np.array(
        [
            [4.5, 4.0, 3.5],  # 0.5 * distance, heading straight at the goal
            [
                0.5 * np.sqrt(101) + 0.5 * (half_pi + np.arctan(1 / 10)),
                0.5 * np.sqrt(104) + 0.5 * (half_pi + np.arctan(2 / 10)),
                0.5 * np.sqrt(109) + 0.5 * (half_pi + np.arctan(3 / 10)),
            ],
            [3.0, 1.0 + 0.5 * half_pi, 0.5 * np.sqrt(20) + 0.5 * np.arccos(-4 / np.sqrt(20))],
            [5.0, 5.0, 5.0],  # stopped: the direction is the library's forward axis
        ]
    )
    np.testing.assert_allclose(costs, expected, atol=1e-12)

    prune, cost = pruned_costs(costs)
    np.testing.assert_array_equal(prune, [2, 0, 1, 0])  # eq. 4.7: argmin over the waypoints
    # eq. 4.8 sums c_1..c_i; the implementation ranks by that sum over i (documented mean)
    sums = [12.0, expected[1, 0], 3.0 + 1.0 + 0.5 * half_pi, 5.0]
    np.testing.assert_allclose(cost * (prune + 1), sums, atol=1e-12)
    np.testing.assert_allclose(cost, [4.0, expected[1, 0], (4.0 + 0.5 * half_pi) / 2, 5.0])


def test_alpha_weighs_distance_against_heading() -> None:
    only_heading = PARAMS.model_copy(update={"alpha": 0.0})
    costs = waypoint_costs(POSITIONS, VELOCITIES, GOAL, FORWARD, only_heading)
    np.testing.assert_allclose(costs[A], 0.0, atol=1e-12)
    only_distance = PARAMS.model_copy(update={"alpha": 1.0})
    costs = waypoint_costs(POSITIONS, VELOCITIES, GOAL, FORWARD, only_distance)
    np.testing.assert_allclose(costs[C], [6.0, 2.0, np.sqrt(20)])


def test_trajectories_are_checked_in_ascending_cost_and_the_first_free_wins() -> None:
    free_map = PointMap()
    chosen = select(free_map)
    assert chosen.index == C and chosen.checked == 1 and chosen.queries == 1
    assert chosen.free.tolist() == [False, False, True, False]  # the rest unchecked

    blocked = PointMap(centres=[[8.0, 0.0, -3.0]])  # C's best waypoint is occupied
    chosen = select(blocked)
    assert chosen.index == A and chosen.checked == 2
    assert chosen.free.tolist() == [True, False, False, False]
    # chunk size 1: one query per trajectory, in the order C (2.39), A (4.0)
    assert [q[0, 0] for q in blocked.queries] == [4.0, 1.0]

    walled = PointMap(centres=[[8.0, 0.0, -3.0], [2.0, 0.0, -3.0], [0.0, 2.0, -3.0]])
    chosen = select(walled)
    assert chosen.index == STOP  # only the brake is left: checked last
    assert chosen.checked == 4 and chosen.free.tolist() == [False, False, False, True]
    assert (
        select(PointMap(centres=[ORIGIN], radius_m=20.0)).index is None
    )  # not even the stop is free

    all_at_once = PARAMS.model_copy(update={"check_mode": CheckMode.ALL})
    one_query = PointMap(centres=[[8.0, 0.0, -3.0]])
    chosen = select(one_query, all_at_once)
    assert chosen.index == A and chosen.queries == 1 and len(one_query.queries) == 1


def test_the_unknown_space_policy_changes_the_choice() -> None:
    def near_only(pts: np.ndarray) -> np.ndarray:
        return pts[:, 0] < 5.0  # C's last two waypoints (x = 8) were never observed

    policy = {
        "free": (UnknownPolicy.FREE, 2.0, C),
        "collision": (UnknownPolicy.COLLISION, 2.0, A),
        "cheap unknown": (UnknownPolicy.COST, 1.0, C),
        "expensive unknown": (UnknownPolicy.COST, 3.0, A),
    }
    for name, (unknown, unknown_cost, expected) in policy.items():
        params = PARAMS.model_copy(
            update={"unknown_policy": unknown, "unknown_cost": unknown_cost, "check_chunk_size": 4}
        )
        chosen = select(PointMap(seen_fn=near_only), params)
        assert chosen.index == expected, name
    # cost policy: the unseen share (2 of 3 checked waypoints) is added to eq. 4.8
    params = PARAMS.model_copy(
        update={"unknown_policy": UnknownPolicy.COST, "unknown_cost": 3.0, "check_chunk_size": 4}
    )
    chosen = select(PointMap(seen_fn=near_only), params)
    assert chosen.cost[C] == pytest.approx((4.0 + 0.5 * np.pi / 2) / 2 + 3.0 * 2 / 3)
    # cost policy: unseen space within the braking distance is a collision, not a cost; only
    # the stop, which stays inside the vehicle's own volume, needs no observation
    blind = PointMap(seen_fn=lambda pts: np.zeros(len(pts), bool))
    assert select(blind, params.model_copy(update={"safety_margin_m": 5.0})).index == STOP
    # ... unless even the vehicle's own volume is taken as unknown
    no_volume = params.model_copy(update={"safety_margin_m": 5.0, "own_volume_m": 0.0})
    assert select(blind, no_volume).index is None


def test_the_vehicles_own_volume_needs_no_observation() -> None:
    # unseen only within 1 m of the start (closer than any camera sees): the straight A is
    # flown once those points lie inside the vehicle's own volume, refused otherwise
    # (C, cheaper, is blocked at its first waypoint)
    near_blind = PointMap(
        centres=[POSITIONS[C, 0]], seen_fn=lambda pts: np.linalg.norm(pts - ORIGIN, axis=1) > 1.01
    )
    params = PARAMS.model_copy(
        update={"unknown_policy": UnknownPolicy.COST, "safety_margin_m": 2.0, "check_chunk_size": 4}
    )
    assert select(near_blind, params.model_copy(update={"own_volume_m": 1.02})).index == A
    assert select(near_blind, params.model_copy(update={"own_volume_m": 0.0})).index is None


def test_the_own_volume_stays_where_a_recovering_vehicle_stopped() -> None:
    # anchored 1 m behind the start, the volume no longer covers the unseen first metre: a
    # vehicle creeping on in recovery cannot carry its exemption into space nobody has seen
    line = np.zeros((1, 8, 3))
    line[0, :, 0] = np.arange(0.25, 2.25, 0.25)
    speed = np.zeros((1, 8, 3))
    speed[0, :, 0] = 1.0
    volume = PARAMS.model_copy(update={"own_volume_m": 0.6})
    _, near = checked_waypoints(line, speed, np.zeros(3), np.array([7]), volume)
    _, anchored = checked_waypoints(
        line, speed, np.zeros(3), np.array([7]), volume, np.array([-1.0, 0.0, 0.0])
    )
    assert not near[0, :2].any()  # 0.25 and 0.5 m: inside the vehicle
    assert anchored[0, :2].all()  # 1.25 and 1.5 m from where it stopped: must be seen


def test_braking_distance_and_safety_margin_extend_the_checked_path() -> None:
    assert braking_distance_m(2.0, PARAMS) == pytest.approx(2.0**2 / 4.0 + 2.0 * 2.0 / 8.0)
    line = np.zeros((1, 8, 3))
    line[0, :, 0] = np.arange(1.0, 9.0)
    speed = np.zeros((1, 8, 3))
    speed[0, :, 0] = 2.0
    margin = PARAMS.model_copy(update={"safety_margin_m": 0.5})
    checked, near = checked_waypoints(line, speed, np.zeros(3), np.array([2]), margin)
    # followed to x = 3, + 1.5 m braking + 0.5 m margin = 5, + the first waypoint beyond
    assert checked[0].tolist() == [True] * 6 + [False] * 2
    assert near[0].tolist() == [True] * 2 + [False] * 6  # 1.5 + 0.5 m from the start
    checked, _ = checked_waypoints(line, speed, np.zeros(3), np.array([2]), PARAMS)
    assert checked[0].tolist() == [True] * 5 + [False] * 3

    # an obstacle 6 m ahead: outside the checked path without margin, inside with it
    positions = np.concatenate([line, np.zeros((1, 8, 3))]) + ORIGIN
    velocities = np.concatenate([speed, np.zeros((1, 8, 3))])
    obstacle = PointMap(centres=[[6.0, 0.0, -3.0]], radius_m=0.1)
    goal = ORIGIN + np.array([3.0, 0.0, 0.0])  # alpha 1: pruned at x = 3, as above
    for params, expected in ((PARAMS, 0), (margin, 1)):
        params = params.model_copy(update={"alpha": 1.0})
        chosen = select_trajectory(
            positions, velocities, ORIGIN, goal, FORWARD, obstacle, params, 1
        )
        assert chosen.prune_index[0] == 2
        assert chosen.index == expected


def test_hysteresis_and_descent_cost_shift_the_ranking() -> None:
    sticky = PARAMS.model_copy(update={"switch_cost": 10.0})
    assert select(PointMap(), sticky, previous_index=A).index == A
    assert select(PointMap(), sticky, previous_index=C).index == C
    sinking = POSITIONS.copy()
    sinking[C, :, 2] += 2.0  # C now descends 2 m at its pruned waypoint
    chosen = select_trajectory(
        sinking,
        VELOCITIES,
        ORIGIN,
        GOAL,
        FORWARD,
        PointMap(),
        PARAMS.model_copy(update={"descent_cost_per_m": 1.0, "min_altitude_m": 0.0}),
        STOP,
    )
    assert chosen.index == A


def test_descent_costs_only_below_the_start_and_the_goal() -> None:
    # two ways forward: level, and descending 2 m; the descent costs extra with the goal at
    # the start's altitude (wires are passed over), nothing with the goal 2 m below
    level = np.array([[1.0, 0, 0], [2, 0, 0], [3, 0, 0]])
    down = level + np.array([[0, 0, 0.7], [0, 0, 1.4], [0, 0, 2.0]])
    positions = np.stack([level, down, np.zeros((3, 3))]) + ORIGIN
    velocities = np.zeros_like(positions)
    velocities[:2, :, 0] = 1.0
    params = PARAMS.model_copy(update={"descent_cost_per_m": 0.3, "alpha": 1.0})
    free = PointMap()
    costs = {}
    for name, goal in (("level", GOAL), ("below", GOAL + np.array([0.0, 0.0, 2.0]))):
        plain = select_trajectory(
            positions,
            velocities,
            ORIGIN,
            goal,
            FORWARD,
            free,
            PARAMS.model_copy(update={"alpha": 1.0}),
            2,
        )
        priced = select_trajectory(positions, velocities, ORIGIN, goal, FORWARD, free, params, 2)
        costs[name] = priced.cost[:2] - plain.cost[:2]
    np.testing.assert_allclose(costs["level"], [0.0, 0.3 * 2.0])
    np.testing.assert_allclose(costs["below"], [0.0, 0.0])


def test_the_ceiling_is_a_collision_but_never_stops_a_descent_from_above_it() -> None:
    # two ways forward from 3 m: level, and climbing 2 m towards a goal 2 m up (the cheaper)
    level = np.array([[1.0, 0, 0], [2, 0, 0], [3, 0, 0]])
    up = level - np.array([[0, 0, 0.7], [0, 0, 1.4], [0, 0, 2.0]])
    positions = np.stack([up, level, np.zeros((3, 3))]) + ORIGIN
    velocities = np.zeros_like(positions)
    velocities[:2, :, 0] = 1.0
    goal = GOAL - np.array([0.0, 0.0, 2.0])

    def chosen(origin_up_m: float, ceiling_m: float) -> int | None:
        lift = np.array([0.0, 0.0, -origin_up_m])
        params = PARAMS.model_copy(update={"max_altitude_m": ceiling_m, "min_altitude_m": 0.0})
        origin = ORIGIN + lift
        return select_trajectory(
            positions + lift, velocities, origin, goal, FORWARD, PointMap(), params, 2
        ).index

    assert chosen(0.0, 120.0) == 0  # the climb, towards the goal
    assert chosen(0.0, 4.0) == 1  # the climb's 5 m is over the 4 m ceiling: level
    assert chosen(3.0, 4.0) == 1  # above it already (6 m): no higher, level is allowed
