"""Path tracking: smooth setpoints across replans, hold at the end, yaw policies."""

import numpy as np
import pytest
from kinematic import flown_velocity

from geometry.rotation import wrap_angle_rad
from planning.params import PlanningParams, SetpointMode, YawPolicy
from planning.synthetic_occupancy import SyntheticOccupancyMap, wall
from planning.tracker import PathTracker, sample_reference
from planning.types import Reference, SetpointKind, VehicleState

PARAMS = PlanningParams()
DT_S = 1.0 / PARAMS.setpoint_rate_hz
MAX_STEP_MPS = PARAMS.setpoint_accel_slack * PARAMS.max_accel_mps2 * DT_S


def straight(start_s: float, origin, velocity, plan_id: int, duration_s: float = 4.0):
    times = np.linspace(0.0, duration_s, 21)
    velocity = np.asarray(velocity, float)
    positions = np.asarray(origin, float) + times[:, None] * velocity
    return Reference(start_s, times, positions, np.tile(velocity, (21, 1)), plan_id)


def run(tracker: PathTracker, references, seconds: float, goal=None, start_yaw: float = 0.0):
    """Kinematic vehicle flying the setpoints; `references(t)` gives the current reference."""
    position, velocity, yaw = np.zeros(3), np.zeros(3), start_yaw
    setpoints = []
    for i in range(round(seconds / DT_S)):
        now_s = i * DT_S
        setpoint = tracker.setpoint(
            now_s, VehicleState(now_s, position, velocity, yaw), references(now_s), goal
        )
        setpoints.append(setpoint)
        velocity = flown_velocity(setpoint, position)
        position = position + DT_S * velocity
        yaw = setpoint.yaw_rad
    return setpoints


def test_sample_reference_interpolates_and_clamps() -> None:
    reference = straight(0.0, [0, 0, 0], [2.0, 0, 0], 1)
    position, velocity = sample_reference(reference, 1.1)
    np.testing.assert_allclose(position, [2.2, 0, 0])
    np.testing.assert_allclose(velocity, [2.0, 0, 0])
    position, _ = sample_reference(reference, 9.0)
    np.testing.assert_allclose(position, [8.0, 0, 0])
    assert wrap_angle_rad(3 * np.pi / 2) == pytest.approx(-np.pi / 2)


@pytest.mark.parametrize("mode", list(SetpointMode))
def test_replanning_to_a_very_different_trajectory_does_not_jump_the_setpoint(
    mode: SetpointMode,
) -> None:
    tracker = PathTracker(PARAMS.model_copy(update={"setpoint_mode": mode}))
    north = straight(0.0, [0, 0, 0], [2.0, 0, 0], 1)

    def references(now_s: float) -> Reference:
        if now_s < 2.0:
            return north
        # every 0.1 s a new plan, alternating hard left and hard right
        k = int((now_s - 2.0) * 10)
        sideways = [0.0, -2.0 if k % 2 else 2.0, -0.5]
        return straight(2.0 + 0.1 * k, [4.0, 0, 0], sideways, 2 + k)

    setpoints = run(tracker, references, 4.0)
    velocities = np.array([s.velocity_ned_mps for s in setpoints])
    steps = np.linalg.norm(np.diff(velocities, axis=0), axis=1)
    assert steps.max() <= MAX_STEP_MPS + 1e-9
    before = velocities[round(2.0 / DT_S) - 1]
    assert np.linalg.norm(before - [2.0, 0, 0]) < 0.3  # tracking the first plan (+ catch-up)
    assert steps[round(2.0 / DT_S) - 1] <= MAX_STEP_MPS + 1e-9  # the switch itself is smooth
    kind = SetpointKind(mode.value)
    assert all(s.kind is kind and s.valid for s in setpoints)
    if mode is SetpointMode.TRAJECTORY:  # the position sent moves no faster than the plans
        positions = np.array([s.position_ned_m for s in setpoints])
        jumps = np.linalg.norm(np.diff(positions, axis=0), axis=1)
        assert jumps.max() < 3.0 * DT_S


