"""The planner against synthetic occupancy: around, over, inside, stop + recovery, rewind, goals.

A kinematic vehicle follows the tracker's setpoints (planner at 10 Hz, setpoints at 20 Hz) and
the map sees only what the vehicle's camera looked at (`SyntheticOccupancyMap` views), so
unknown space is really unknown. Collisions are judged on the ground-truth geometry.
"""

import itertools
from collections.abc import Iterable
from dataclasses import dataclass, replace

import numpy as np
import pytest
from kinematic import flown_velocity

from geometry.shapes import Box
from mapping.query import OccupancyQuery
from planning.library import generate_library
from planning.params import PlanningParams
from planning.planner import LocalPlanner
from planning.synthetic_occupancy import (
    SyntheticOccupancyMap,
    box_canyon,
    corridor,
    wall,
    wire_across,
)
from planning.tracker import PathTracker, sample_reference
from planning.types import PlannerOutput, PlannerState, Setpoint, SetpointKind, VehicleState

PARAMS = PlanningParams()
LIBRARY = generate_library(PARAMS)
START = np.array([0.0, 0.0, -3.0])
GOAL = np.array([20.0, 0.0, -3.0])
ROBOT_RADIUS_M = 0.3  # ground-truth clearance every flight must keep (maps inflate by 0.5)
SETPOINT_DT_S = 0.05


@dataclass
class Flight:
    path: np.ndarray  # (N, 3) positions at 20 Hz
    outputs: list[PlannerOutput]  # one per planning cycle (10 Hz)
    setpoints: list[Setpoint]
    planner: LocalPlanner

    @property
    def states(self) -> list[PlannerState]:
        return [o.state for o in self.outputs]

    def first(self, state: PlannerState) -> int:
        return self.states.index(state)


def fly(
    world: SyntheticOccupancyMap,
    goal: np.ndarray = GOAL,
    start: np.ndarray = START,
    duration_s: float = 40.0,
    params: PlanningParams = PARAMS,
    stop_at: Iterable[PlannerState] = (PlannerState.ARRIVED, PlannerState.UNREACHABLE),
) -> Flight:
    """Fly until a state in `stop_at` held for a cycle, or `duration_s` of simulated time."""
    planner, tracker = LocalPlanner(params, LIBRARY), PathTracker(params)
    planner.set_goal(goal, 0.0)
    position, velocity, yaw, now_s = np.array(start, float), np.zeros(3), 0.0, 0.0
    path, outputs, setpoints = [position.copy()], [], []
    while now_s < duration_s:
        world.add_view(position, yaw)
        output = planner.step(now_s, VehicleState(now_s, position, velocity, yaw), velocity, world)
        outputs.append(output)
        if len(outputs) > 1 and output.state in stop_at and outputs[-2].state is output.state:
            break
        for _ in range(2):
            vehicle = VehicleState(now_s, position, velocity, yaw)
            setpoint = tracker.setpoint(now_s, vehicle, output.reference, goal)
            setpoints.append(setpoint)
            velocity = flown_velocity(setpoint, position)
            position = position + SETPOINT_DT_S * velocity
            yaw = setpoint.yaw_rad
            now_s += SETPOINT_DT_S
            path.append(position.copy())
    return Flight(np.array(path), outputs, setpoints, planner)


def clearance_ok(boxes=(), wires=(), path=None) -> bool:
    truth = SyntheticOccupancyMap(boxes=list(boxes), wires=list(wires), inflation_m=ROBOT_RADIUS_M)
    return not truth.occupied(path).any()


def test_a_wall_across_the_path_is_flown_around() -> None:
    obstacle = wall(8.0, 1.5, 15.0)  # too high to climb over within the horizon
    flight = fly(SyntheticOccupancyMap(boxes=[obstacle]))
    assert flight.states[-1] is PlannerState.ARRIVED
    assert np.linalg.norm(flight.path[-1] - GOAL) <= PARAMS.arrival_tolerance_m + 0.1
    beside = flight.path[(flight.path[:, 0] > 7.5) & (flight.path[:, 0] < 8.8)]
    assert len(beside) and np.all(np.abs(beside[:, 1]) > 1.5 + ROBOT_RADIUS_M)
    assert np.ptp(flight.path[:, 2]) < 0.1  # around, not over
    assert clearance_ok(boxes=[obstacle], path=flight.path)
    assert len(flight.outputs) * 0.1 < 20.0


