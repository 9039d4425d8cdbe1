"""The mission state machine (`companion.mission`): every transition, failsafe and command."""

from __future__ import annotations

import numpy as np
import pytest

from companion.mission import (
    FailsafeCause,
    Mission,
    MissionParams,
    MissionState,
    Operation,
    OperationResult,
    StageHealth,
    VehicleStatus,
)
from planning.types import PlannerState

GOALS = [(10.0, 0.0, -3.0), (10.0, 5.0, -3.0)]
HEALTHY = StageHealth(perception_fresh=True, planner_fresh=True)


def status(**overrides) -> VehicleStatus:
    values = dict(link_ok=True, armed=True, in_air=True, offboard=True, position_ned_m=np.zeros(3))
    values.update(overrides)
    return VehicleStatus(**values)


class Flight:
    """Steps a mission at 10 Hz, answering its operations as the flight process would."""

    def __init__(self, **params) -> None:
        defaults = dict(auto_start=True, goals_ned_m=GOALS)
        defaults.update(params)
        self.mission = Mission(MissionParams(**defaults))
        self.t = 0.0
        self.result: OperationResult | None = None
        self.events = []

    def step(self, vehicle=None, health=HEALTHY, planner=None, ok=True, detail=""):
        self.t += 0.1
        decision = self.mission.step(self.t, vehicle or status(), health, planner, self.result)
        self.result = None
        if decision.operation is not None:
            self.result = OperationResult(decision.operation, ok, detail)
        self.events.extend(decision.events)
        return decision

    def airborne(self):
        """Arm, take off and enter offboard; returns the first NAVIGATE decision."""
        grounded = status(armed=False, in_air=False, offboard=False)
        assert self.step(grounded).operation is Operation.ARM
        assert self.step(grounded).operation is Operation.TAKEOFF
        decision = self.step(status(offboard=False))
        assert decision.state is MissionState.NAVIGATE
        assert decision.operation is Operation.OFFBOARD
        return self.step(status(), planner=PlannerState.TRACKING)


def test_auto_start_arms_takes_off_and_flies_the_goals_in_order_then_lands() -> None:
    flight = Flight()
    decision = flight.airborne()
    assert decision.state is MissionState.NAVIGATE and not decision.hold
    np.testing.assert_array_equal(decision.goal_ned_m, GOALS[0])
    decision = flight.step(planner=PlannerState.ARRIVED)
    assert decision.goal_index == 1
    np.testing.assert_array_equal(decision.goal_ned_m, GOALS[1])
    decision = flight.step(planner=PlannerState.ARRIVED)
    assert decision.state is MissionState.LANDING and decision.operation is Operation.LAND
    decision = flight.step(status(armed=False, in_air=False, offboard=False))
    assert decision.state is MissionState.LANDED
    texts = [e.text for e in flight.events]
    assert texts[:3] == ["arming", "taking off to 3.0 m", "to goal 0"]
    assert "goal 1 reached" in texts and texts[-1] == "landed and disarmed"


def test_without_auto_start_it_waits_for_a_command() -> None:
    flight = Flight(auto_start=False)
    for _ in range(5):
        assert flight.step(status(armed=False)).state is MissionState.IDLE
    assert flight.mission.goto([np.array(GOALS[0])]).accepted
    assert flight.step(status(armed=False)).operation is Operation.ARM


def test_end_action_hold_holds_at_the_last_goal() -> None:
    flight = Flight(end_action="hold", goals_ned_m=GOALS[:1])
    flight.airborne()
    decision = flight.step(planner=PlannerState.ARRIVED)
    assert decision.state is MissionState.HOLD and decision.hold
    assert decision.operation is None


def test_the_planner_state_maps_to_avoid_and_recovery() -> None:
    flight = Flight()
    flight.airborne()
    assert flight.step(planner=PlannerState.BRAKING).state is MissionState.AVOID
    assert flight.step(planner=PlannerState.GOAL_BLOCKED).state is MissionState.AVOID
    assert flight.step(planner=PlannerState.RECOVERING).state is MissionState.RECOVERY
    assert flight.step(planner=PlannerState.REWINDING).state is MissionState.RECOVERY
    assert flight.step(planner=PlannerState.TRACKING).state is MissionState.NAVIGATE
    decision = flight.step(planner=PlannerState.UNREACHABLE)
    assert decision.state is MissionState.HOLD and decision.hold
    assert any(e.warning and "unreachable" in e.text for e in flight.events)


def test_arming_and_takeoff_failures() -> None:
    flight = Flight()
    grounded = status(armed=False, in_air=False, offboard=False)
    flight.step(grounded)  # ARM started
    assert flight.step(grounded, ok=False).state is MissionState.TAKEOFF  # ARM succeeded
    decision = flight.step(grounded)  # TAKEOFF reported failed
    assert decision.state is MissionState.LANDING and decision.operation is Operation.LAND

    denied = Flight()
    denied.step(grounded, ok=False, detail="system not ready")
    decision = denied.step(grounded)
    assert decision.state is MissionState.IDLE
    assert any("arming failed: system not ready" in e.text for e in denied.events)


def test_offboard_is_retried_then_held_in_px4_hold() -> None:
    flight = Flight(offboard_attempts=2)
    grounded = status(armed=False, in_air=False, offboard=False)
    flight.step(grounded)
    flight.step(grounded)
    flight.step(status(offboard=False), ok=False)  # takeoff ok -> OFFBOARD, which fails
    operations = [flight.step(status(offboard=False), ok=False).operation for _ in range(4)]
    assert operations.count(Operation.OFFBOARD) == 1  # the retry
    assert Operation.HOLD in operations
    assert flight.mission.state is MissionState.HOLD


