"""PX4 commander/navigator semantics of the SIL vehicle, in lockstep without sockets."""

from __future__ import annotations

import numpy as np
import pytest

from hil.vehicle.params import VehicleSimParams
from hil.vehicle.px4_controller import TrajectorySetpoint
from hil.vehicle.px4_modes import CommandResult, MavLandedState, Px4Mode, Px4Vehicle

DT_S = 0.02
VELOCITY_NORTH = TrajectorySetpoint(velocity_ned_mps=np.array([1.0, 0.0, 0.0]), yaw_rad=0.0)


def run_until(vehicle: Px4Vehicle, predicate, timeout_s: float, feed=None) -> float:
    """Step until predicate(vehicle); returns the simulated time it became true."""
    deadline = vehicle.time_s + timeout_s
    while vehicle.time_s < deadline:
        if feed is not None:
            feed(vehicle)
        vehicle.step(DT_S)
        if predicate(vehicle):
            return vehicle.time_s
    raise AssertionError(f"not reached in {timeout_s} s: mode {vehicle.mode}, t {vehicle.time_s}")


def hovering(params: VehicleSimParams | None = None) -> Px4Vehicle:
    """A vehicle armed, taken off and in Hold."""
    vehicle = Px4Vehicle(params or VehicleSimParams(arm_denied_after_boot_s=0.0))
    vehicle.step(vehicle.params.health_ok_after_boot_s + 0.1)
    assert vehicle.arm() is CommandResult.ACCEPTED
    assert vehicle.takeoff() is CommandResult.ACCEPTED
    run_until(vehicle, lambda v: v.mode is Px4Mode.HOLD, 10.0)
    return vehicle


def in_offboard(params: VehicleSimParams | None = None) -> Px4Vehicle:
    vehicle = hovering(params)
    vehicle.offboard_setpoint(VELOCITY_NORTH)
    assert vehicle.request_mode(Px4Mode.OFFBOARD) is CommandResult.ACCEPTED
    return vehicle


def test_arming_denied_after_boot_then_allowed() -> None:
    params = VehicleSimParams(health_ok_after_boot_s=1.0, arm_denied_after_boot_s=3.0)
    vehicle = Px4Vehicle(params)
    assert vehicle.arm() is CommandResult.TEMPORARILY_REJECTED  # not healthy yet
    vehicle.step(1.5)
    assert vehicle.healthy
    assert vehicle.arm() is CommandResult.TEMPORARILY_REJECTED  # healthy but too early
    assert not vehicle.armed
    vehicle.step(1.6)
    assert vehicle.arm() is CommandResult.ACCEPTED
    assert vehicle.armed
    texts = [t.text for t in vehicle.status_texts]
    assert any("Arming denied" in t for t in texts)


def test_force_arm_skips_checks() -> None:
    vehicle = Px4Vehicle(VehicleSimParams())
    assert vehicle.arm(force=True) is CommandResult.ACCEPTED


def test_takeoff_climbs_to_mis_takeoff_alt_then_holds() -> None:
    params = VehicleSimParams(arm_denied_after_boot_s=0.0, takeoff_alt_m=5.0)
    vehicle = Px4Vehicle(params)
    vehicle.step(1.1)
    assert vehicle.landed_state is MavLandedState.ON_GROUND
    vehicle.arm()
    vehicle.takeoff()
    vehicle.step(1.0)  # spool-up (COM_SPOOLUP_TIME): still on the ground
    assert vehicle.landed_state is MavLandedState.ON_GROUND
    vehicle.step(1.5)  # the takeoff ramp raised the thrust: no longer landed
    assert vehicle.landed_state is MavLandedState.TAKEOFF
    climb_rates = []
    run_until(
        vehicle,
        lambda v: v.mode is Px4Mode.HOLD,
        15.0,
        feed=lambda v: climb_rates.append(-v.truth.velocity_ned_mps[2]),
    )
    assert max(climb_rates) <= params.takeoff_speed_mps * 1.15
    # done within NAV_MC_ALT_RAD of the target; Hold then climbs the rest smoothly
    assert vehicle.truth.position_ned_m[2] <= -5.0 + params.nav_mc_alt_rad_m
    vehicle.step(6.0)
    assert vehicle.landed_state is MavLandedState.IN_AIR
    np.testing.assert_allclose(vehicle.truth.position_ned_m, [0.0, 0.0, -5.0], atol=0.1)