def test_a_low_wide_wall_is_flown_over() -> None:
    obstacle = wall(8.0, 10.0, 4.0)  # 20 m wide, 1 m above the flight altitude
    flight = fly(SyntheticOccupancyMap(boxes=[obstacle]))
    assert flight.states[-1] is PlannerState.ARRIVED
    crossing = flight.path[(flight.path[:, 0] > 7.5) & (flight.path[:, 0] < 8.8)]
    assert len(crossing) and np.all(-crossing[:, 2] > 4.0 + ROBOT_RADIUS_M)
    assert np.abs(flight.path[:, 1]).max() < 1.0  # over, not around
    assert clearance_ok(boxes=[obstacle], path=flight.path)


@pytest.mark.parametrize("altitude_m", [3.0, 3.4])
def test_a_wire_across_the_path_is_passed_over(altitude_m: float) -> None:
    obstacle = wire_across(8.0, altitude_m)
    flight = fly(SyntheticOccupancyMap(wires=[obstacle]))
    assert flight.states[-1] is PlannerState.ARRIVED
    crossing = flight.path[np.argmin(np.abs(flight.path[:, 0] - 8.0))]
    assert -crossing[2] > altitude_m + 0.5  # over the wire and its inflation
    assert clearance_ok(wires=[obstacle], path=flight.path)
    labels = {o.label for o in flight.outputs}
    assert any("climb" in label for label in labels)
    assert max(np.abs(flight.path[:, 1])) < 1.0  # straight over, no detour


@pytest.mark.parametrize(
    ("goal", "aligns"),
    [
        ([-6.0, 1.0, -3.0], True),  # behind, level: turn the camera to it first
        ([-0.3, 0.2, -1.0], False),  # right below: no turn shows it, and its bearing is noise
        ([-0.3, 0.3, -7.0], False),  # right above
    ],
)
def test_a_stopped_vehicle_turns_to_a_goal_off_its_nose_unless_it_is_below_or_above(
    goal: list[float], aligns: bool
) -> None:
    planner = LocalPlanner(PARAMS, LIBRARY)
    planner.set_goal(np.array(goal), 0.0)
    world = SyntheticOccupancyMap()
    world.add_view(START, 0.0)
    output = planner.step(0.0, VehicleState(0.0, START, np.zeros(3), 0.0), np.zeros(3), world)
    assert (output.label == "align") is aligns
    assert (output.state is PlannerState.ALIGNING) is aligns


def test_a_wire_over_the_path_with_a_ceiling_is_passed_under() -> None:
    obstacle = wire_across(8.0, 3.4)
    # a deck 4 m above home over the crossing: no way over, the flight floor is 1 m
    deck = Box(np.array([5.0, -30.0, -30.0]), np.array([11.0, 30.0, -4.0]))
    flight = fly(SyntheticOccupancyMap(boxes=[deck], wires=[obstacle]))
    assert flight.states[-1] is PlannerState.ARRIVED
    crossing = flight.path[np.argmin(np.abs(flight.path[:, 0] - 8.0))]
    assert PARAMS.min_altitude_m - 0.05 < -crossing[2] < 3.4 - 0.5
    assert clearance_ok(boxes=[deck], wires=[obstacle], path=flight.path)


def test_a_corridor_is_flown_inside() -> None:
    walls = corridor(2.0, 18.0, 2.0, 10.0)
    goal = np.array([22.0, 1.0, -3.0])
    flight = fly(SyntheticOccupancyMap(boxes=walls), goal)
    assert flight.states[-1] is PlannerState.ARRIVED
    inside = flight.path[(flight.path[:, 0] > 2.0) & (flight.path[:, 0] < 18.0)]
    assert len(inside) > 50
    assert np.abs(inside[:, 1]).max() < 2.0 - ROBOT_RADIUS_M
    assert clearance_ok(boxes=walls, path=flight.path)