def test_stale_perception_brakes_and_holds_then_resumes_when_fresh_again() -> None:
    flight = Flight(stale_resume_s=1.0)
    flight.airborne()
    stale = StageHealth(perception_fresh=False, planner_fresh=True)
    decision = flight.step(health=stale, planner=PlannerState.TRACKING)
    assert decision.state is MissionState.FAILSAFE and decision.hold
    assert decision.cause is FailsafeCause.PERCEPTION_STALE
    for _ in range(5):  # fresh again, but not yet for stale_resume_s
        assert flight.step(planner=PlannerState.BRAKING).state is MissionState.FAILSAFE
    for _ in range(10):
        decision = flight.step(planner=PlannerState.BRAKING)
    assert decision.state in (MissionState.NAVIGATE, MissionState.AVOID)
    assert not decision.hold and decision.cause is None


def test_perception_stale_too_long_lands() -> None:
    flight = Flight(stale_land_s=2.0)
    flight.airborne()
    stale = StageHealth(perception_fresh=False, planner_fresh=True)
    states = [flight.step(health=stale).state for _ in range(30)]
    assert MissionState.FAILSAFE in states and states[-1] is MissionState.LANDING


def test_a_stalled_planner_is_a_failsafe_and_offboard_is_reentered_after() -> None:
    flight = Flight(stale_resume_s=0.5)
    flight.airborne()
    stalled = StageHealth(perception_fresh=True, planner_fresh=False)
    decision = flight.step(health=stalled)
    assert decision.cause is FailsafeCause.PLANNER_STALE
    # the link's watchdog left offboard for PX4's Hold meanwhile
    for _ in range(10):
        decision = flight.step(status(offboard=False))
    assert decision.state is MissionState.NAVIGATE
    assert decision.operation is Operation.OFFBOARD or flight.result is not None


def test_vehicle_link_loss_then_hold_for_the_operator() -> None:
    flight = Flight()
    flight.airborne()
    decision = flight.step(status(link_ok=False))
    assert decision.state is MissionState.FAILSAFE
    assert decision.cause is FailsafeCause.VEHICLE_LINK_LOST
    decision = flight.step(status())
    assert decision.state is MissionState.HOLD and decision.hold


@pytest.mark.parametrize(
    ("action", "state"), [("land", MissionState.LANDING), ("rtl", MissionState.LANDING)]
)
def test_low_battery_ends_the_mission(action: str, state: MissionState) -> None:
    flight = Flight(battery_action=action)
    flight.airborne()
    decision = flight.step(status(battery_frac=0.1))
    assert decision.state is state
    assert decision.operation is (Operation.LAND if action == "land" else Operation.RTL)


def test_ground_link_loss_does_what_is_configured() -> None:
    lost = StageHealth(perception_fresh=True, planner_fresh=True, ground_link_ok=False)
    keep = Flight()
    keep.airborne()
    assert keep.step(health=lost, planner=PlannerState.TRACKING).state is MissionState.NAVIGATE
    hold = Flight(ground_lost_action="hold")
    hold.airborne()
    assert hold.step(health=lost).cause is FailsafeCause.GROUND_LINK_LOST
    land = Flight(ground_lost_action="land")
    land.airborne()
    assert land.step(health=lost).operation is Operation.LAND


def test_geofence_breach_holds_and_a_goto_inside_resumes() -> None:
    flight = Flight()
    flight.airborne()
    outside = StageHealth(perception_fresh=True, planner_fresh=True, inside_geofence=False)
    assert flight.step(health=outside).cause is FailsafeCause.GEOFENCE
    assert flight.mission.goto([np.zeros(3)]).accepted
    assert flight.step().state is MissionState.NAVIGATE


def test_operator_commands_and_their_refusals() -> None:
    flight = Flight(auto_start=False)
    m = flight.mission
    assert not m.hold().accepted and "idle" in m.hold().reason
    assert not m.resume().accepted
    assert not m.land().accepted
    assert not m.goto([]).accepted
    assert not m.goto([np.zeros(3)], speed_mps=float("nan")).accepted
    assert not m.set_speed(40.0).accepted and m.set_speed(3.0).accepted
    assert m.takeoff(5.0).accepted and m.takeoff_altitude_m == 5.0
    flight.step(status(armed=False))  # ARM
    assert not m.goto([np.zeros(3)]).accepted  # not while arming
    flight.step(status(armed=False))
    flight.step(status(offboard=False))  # takeoff done, no goals: hold
    assert m.state is MissionState.HOLD
    assert not m.resume().accepted  # no goal to resume to
    assert m.goto([np.array(GOALS[0])]).accepted and m.state is MissionState.NAVIGATE
    assert m.hold().accepted and flight.step().hold
    assert m.resume().accepted and not flight.step(planner=PlannerState.TRACKING).hold
    assert m.abort().accepted
    decision = flight.step()
    assert decision.state is MissionState.HOLD and decision.hold
    assert m.land().accepted and flight.step().operation is Operation.LAND
    assert not m.goto([np.zeros(3)]).accepted  # not while landing


def test_goto_is_refused_while_flying_blind() -> None:
    flight = Flight()
    flight.airborne()
    flight.step(health=StageHealth(perception_fresh=False, planner_fresh=True))
    verdict = flight.mission.goto([np.zeros(3)])
    assert not verdict.accepted and "blind" in verdict.reason
    assert flight.mission.state is MissionState.FAILSAFE