def test_takeoff_altitude_param7_is_amsl() -> None:
    params = VehicleSimParams(arm_denied_after_boot_s=0.0, home_alt_amsl_m=100.0)
    vehicle = Px4Vehicle(params)
    vehicle.step(1.1)
    vehicle.arm()
    assert vehicle.takeoff(103.0) is CommandResult.ACCEPTED
    run_until(vehicle, lambda v: v.mode is Px4Mode.HOLD, 15.0)
    vehicle.step(6.0)
    assert vehicle.truth.position_ned_m[2] == pytest.approx(-3.0, abs=0.1)


def test_land_then_auto_disarm_after_com_disarm_land() -> None:
    vehicle = hovering()
    assert vehicle.land() is CommandResult.ACCEPTED
    touchdown = run_until(vehicle, lambda v: v.truth.on_ground, 20.0)
    # PX4's land detector needs the crawl's integrator to wind the thrust down first:
    # seconds after touchdown (2.8-7.6 s in PX4 SITL), never at once
    landed = run_until(vehicle, lambda v: v.landed, 15.0)
    assert 1.0 < landed - touchdown < 10.0
    disarmed = run_until(vehicle, lambda v: not v.armed, 5.0)
    assert disarmed - landed == pytest.approx(vehicle.params.disarm_land_s, abs=0.05)
    assert vehicle.landed_state is MavLandedState.ON_GROUND
    assert vehicle.truth.position_ned_m[2] == 0.0
    names = [e.name for e in vehicle.events]
    assert names.index("commander_landing_detected") < names.index("commander_disarmed_by")
    assert vehicle.mode is Px4Mode.HOLD  # the mode before Land, as PX4 reports it


def test_preflight_auto_disarm() -> None:
    vehicle = Px4Vehicle(VehicleSimParams(arm_denied_after_boot_s=0.0, disarm_preflight_s=4.0))
    vehicle.step(1.1)
    vehicle.arm()
    armed_at = vehicle.time_s
    disarmed = run_until(vehicle, lambda v: not v.armed, 10.0)
    assert disarmed - armed_at == pytest.approx(4.0, abs=0.05)


def test_disarm_in_air_denied_unless_forced() -> None:
    vehicle = hovering()
    assert vehicle.disarm() is CommandResult.DENIED
    assert vehicle.armed
    assert vehicle.disarm(force=True) is CommandResult.ACCEPTED
    run_until(vehicle, lambda v: v.truth.on_ground, 10.0)  # falls, onto the ground


def test_offboard_refused_without_a_recent_setpoint() -> None:
    vehicle = hovering()
    assert vehicle.request_mode(Px4Mode.OFFBOARD) is CommandResult.TEMPORARILY_REJECTED
    assert vehicle.mode is Px4Mode.HOLD
    vehicle.offboard_setpoint(VELOCITY_NORTH)
    vehicle.step(0.6)  # older than 0.5 s
    assert vehicle.request_mode(Px4Mode.OFFBOARD) is CommandResult.TEMPORARILY_REJECTED
    vehicle.offboard_setpoint(VELOCITY_NORTH)
    vehicle.step(0.4)
    assert vehicle.request_mode(Px4Mode.OFFBOARD) is CommandResult.ACCEPTED
    assert vehicle.mode is Px4Mode.OFFBOARD


def test_offboard_follows_setpoints_then_loss_takes_com_obl_rc_act() -> None:
    vehicle = in_offboard()
    for _ in range(500):
        vehicle.offboard_setpoint(VELOCITY_NORTH)
        vehicle.step(DT_S)
    # SIH's drag against PX4's slow velocity integrator: 1 m/s is approached, not reached
    assert 0.85 < vehicle.truth.velocity_ned_mps[0] < 1.0
    last_setpoint_s = vehicle.time_s
    height_s = -vehicle.truth.position_ned_m[2]
    failsafe_s = run_until(vehicle, lambda v: v.mode is not Px4Mode.OFFBOARD, 3.0)
    assert failsafe_s - last_setpoint_s == pytest.approx(
        vehicle.params.offboard_loss_timeout_s, abs=2 * DT_S
    )
    # COM_OBL_RC_ACT 0 (Position) without RC falls back to Return, which climbs
    assert vehicle.mode is Px4Mode.RTL and vehicle.failsafe_active
    assert vehicle.intended_mode is Px4Mode.OFFBOARD
    vehicle.step(3.0)
    assert -vehicle.truth.position_ned_m[2] > height_s + 1.0
    assert "commander_failsafe_enter_generic" in [e.name for e in vehicle.events]


