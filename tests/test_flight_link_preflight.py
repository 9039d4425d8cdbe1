"""The pre-flight failsafe check (companion.link.preflight): pure rules, then through the link."""

from __future__ import annotations

import math

import pytest

from companion.cli.demo_flight import free_udp_port, run_demo
from companion.cli.settings import SimSettings
from companion.link.params import LinkParams
from companion.link.preflight import Severity, failsafe_report, rtl_return_altitude_m
from companion.link.vehicle_link import VehicleLink
from hil.mavlink.server import VehicleServer
from hil.vehicle.params import VehicleSimParams

PX4_SITL = {"COM_OBL_RC_ACT": 0, "COM_OF_LOSS_T": 1.0, "RTL_RETURN_ALT": 30.0, "NAV_RCL_ACT": 2}


def _finding(report, failsafe: str):
    return next(f for f in report.findings if f.failsafe.startswith(failsafe))


def test_px4s_default_offboard_loss_climbs_to_rtl_return_alt_and_is_refused():
    report = failsafe_report(PX4_SITL, flight_height_m=3.0, max_speed_mps=2.0)
    loss = _finding(report, "offboard loss")
    assert report.refuse and loss.severity is Severity.REFUSE
    assert "falls back to Return" in loss.action and "climbs 27 m" in loss.action
    assert "COM_OBL_RC_ACT to 5" in loss.fix
    blind = _finding(report, "setpoint timeout")
    assert blind.severity is Severity.WARN and "2.0 m" in blind.action
    assert report.problems[0] is loss  # worst first


def test_the_rtl_altitude_follows_px4s_cone():
    values = failsafe_report({}, flight_height_m=3.0, max_speed_mps=1.0).parameters
    values = {**values, "RTL_RETURN_ALT": 30.0}
    assert rtl_return_altitude_m(values, 3.0, math.inf) == 30.0
    assert rtl_return_altitude_m(values, 3.0, 1.0) == 3.0  # next to home: no climb
    assert rtl_return_altitude_m(values, 3.0, 6.0) == pytest.approx(6.0)  # 45 deg cone
    assert rtl_return_altitude_m(values, 40.0, math.inf) == 40.0  # never down
    near = failsafe_report(
        {"COM_OBL_RC_ACT": 3}, flight_height_m=3.0, max_speed_mps=1.0, home_distance_m=1.0
    )
    # no climb, but still home blind through the wire area: refused
    assert near.refuse and "flies home" in _finding(near, "offboard loss").action


@pytest.mark.parametrize(
    ("action", "severity"),
    [
        (5, Severity.OK),
        (4, Severity.WARN),
        (6, Severity.WARN),
        (7, Severity.WARN),
        (3, Severity.REFUSE),
    ],
)
def test_the_setting_that_holds_or_lands_is_not_refused(action: int, severity: Severity):
    report = failsafe_report(
        {**PX4_SITL, "COM_OBL_RC_ACT": action}, flight_height_m=3.0, max_speed_mps=2.0
    )
    assert _finding(report, "offboard loss").severity is severity
    assert report.refuse is (severity is Severity.REFUSE)


def test_stick_loss_and_setpoint_timeout_rules():
    short = failsafe_report({"COM_OF_LOSS_T": 0.3}, flight_height_m=3.0, max_speed_mps=2.0)
    assert _finding(short, "setpoint timeout").severity is Severity.OK
    sticks = _finding(failsafe_report(PX4_SITL, flight_height_m=3.0, max_speed_mps=2.0), "pilot")
    assert sticks.severity is Severity.WARN and "climbs" in sticks.action
    excepted = failsafe_report({"COM_RCL_EXCEPT": 4}, flight_height_m=3.0, max_speed_mps=2.0)
    assert _finding(excepted, "pilot").severity is Severity.OK
    no_sticks = failsafe_report({"COM_RC_IN_MODE": 4}, flight_height_m=3.0, max_speed_mps=2.0)
    assert _finding(no_sticks, "pilot").severity is Severity.OK
    hold = failsafe_report({"NAV_RCL_ACT": 1}, flight_height_m=3.0, max_speed_mps=2.0)
    assert _finding(hold, "pilot").severity is Severity.OK


@pytest.mark.timeout(60)
async def test_the_link_reads_px4s_parameters_from_the_vehicle():
    port = free_udp_port()
    params = VehicleSimParams(offboard_loss_action=5, offboard_loss_timeout_s=0.3)
    with VehicleServer(params, port, speed=2.0):
        async with VehicleLink(LinkParams(connection_url=f"udpin://0.0.0.0:{port}")) as link:
            await link.wait_healthy()
            values = await link.read_parameters(["COM_OBL_RC_ACT", "COM_OF_LOSS_T", "NO_SUCH"])
    assert values == {"COM_OBL_RC_ACT": 5, "COM_OF_LOSS_T": pytest.approx(0.3), "NO_SUCH": None}
    assert not failsafe_report(values, flight_height_m=3.0, max_speed_mps=2.0).refuse


@pytest.mark.slow
@pytest.mark.timeout(90)
async def test_fly_pattern_refuses_offboard_when_told_to_and_lands():
    settings = SimSettings()
    settings = settings.model_copy(
        update={"link": settings.link.model_copy(update={"failsafe_check": "refuse"})}
    )
    summary = await run_demo(settings, speed=4.0)
    assert not summary.ok
    assert summary.verdict.startswith("refused to start offboard: refuse: offboard loss")
    assert [leg.name for leg in summary.legs] == ["takeoff"]
    kinds = [event["kind"] for event in summary.events]
    assert "offboard_started" not in kinds
    # brought down: landed and disarmed by PX4's land detector
    assert any("Disarmed by landing" in event["detail"] for event in summary.events)