@pytest.fixture(scope="module")
def canyon() -> tuple[list[Box], Flight]:
    boxes = box_canyon(-2.0, 10.0, 2.0, 6.0)  # walls, an end wall and a roof: a dead end
    return boxes, fly(
        SyntheticOccupancyMap(boxes=boxes), np.array([25.0, 0.0, -3.0]), duration_s=120.0
    )


def test_a_box_canyon_stops_the_vehicle_and_starts_recovery(canyon) -> None:
    boxes, flight = canyon
    states = flight.states
    braking = flight.first(PlannerState.BRAKING)
    recovering = flight.first(PlannerState.RECOVERING)
    assert all(s is PlannerState.TRACKING for s in states[:braking])
    assert braking < recovering
    assert all(s is PlannerState.BRAKING for s in states[braking:recovering])
    brake = flight.outputs[braking]
    assert brake.label == "stop" and brake.reference.brake
    assert flight.setpoints[2 * braking].kind is SetpointKind.BRAKE
    # recovery: hold the position and rotate in place (4.5)
    rotate = flight.outputs[recovering]
    assert rotate.label == "rotate"
    assert rotate.reference.yaw_rate_radps == PARAMS.recovery_yaw_rate_radps
    hold = flight.setpoints[2 * recovering + 1]
    assert hold.kind is SetpointKind.POSITION and hold.yaw_rate_radps > 0.0
    np.testing.assert_allclose(hold.velocity_ned_mps, 0.0)
    assert clearance_ok(boxes=boxes, path=flight.path)


def test_stuck_in_the_canyon_rewinds_along_the_flown_path_then_gives_up(canyon) -> None:
    _, flight = canyon
    rewinding = flight.first(PlannerState.REWINDING)
    rewind = flight.outputs[rewinding]
    assert rewind.label == "rewind"
    waypoints = rewind.reference.positions_ned_m
    flown = flight.path[: 2 * rewinding + 1]
    gaps = np.linalg.norm(waypoints[:, None] - flown[None], axis=-1).min(axis=1)
    assert gaps.max() < 0.05  # every rewind waypoint lies on the flown path
    length = np.linalg.norm(np.diff(waypoints, axis=0), axis=1).sum()
    assert PARAMS.rewind_distance_m <= length < PARAMS.rewind_distance_m + 1.0
    speed = np.linalg.norm(rewind.reference.velocities_ned_mps[:-1], axis=1)
    np.testing.assert_allclose(speed, PARAMS.rewind_speed_mps, rtol=1e-6)
    # the vehicle follows it back
    after = 2 * (rewinding + 40)
    assert np.linalg.norm(flight.path[after] - waypoints[-1]) < np.linalg.norm(
        flight.path[2 * rewinding] - waypoints[-1]
    )
    # the dead end is not circled forever: after the rewinds the goal is unreachable
    assert flight.states[-1] is PlannerState.UNREACHABLE
    assert flight.states.count(PlannerState.REWINDING) > 0
    assert len(flight.outputs) * 0.1 < 120.0


def test_a_goal_inside_an_obstacle_is_held_short_of_then_reported_unreachable() -> None:
    building = Box(np.array([18.0, -2.0, -6.0]), np.array([22.0, 2.0, 0.0]))
    flight = fly(SyntheticOccupancyMap(boxes=[building]), duration_s=60.0)
    assert flight.states[-1] is PlannerState.UNREACHABLE
    # held short of within the confirmation cycles of first seeing it, not after circling
    blocked = flight.first(PlannerState.GOAL_BLOCKED)
    assert blocked * 0.1 < 10.0
    # ...re-checked while holding, and given up only after the timeout
    held = flight.first(PlannerState.UNREACHABLE) - blocked
    assert held * 0.1 == pytest.approx(PARAMS.goal_blocked_timeout_s, abs=0.15)
    assert set(flight.states[blocked : blocked + held]) == {PlannerState.GOAL_BLOCKED}
    hold = flight.outputs[-1].reference
    assert hold.times_s.tolist() == [0.0]
    assert np.linalg.norm(hold.positions_ned_m[0] - flight.path[-1]) < 1.0
    assert np.ptp(flight.path[2 * blocked + 20 :], axis=0).max() < 0.3  # it held
    assert clearance_ok(boxes=[building], path=flight.path)