def test_setpoints_stay_smooth_through_the_replans_of_a_planned_flight() -> None:
    from test_planning_scenarios import fly

    flight = fly(SyntheticOccupancyMap(boxes=[wall(8.0, 1.5, 15.0)]))
    plans = {s.reference.plan_id for s in flight.outputs}
    labels = {s.label for s in flight.outputs}
    assert len(plans) > 50 and len(labels) > 3  # the choice changed many times
    moving = [s for s in flight.setpoints if s.kind is not SetpointKind.POSITION]
    stamps = np.array([s.stamp_s for s in moving])
    velocities = np.array([s.velocity_ned_mps for s in moving])
    consecutive = np.isclose(np.diff(stamps), DT_S)
    steps = np.linalg.norm(np.diff(velocities, axis=0), axis=1)[consecutive]
    assert steps.max() <= MAX_STEP_MPS + 1e-9
    yaws = np.array([s.yaw_rad for s in flight.setpoints])
    yaw_steps = np.abs(wrap_angle_rad(np.diff(yaws)))
    assert yaw_steps.max() <= PARAMS.max_yaw_rate_radps * DT_S + 1e-9


def test_the_end_of_a_reference_becomes_a_position_hold() -> None:
    tracker = PathTracker(PARAMS)
    reference = straight(0.0, [0, 0, 0], [1.0, 0, 0], 1, duration_s=2.0)
    setpoints = run(tracker, lambda now_s: reference, 5.0)
    last = setpoints[-1]
    assert last.kind is SetpointKind.POSITION
    np.testing.assert_allclose(last.position_ned_m, [2.0, 0, 0])
    np.testing.assert_allclose(last.velocity_ned_mps, 0.0)
    # it slows down before the end rather than overshooting it
    speeds = [np.linalg.norm(s.velocity_ned_mps) for s in setpoints if s.stamp_s < 2.0]
    assert speeds[-1] < 0.9


def test_without_a_plan_the_tracker_brakes_and_marks_the_setpoint_invalid() -> None:
    tracker = PathTracker(PARAMS)
    vehicle = VehicleState(0.0, np.zeros(3), np.array([2.0, 0, 0]), 0.0)
    first = tracker.setpoint(0.0, vehicle, None)
    second = tracker.setpoint(DT_S, vehicle, None)
    assert first.kind is SetpointKind.BRAKE and not first.valid
    assert np.linalg.norm(first.velocity_ned_mps) == pytest.approx(2.0)  # no jump to zero
    assert np.linalg.norm(second.velocity_ned_mps) == pytest.approx(2.0 - MAX_STEP_MPS)


@pytest.mark.parametrize(
    ("policy", "expected_yaw"),
    [(YawPolicy.MOTION, np.pi / 2), (YawPolicy.GOAL, -np.pi / 4), (YawPolicy.FIXED, 1.0)],
)
def test_yaw_policies(policy: YawPolicy, expected_yaw: float) -> None:
    params = PARAMS.model_copy(update={"yaw_policy": policy, "fixed_yaw_rad": 1.0})
    tracker = PathTracker(params)
    east = straight(0.0, [0, 0, 0], [0.0, 1.5, 0], 1, duration_s=10.0)
    goal = np.array([5000.0, -5000.0, 0.0])  # north-west, far
    setpoints = run(tracker, lambda now_s: east, 5.0, goal=goal)
    yaws = np.array([s.yaw_rad for s in setpoints])
    assert yaws[-1] == pytest.approx(expected_yaw, abs=0.05)
    # turned at no more than the yaw-rate limit
    assert np.abs(wrap_angle_rad(np.diff(yaws))).max() <= params.max_yaw_rate_radps * DT_S + 1e-9
    assert np.abs(wrap_angle_rad(np.diff(yaws))).max() > 0.5 * params.max_yaw_rate_radps * DT_S


def test_rotate_in_place_and_align_commands_override_the_policy() -> None:
    params = PARAMS.model_copy(update={"yaw_policy": YawPolicy.FIXED})
    hold = np.zeros((1, 3))
    rotate = Reference(0.0, np.zeros(1), hold, hold, 1, yaw_rate_radps=0.6)
    setpoints = run(PathTracker(params), lambda now_s: rotate, 2.0)
    assert setpoints[-1].yaw_rate_radps == pytest.approx(0.6)
    assert setpoints[-1].yaw_rad == pytest.approx(0.6 * (len(setpoints) - 1) * DT_S)
    assert setpoints[-1].kind is SetpointKind.POSITION
    align = Reference(0.0, np.zeros(1), hold, hold, 2, yaw_target_rad=-2.0)
    setpoints = run(PathTracker(params), lambda now_s: align, 4.0)
    assert setpoints[-1].yaw_rad == pytest.approx(-2.0, abs=1e-9)
