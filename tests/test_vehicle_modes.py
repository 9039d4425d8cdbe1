"""PX4 commander/navigator semantics of the SIL vehicle, in lockstep without sockets."""

from __future__ import annotations

import numpy as np
import pytest

from hil.params import VehicleSimParams
from hil.px4_controller import TrajectorySetpoint
from hil.px4_modes import CommandResult, FlightMode, LandedState, Px4Vehicle

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
    run_until(vehicle, lambda v: v.mode is FlightMode.HOLD, 10.0)
    return vehicle


def in_offboard(params: VehicleSimParams | None = None) -> Px4Vehicle:
    vehicle = hovering(params)
    vehicle.offboard_setpoint(VELOCITY_NORTH)
    assert vehicle.request_mode(FlightMode.OFFBOARD) is CommandResult.ACCEPTED
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
    assert vehicle.landed_state is LandedState.ON_GROUND
    vehicle.arm()
    vehicle.takeoff()
    vehicle.step(1.0)
    assert vehicle.landed_state is LandedState.TAKEOFF
    climb_rates = []
    run_until(
        vehicle,
        lambda v: v.mode is FlightMode.HOLD,
        15.0,
        feed=lambda v: climb_rates.append(-v.truth.velocity_ned_mps[2]),
    )
    assert max(climb_rates) <= params.takeoff_speed_mps * 1.15
    vehicle.step(3.0)
    assert vehicle.landed_state is LandedState.IN_AIR
    np.testing.assert_allclose(vehicle.truth.position_ned_m, [0.0, 0.0, -5.0], atol=0.1)


def test_takeoff_altitude_param7_is_amsl() -> None:
    params = VehicleSimParams(arm_denied_after_boot_s=0.0, home_alt_amsl_m=100.0)
    vehicle = Px4Vehicle(params)
    vehicle.step(1.1)
    vehicle.arm()
    assert vehicle.takeoff(103.0) is CommandResult.ACCEPTED
    run_until(vehicle, lambda v: v.mode is FlightMode.HOLD, 10.0)
    vehicle.step(3.0)
    assert vehicle.truth.position_ned_m[2] == pytest.approx(-3.0, abs=0.1)


def test_land_then_auto_disarm_after_com_disarm_land() -> None:
    vehicle = hovering()
    assert vehicle.land() is CommandResult.ACCEPTED
    touchdown = run_until(vehicle, lambda v: v.truth.on_ground, 20.0)
    disarmed = run_until(vehicle, lambda v: not v.armed, 10.0)
    p = vehicle.params
    assert disarmed - touchdown == pytest.approx(p.land_detect_time_s + p.disarm_land_s, abs=0.05)
    assert vehicle.landed_state is LandedState.ON_GROUND
    assert vehicle.truth.position_ned_m[2] == 0.0


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
    assert vehicle.request_mode(FlightMode.OFFBOARD) is CommandResult.TEMPORARILY_REJECTED
    assert vehicle.mode is FlightMode.HOLD
    vehicle.offboard_setpoint(VELOCITY_NORTH)
    vehicle.step(0.6)  # older than 0.5 s
    assert vehicle.request_mode(FlightMode.OFFBOARD) is CommandResult.TEMPORARILY_REJECTED
    vehicle.offboard_setpoint(VELOCITY_NORTH)
    vehicle.step(0.4)
    assert vehicle.request_mode(FlightMode.OFFBOARD) is CommandResult.ACCEPTED
    assert vehicle.mode is FlightMode.OFFBOARD


def test_offboard_follows_setpoints_then_loss_failsafes_to_hold() -> None:
    vehicle = in_offboard()
    for _ in range(200):
        vehicle.offboard_setpoint(VELOCITY_NORTH)
        vehicle.step(DT_S)
    assert vehicle.truth.velocity_ned_mps[0] == pytest.approx(1.0, abs=0.05)
    last_setpoint_s = vehicle.time_s
    failsafe_s = run_until(vehicle, lambda v: v.mode is FlightMode.HOLD, 3.0)
    assert failsafe_s - last_setpoint_s == pytest.approx(
        vehicle.params.offboard_loss_timeout_s, abs=2 * DT_S
    )
    run_until(vehicle, lambda v: np.linalg.norm(v.truth.velocity_ned_mps) < 0.05, 5.0)
    assert any("offboard" in t.text for t in vehicle.status_texts)