class VanishingBox(SyntheticOccupancyMap):
    """A false obstacle: its boxes answer for the first `lifetime` views, then are gone."""

    lifetime: int = 0

    def add_view(self, position_ned_m: np.ndarray, yaw_rad: float) -> None:
        self.lifetime -= 1
        if self.lifetime < 0:
            self.boxes = []
        super().add_view(position_ned_m, yaw_rad)


def test_a_goal_seen_blocked_then_free_is_flown_to() -> None:
    # one view's false obstacle over the goal (a stereo artefact, a wire's expansion from a
    # bad pose) must not end the mission: the goal is re-checked while the vehicle holds
    ghost = Box(np.array([18.0, -2.0, -6.0]), np.array([22.0, 2.0, 0.0]))
    world = VanishingBox(boxes=[ghost])
    world.lifetime = 150  # 15 s of planning cycles: long enough to be seen and confirmed
    flight = fly(world, duration_s=60.0)
    assert PlannerState.GOAL_BLOCKED in flight.states
    assert PlannerState.UNREACHABLE not in flight.states
    assert flight.states[-1] is PlannerState.ARRIVED
    assert np.linalg.norm(flight.path[-1] - GOAL) <= PARAMS.arrival_tolerance_m + 0.1


class WirePriorOnly(SyntheticOccupancyMap):
    """Its obstacles answer as the wire depth prior does: in collision, never solid."""

    def query(self, points_ned_m: np.ndarray) -> OccupancyQuery:
        return replace(super().query(points_ned_m), solid=np.zeros(len(points_ned_m), bool))


def test_a_goal_behind_only_the_wire_prior_is_not_declared_unreachable() -> None:
    # a wire seen without parallax lies anywhere on its rays (4.4.3): the prior keeps paths
    # out of it but cannot say that the goal itself is occupied
    building = Box(np.array([18.0, -2.0, -6.0]), np.array([22.0, 2.0, 0.0]))
    flight = fly(WirePriorOnly(boxes=[building]), duration_s=10.0)
    assert PlannerState.UNREACHABLE not in flight.states
    assert clearance_ok(boxes=[building], path=flight.path)


def test_arrival_within_tolerance_holds_position_at_the_goal() -> None:
    goal = np.array([6.0, 2.0, -3.5])
    flight = fly(SyntheticOccupancyMap(), goal, stop_at=())  # keep flying after arrival
    arrived = flight.first(PlannerState.ARRIVED)
    assert all(s is PlannerState.ARRIVED for s in flight.states[arrived:])
    assert np.linalg.norm(flight.path[2 * arrived] - goal) <= PARAMS.arrival_tolerance_m + 0.05
    holds = flight.setpoints[2 * arrived + 1 :]
    assert all(s.kind is SetpointKind.POSITION for s in holds)
    np.testing.assert_allclose(holds[-1].position_ned_m, goal)
    assert np.linalg.norm(flight.path[-1] - goal) < 0.05  # settled on the goal
    assert flight.outputs[-1].label == "" and flight.outputs[arrived].label == "arrived"


def test_without_a_goal_the_planner_holds() -> None:
    planner = LocalPlanner(PARAMS, LIBRARY)
    vehicle = VehicleState(0.0, START, np.zeros(3), 0.3)
    output = planner.step(0.0, vehicle, np.zeros(3), SyntheticOccupancyMap())
    assert output.state is PlannerState.IDLE
    np.testing.assert_allclose(output.reference.positions_ned_m, [START])