@pytest.mark.parametrize(
    ("action", "mode"), [(5, Px4Mode.HOLD), (4, Px4Mode.LAND), (3, Px4Mode.RTL)]
)
def test_offboard_loss_action_follows_com_obl_rc_act(action: int, mode: Px4Mode) -> None:
    vehicle = in_offboard(
        VehicleSimParams(arm_denied_after_boot_s=0.0, offboard_loss_action=action)
    )
    vehicle.offboard_setpoint(VELOCITY_NORTH)
    run_until(vehicle, lambda v: v.mode is not Px4Mode.OFFBOARD, 3.0)
    assert vehicle.mode is mode
    if mode is Px4Mode.HOLD:
        run_until(vehicle, lambda v: np.linalg.norm(v.truth.velocity_ned_mps) < 0.05, 8.0)


def test_offboard_loss_terminate_and_disarm_stop_the_motors() -> None:
    for action in (6, 7):
        params = VehicleSimParams(arm_denied_after_boot_s=0.0, offboard_loss_action=action)
        vehicle = in_offboard(params)
        run_until(vehicle, lambda v: not v.armed, 3.0)
        run_until(vehicle, lambda v: v.truth.on_ground, 10.0)


def test_companion_heartbeat_loss_is_only_a_warning() -> None:
    """PX4 main: COM_OBC_LOSS_T warns about the lost onboard computer, it takes no action."""
    params = VehicleSimParams(arm_denied_after_boot_s=0.0, companion_loss_timeout_s=2.0)
    vehicle = in_offboard(params)

    def feed(v: Px4Vehicle, with_heartbeat: bool) -> None:
        v.offboard_setpoint(VELOCITY_NORTH)
        if with_heartbeat:
            v.companion_heartbeat()

    for _ in range(100):
        feed(vehicle, True)
        vehicle.step(DT_S)
    last_heartbeat_s = vehicle.time_s
    warned = lambda v: any("onboard computer lost" in t.text for t in v.status_texts)  # noqa: E731
    lost_s = run_until(vehicle, warned, 5.0, feed=lambda v: feed(v, False))
    assert lost_s - last_heartbeat_s == pytest.approx(2.0, abs=2 * DT_S)
    for _ in range(100):
        feed(vehicle, False)
        vehicle.step(DT_S)
    assert vehicle.mode is Px4Mode.OFFBOARD and not vehicle.failsafe_active


def test_no_companion_failsafe_when_none_was_ever_seen() -> None:
    params = VehicleSimParams(arm_denied_after_boot_s=0.0, companion_loss_timeout_s=0.5)
    vehicle = in_offboard(params)
    for _ in range(150):
        vehicle.offboard_setpoint(VELOCITY_NORTH)
        vehicle.step(DT_S)
    assert vehicle.mode is Px4Mode.OFFBOARD


def race_vehicle(probability: float) -> Px4Vehicle:
    params = VehicleSimParams(
        arm_denied_after_boot_s=0.0,
        takeoff_hold_race_probability=probability,
        takeoff_hold_race_window_s=0.5,
    )
    return hovering(params)


def test_end_of_takeoff_hold_race_wins_over_offboard_while_acked() -> None:
    vehicle = race_vehicle(1.0)
    vehicle.offboard_setpoint(VELOCITY_NORTH)
    assert vehicle.request_mode(Px4Mode.OFFBOARD) is CommandResult.ACCEPTED
    for _ in range(25):
        vehicle.offboard_setpoint(VELOCITY_NORTH)
        vehicle.step(DT_S)
    assert vehicle.mode is Px4Mode.HOLD
    # a retry after the window succeeds
    vehicle.step(0.5)
    vehicle.offboard_setpoint(VELOCITY_NORTH)
    assert vehicle.request_mode(Px4Mode.OFFBOARD) is CommandResult.ACCEPTED
    for _ in range(50):
        vehicle.offboard_setpoint(VELOCITY_NORTH)
        vehicle.step(DT_S)
    assert vehicle.mode is Px4Mode.OFFBOARD