def test_companion_heartbeat_loss_failsafes_to_hold() -> None:
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
    lost_s = run_until(
        vehicle, lambda v: v.mode is FlightMode.HOLD, 5.0, feed=lambda v: feed(v, False)
    )
    assert lost_s - last_heartbeat_s == pytest.approx(2.0, abs=2 * DT_S)


def test_no_companion_failsafe_when_none_was_ever_seen() -> None:
    params = VehicleSimParams(arm_denied_after_boot_s=0.0, companion_loss_timeout_s=0.5)
    vehicle = in_offboard(params)
    for _ in range(150):
        vehicle.offboard_setpoint(VELOCITY_NORTH)
        vehicle.step(DT_S)
    assert vehicle.mode is FlightMode.OFFBOARD


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
    assert vehicle.request_mode(FlightMode.OFFBOARD) is CommandResult.ACCEPTED
    for _ in range(25):
        vehicle.offboard_setpoint(VELOCITY_NORTH)
        vehicle.step(DT_S)
    assert vehicle.mode is FlightMode.HOLD
    # a retry after the window succeeds
    vehicle.step(0.5)
    vehicle.offboard_setpoint(VELOCITY_NORTH)
    assert vehicle.request_mode(FlightMode.OFFBOARD) is CommandResult.ACCEPTED
    for _ in range(50):
        vehicle.offboard_setpoint(VELOCITY_NORTH)
        vehicle.step(DT_S)
    assert vehicle.mode is FlightMode.OFFBOARD


def test_no_race_when_disabled() -> None:
    vehicle = race_vehicle(0.0)
    vehicle.offboard_setpoint(VELOCITY_NORTH)
    assert vehicle.request_mode(FlightMode.OFFBOARD) is CommandResult.ACCEPTED
    for _ in range(50):
        vehicle.offboard_setpoint(VELOCITY_NORTH)
        vehicle.step(DT_S)
    assert vehicle.mode is FlightMode.OFFBOARD


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
            vehicle.request_mode(FlightMode.OFFBOARD)
            for _ in range(10):
                vehicle.offboard_setpoint(VELOCITY_NORTH)
                vehicle.step(DT_S)
            results.append(vehicle.mode is FlightMode.HOLD)
            vehicle.request_mode(FlightMode.HOLD)
        return results

    first = outcomes(7)
    assert first == outcomes(7)
    assert any(first) and not all(first)


@pytest.mark.slow
def test_rtl_climbs_returns_lands_and_disarms() -> None:
    params = VehicleSimParams(arm_denied_after_boot_s=0.0, rtl_return_alt_m=8.0)
    vehicle = in_offboard(params)
    for _ in range(250):
        vehicle.offboard_setpoint(VELOCITY_NORTH)
        vehicle.step(DT_S)
    assert vehicle.return_to_launch() is CommandResult.ACCEPTED
    heights = []
    run_until(
        vehicle,
        lambda v: not v.armed,
        60.0,
        feed=lambda v: heights.append(-v.truth.position_ned_m[2]),
    )
    assert max(heights) == pytest.approx(8.0, abs=0.3)
    np.testing.assert_allclose(vehicle.truth.position_ned_m, 0.0, atol=0.3)
    assert vehicle.mode is FlightMode.HOLD


def test_px4_custom_mode_encoding() -> None:
    assert FlightMode.HOLD.custom_mode == (4 << 16) | (3 << 24)
    assert FlightMode.OFFBOARD.custom_mode == 6 << 16
    assert FlightMode.from_px4(4, 5) is FlightMode.RTL
    assert FlightMode.from_px4(6, 0) is FlightMode.OFFBOARD
    assert FlightMode.from_px4(3, 0) is None  # position mode needs RC: not offered