def test_no_progress_for_the_stuck_timeout_starts_a_rewind() -> None:
    """A vehicle that stops moving (a gust, a tether) while every plan looks free."""
    planner = LocalPlanner(PARAMS, LIBRARY)
    world = SyntheticOccupancyMap(omniscient=True)
    planner.set_goal(GOAL, 0.0)
    position, velocity = START.copy(), np.array([1.0, 0.0, 0.0])
    now_s, states = 0.0, []
    for _ in range(60):  # 6 s flying north at 1 m/s: breadcrumbs every 0.5 m
        planner.step(now_s, VehicleState(now_s, position, velocity, 0.0), velocity, world)
        position, now_s = position + 0.1 * velocity, now_s + 0.1
    stuck_at = now_s
    while now_s < stuck_at + PARAMS.stuck_timeout_s + 1.0:  # then no motion at all
        output = planner.step(now_s, VehicleState(now_s, position, velocity, 0.0), velocity, world)
        states.append((round(now_s - stuck_at, 1), output.state))
        if output.state is PlannerState.REWINDING:
            break
        now_s += 0.1
    assert all(s is PlannerState.TRACKING for _, s in states[:-1])
    waited, state = states[-1]
    assert state is PlannerState.REWINDING
    assert PARAMS.stuck_timeout_s - 0.5 <= waited <= PARAMS.stuck_timeout_s + 0.2
    back = output.reference.positions_ned_m
    np.testing.assert_allclose(back[0], position)
    assert back[-1][0] == pytest.approx(position[0] - PARAMS.rewind_distance_m, abs=0.5)
    np.testing.assert_allclose(back[:, 1], START[1])
    # everything seen free: the first rewind climbs `rewind_climb_m` along its length, the
    # nose kept towards the goal
    climb = START[2] - back[:, 2]
    assert climb[0] == 0.0 and climb[-1] == pytest.approx(PARAMS.rewind_climb_m)
    assert np.all(np.diff(climb) >= 0.0)
    assert output.reference.yaw_target_rad == pytest.approx(0.0)


def _rewinds(world: SyntheticOccupancyMap, count: int = 1) -> list[np.ndarray]:
    """The paths of the first `count` rewinds of a vehicle that flew 6 s north at 1 m/s and
    then stopped for good (each rewind starts from there: the vehicle does not follow)."""
    planner = LocalPlanner(PARAMS, LIBRARY)
    planner.set_goal(GOAL, 0.0)
    position, velocity, now_s = START.copy(), np.array([1.0, 0.0, 0.0]), 0.0
    for _ in range(60):
        planner.step(now_s, VehicleState(now_s, position, velocity, 0.0), velocity, world)
        position, now_s = position + 0.1 * velocity, now_s + 0.1
    paths: list[np.ndarray] = []
    previous = None
    while len(paths) < count and now_s < 100.0:
        output = planner.step(now_s, VehicleState(now_s, position, velocity, 0.0), velocity, world)
        if output.state is PlannerState.REWINDING and previous is not PlannerState.REWINDING:
            paths.append(output.reference.positions_ned_m)
        previous = output.state
        now_s += 0.1
    return paths


def test_a_rewind_changes_height_only_through_space_seen_free() -> None:
    """Up first, down on the second rewind; the other way where the map holds something
    (or has not seen) along the ramp; level where both ways are blocked."""
    climb = PARAMS.rewind_climb_m
    up, down = _rewinds(SyntheticOccupancyMap(omniscient=True), 2)
    assert START[2] - up[-1, 2] == pytest.approx(climb)
    assert START[2] - down[-1, 2] == pytest.approx(-climb)
    # a deck 0.9 m over the flown path, from 1 m to 3 m north (the ramp's end)
    deck = Box(np.array([1.0, -5.0, START[2] - 2.0]), np.array([3.0, 5.0, START[2] - 0.9]))
    (below,) = _rewinds(SyntheticOccupancyMap(boxes=[deck], omniscient=True))
    assert START[2] - below[-1, 2] == pytest.approx(-climb)
    floor = Box(np.array([1.0, -5.0, START[2] + 0.9]), np.array([3.0, 5.0, START[2] + 2.0]))
    (level,) = _rewinds(SyntheticOccupancyMap(boxes=[deck, floor], omniscient=True))
    np.testing.assert_allclose(level[:, 2], START[2])
    # nothing seen: the flown path itself
    (blind,) = _rewinds(SyntheticOccupancyMap())
    np.testing.assert_allclose(blind[:, 2], START[2])