def test_no_race_when_disabled() -> None:
    vehicle = race_vehicle(0.0)
    vehicle.offboard_setpoint(VELOCITY_NORTH)
    assert vehicle.request_mode(Px4Mode.OFFBOARD) is CommandResult.ACCEPTED
    for _ in range(50):
        vehicle.offboard_setpoint(VELOCITY_NORTH)
        vehicle.step(DT_S)
    assert vehicle.mode is Px4Mode.OFFBOARD


def test_race_is_reproducible_from_the_seed() -> None:
    def outcomes(seed: int) -> list[bool]:
        params = VehicleSimParams(
            seed=seed, arm_denied_after_boot_s=0.0, takeoff_hold_race_probability=0.5
        )
        results = []
        vehicle = hovering(params)
        for _ in range(8):
            vehicle.offboard_setpoint(VELOCITY_NORTH)
            vehicle._takeoff_completed_s = vehicle.time_s  # re-expose to the race window
            vehicle.request_mode(Px4Mode.OFFBOARD)
            for _ in range(10):
                vehicle.offboard_setpoint(VELOCITY_NORTH)
                vehicle.step(DT_S)
            results.append(vehicle.mode is Px4Mode.HOLD)
            vehicle.request_mode(Px4Mode.HOLD)
        return results

    first = outcomes(7)
    assert first == outcomes(7)
    assert any(first) and not all(first)


@pytest.mark.slow
def test_rtl_climbs_returns_lands_and_disarms() -> None:
    params = VehicleSimParams(arm_denied_after_boot_s=0.0, rtl_return_alt_m=8.0)
    vehicle = in_offboard(params)
    north = TrajectorySetpoint(velocity_ned_mps=np.array([3.0, 0.0, 0.0]), yaw_rad=0.0)
    run_until(
        vehicle,
        lambda v: v.truth.position_ned_m[0] > 15.0,
        20.0,
        feed=lambda v: v.offboard_setpoint(north),
    )
    assert vehicle.return_to_launch() is CommandResult.ACCEPTED
    heights = []
    run_until(
        vehicle,
        lambda v: not v.armed,
        90.0,
        feed=lambda v: heights.append(-v.truth.position_ned_m[2]),
    )
    # beyond RTL_MIN_DIST of home it climbs to RTL_RETURN_ALT
    assert max(heights) == pytest.approx(8.0, abs=0.4)
    np.testing.assert_allclose(vehicle.truth.position_ned_m, 0.0, atol=0.3)
    assert vehicle.mode is Px4Mode.OFFBOARD  # the mode before RTL, as PX4 reports it


def test_rtl_next_to_home_lands_without_climbing() -> None:
    vehicle = hovering(VehicleSimParams(arm_denied_after_boot_s=0.0, rtl_return_alt_m=30.0))
    start_height = -vehicle.truth.position_ned_m[2]
    assert vehicle.return_to_launch() is CommandResult.ACCEPTED
    heights = []
    run_until(
        vehicle, lambda v: v.landed, 40.0, feed=lambda v: heights.append(-v.truth.position_ned_m[2])
    )
    # within NAV_ACC_RAD of home PX4's RTL cone gives no climb: it lands where it is
    assert max(heights) < start_height + 0.3
    assert [e.arguments[1] for e in vehicle.events if e.name == "vrtl_return_at"] == [
        round(start_height)
    ]


def test_px4_custom_mode_encoding() -> None:
    assert Px4Mode.HOLD.custom_mode == (4 << 16) | (3 << 24)
    assert Px4Mode.OFFBOARD.custom_mode == 6 << 16
    assert Px4Mode.from_px4(4, 5) is Px4Mode.RTL
    assert Px4Mode.from_px4(6, 0) is Px4Mode.OFFBOARD
    assert Px4Mode.from_px4(3, 0) is None  # position mode needs RC: not offered
