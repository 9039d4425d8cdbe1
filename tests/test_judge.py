"""The flight judge (hil.judge): clearances and collisions on the world's true geometry."""

import numpy as np
import pytest

from geometry.shapes import Box, Wire
from hil.judge import FlightJudge, clearance_m, contact_episodes, ground_clearance_m, plot_flight
from hil.world.model import Solid, World

BOX = Solid(Box([10.0, -5.0, -4.0], [12.0, -3.0, 0.0]))
WIRE = Wire.straight([20.0, -10.0, -3.0], [20.0, 10.0, -3.0], radius_m=0.01)
WORLD = World(solids=[BOX], wires=[WIRE], goals_ned_m=[[15.0, 5.0, -3.0], [30.0, 0.0, -3.0]])


def test_clearances_match_hand_computed_distances() -> None:
    points = np.array(
        [
            [8.0, -4.0, -2.0],  # 2 m before the box face
            [11.0, -4.0, -2.0],  # inside, 1 m from the nearest faces
            [13.0, -2.0, -6.0],  # off a corner: (1, 1, 2)
            [20.0, 0.0, -5.0],  # 2 m above the wire (it is 3 m up, this 5 m)
            [23.0, 4.0, -7.0],  # (3, 0, 4) from the wire's axis
        ]
    )
    obstacle, wire = clearance_m(WORLD, points)
    np.testing.assert_allclose(obstacle[:3], [2.0, -1.0, np.sqrt(6.0)])
    np.testing.assert_allclose(wire[3:], [2.0 - 0.01, 5.0 - 0.01])
    assert wire[0] == pytest.approx(np.hypot(12.0, 1.0) - 0.01)
    np.testing.assert_allclose(ground_clearance_m(WORLD, points), [2, 2, 6, 5, 7])
    nothing = clearance_m(World(), points)
    assert np.isinf(nothing[0]).all() and np.isinf(nothing[1]).all()


def test_contact_episodes_count_distinct_entries_with_hysteresis() -> None:
    d = np.array([1.0, 0.4, 0.45, 0.52, 0.4, 0.6, 0.4, 1.0])
    # 0.52 is above the radius but inside the 5 cm release band: still the first episode
    assert contact_episodes(d < 0.5, d >= 0.55) == 2


def straight(judge: FlightJudge, start, end, speed_mps=2.0, t0_s=0.0, on_ground=False) -> float:
    start, end = np.asarray(start, float), np.asarray(end, float)
    duration = np.linalg.norm(end - start) / speed_mps
    for t in np.arange(0.0, duration, 0.5):  # 1 m apart: the judge densifies
        judge.add(t0_s + t, start + (end - start) * t / duration, on_ground)
    judge.add(t0_s + duration, end, on_ground)
    return t0_s + duration


def test_a_flight_through_the_wire_is_one_collision_and_goals_count_in_order() -> None:
    judge = FlightJudge(WORLD, vehicle_radius_m=0.5, goal_radius_m=1.0)
    t = straight(judge, [0, 0, 0], [0, 0, -3], on_ground=True)  # take-off: ground ok
    t = straight(judge, [0, 0, -3], [15, 5, -3], t0_s=t)  # misses the box, reaches goal 1
    t = straight(judge, [15, 5, -3], [30, 0, -3], t0_s=t)  # through the wire to goal 2
    verdict = judge.verdict()
    assert verdict.collisions == 1 and verdict.wire_collisions == 1
    assert verdict.obstacle_collisions == 0 and verdict.ground_collisions == 0
    assert verdict.min_wire_clearance_m < 0.03  # the path crossed the wire (5 cm steps)
    assert verdict.goals_reached == (True, True) and not verdict.success
    assert verdict.goal_times_s[0] < verdict.goal_times_s[1]
    expected = 3.0 + np.hypot(15, 5) + np.hypot(15, 5)
    assert verdict.path_length_m == pytest.approx(expected)
    assert verdict.duration_s == pytest.approx(t)


def test_near_misses_ground_contact_and_unreached_goals() -> None:
    judge = FlightJudge(WORLD, vehicle_radius_m=0.5, goal_radius_m=1.0)
    t = straight(judge, [0, 0, -3], [20, 0, -3.6])  # passes 0.6 m over the wire
    verdict = judge.verdict()
    assert verdict.collisions == 0
    assert verdict.min_wire_clearance_m == pytest.approx(0.6 - 0.01, abs=0.01)
    assert verdict.goals_reached == (False, False)  # goal 2 never, goal 1 not passed
    # the box: the flight skims its top 0.3 m above it -> one obstacle collision
    straight(judge, [20, 0, -3.6], [10.5, -4, -4.3], t0_s=t)
    assert judge.verdict().obstacle_collisions == 1
    # the ground counts while airborne, not while landed
    low = FlightJudge(WORLD, 0.5, 1.0)
    straight(low, [0, -5, -0.2], [5, -5, -0.2])
    assert low.verdict().ground_collisions == 1
    landed = FlightJudge(WORLD, 0.5, 1.0)
    straight(landed, [0, -5, -0.2], [5, -5, -0.2], on_ground=True)
    assert landed.verdict().collisions == 0


def test_goals_must_be_reached_in_order() -> None:
    judge = FlightJudge(WORLD, 0.5, 1.0)
    straight(judge, [30, 3, -3], [30, 0, -3])  # the second goal first
    assert judge.verdict().goals_reached == (False, False)


def test_plot_flight_writes_a_png_with_both_views(tmp_path) -> None:
    import matplotlib.image

    judge = FlightJudge(WORLD, 0.5, 1.0)
    straight(judge, [0, 0, -3], [30, 0, -5])
    out = plot_flight(WORLD, judge.path_ned_m, tmp_path / "flight.png", WORLD.goals_ned_m)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    image = matplotlib.image.imread(out)
    assert image.shape[1] > 1.8 * image.shape[0]  # two views side by side