def test_a_brake_for_a_wire_just_mapped_leaves_a_descent_that_would_run_into_it() -> None:
    """The path being flown was checked before the wire was in the map (stereo places a thin
    wire about 2 m ahead): braking along it would carry the vehicle down into the wire, so it
    brakes along the level stop trajectory, which stays clear of it."""
    planner = LocalPlanner(PARAMS, LIBRARY)
    goal = np.array([15.0, 0.0, -1.0])  # ahead and 2 m below: the planner descends
    planner.set_goal(goal, 0.0)
    world = SyntheticOccupancyMap(omniscient=True)
    velocity = np.array([1.6, 0.0, 0.0])
    descent = planner.step(0.0, VehicleState(0.0, START, velocity, 0.0), velocity, world)
    assert descent.state is PlannerState.TRACKING and descent.label == "descend-1"
    position, velocity = sample_reference(descent.reference, 0.5)
    assert velocity[2] > 0.3  # going down
    # now mapped: a wire 1 m ahead, 0.6 m below, and a dead end beyond it (nothing is free)
    wire = wire_across(position[0] + 1.0, -position[2] - 0.6)
    world.wires, world.boxes = [wire], box_canyon(-5.0, position[0] + 4.5, 1.5, 4.5)
    held = planner.step(0.5, VehicleState(0.5, position, velocity, 0.0), velocity, world)
    assert held.state is PlannerState.BRAKING and held.reference.brake
    stop = held.reference.positions_ned_m
    np.testing.assert_allclose(stop[:, 2], position[2], atol=1e-6)  # level
    assert wire.distance_m(stop).min() > world.inflation_m
    # the descent it replaced: within the inflated wire (0.32 m from it)
    along = descent.reference.positions_ned_m
    ahead = along[(along[:, 0] > position[0]) & (along[:, 0] < stop[-1, 0] + 0.5)]
    assert wire.distance_m(ahead).min() < world.inflation_m


def test_a_hold_mid_turn_brakes_along_the_turn_that_was_checked_free() -> None:
    """The stop follows the chosen trajectory's path (checked free, its braking distance
    included), not a straight line along the velocity into unchecked space."""
    planner = LocalPlanner(PARAMS, LIBRARY)
    planner.set_goal(np.array([6.0, 12.0, -3.0]), 0.0)  # far to the right of the nose
    world = SyntheticOccupancyMap(omniscient=True)
    velocity = np.array([2.0, 0.0, 0.0])
    turning = planner.step(0.0, VehicleState(0.0, START, velocity, 0.0), velocity, world)
    assert turning.state is PlannerState.TRACKING and turning.label.startswith("right")
    position, velocity = sample_reference(turning.reference, 0.1)
    held = planner.stop(0.1, VehicleState(0.1, position, velocity, 0.0), velocity)
    stop = held.reference
    assert held.state is PlannerState.BRAKING and stop.brake
    # on the turn: every point of the stop within a few cm of the turn's own path
    turn = turning.reference.positions_ned_m
    dense = np.concatenate([np.linspace(a, b, 20) for a, b in itertools.pairwise(turn)])
    gaps = np.min(np.linalg.norm(stop.positions_ned_m[:, None] - dense[None], axis=-1), axis=1)
    assert gaps.max() < 0.05
    # and it curves: its end is off the straight line along the velocity it started with
    offset = stop.positions_ned_m[-1] - stop.positions_ned_m[0]
    along = velocity / np.linalg.norm(velocity)
    assert np.linalg.norm(offset - (offset @ along) * along) > 0.05
    # stopped at max deceleration: v^2 / 2a along the path, ending at rest
    length = np.sum(np.linalg.norm(np.diff(stop.positions_ned_m, axis=0), axis=1))
    speed = float(np.linalg.norm(velocity))
    assert length == pytest.approx(speed**2 / (2 * PARAMS.max_accel_mps2), rel=0.05)
    np.testing.assert_allclose(stop.velocities_ned_mps[-1], 0.0)
