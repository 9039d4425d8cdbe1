"""The README's main command: `wireavoid fly-pattern` flies the hil vehicle and reports."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from companion.cli import app
from companion.cli.demo_flight import (
    DemoPattern,
    FlightSummary,
    LegResult,
    _velocity_verdict,
    verdict,
)
from companion.link.vehicle_link import LinkEvent, LinkEventKind
from hil.vehicle.multirotor import Multirotor
from hil.vehicle.params import VehicleSimParams


def _leg(name: str, ok: bool = True, error: float = 0.1) -> LegResult:
    return LegResult(name, [0.0], [error], error, None, 0.3, "m", 1.0, ok)


def test_verdict_passes_only_when_every_leg_is_in_tolerance_and_no_faults():
    legs = [_leg("takeoff"), _leg("velocity north"), _leg("position"), _leg("land")]
    assert verdict(legs, []) == (True, "all 4 legs within tolerance")

    ok, why = verdict([*legs[:2], _leg("position", ok=False, error=0.8), legs[3]], [])
    assert not ok and "position" in why and "0.80" in why

    ok, why = verdict(legs[:2], [])
    assert not ok and "land" in why and "position" in why

    brake = LinkEvent(1.0, LinkEventKind.WATCHDOG_BRAKE, "planner output 0.35 s old")
    ok, why = verdict(legs, [brake])
    assert not ok and "watchdog_brake" in why


def test_summary_text_names_each_leg_and_the_verdict():
    summary = FlightSummary(legs=[_leg("takeoff"), _leg("land", ok=False)], verdict="x")
    text = summary.to_text()
    assert "takeoff" in text and "land" in text and "NO" in text
    assert text.splitlines()[-1] == "verdict: FAIL - x"
    assert json.loads(summary.to_json())["legs"][1]["ok"] is False


@pytest.mark.slow
@pytest.mark.timeout(60)
def test_fly_pattern_command_flies_the_sim_vehicle_and_passes():
    result = CliRunner().invoke(app, ["fly-pattern", "--speed", "3", "--json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)
    assert summary["ok"] is True
    names = [leg["name"] for leg in summary["legs"]]
    assert names[0] == "takeoff" and names[-1] == "land" and "position" in names
    assert sum(name.startswith("velocity") for name in names) == 4
    for leg in summary["legs"]:
        assert leg["error"] <= leg["tolerance"]
        assert leg["truth_error"] is not None and leg["truth_error"] <= leg["tolerance"]
    assert summary["watchdog_events"] == 0
    assert summary["speed"] == 3.0
    # PX4's default failsafe (COM_OBL_RC_ACT 0, no RC: Return to 30 m) is flagged, not flown
    assert any(line.startswith("refuse: offboard loss") for line in summary["preflight"])
    kinds = {event["kind"] for event in summary["events"]}
    assert {"vehicle_event", "arming_check"} <= kinds  # PX4's events, decoded by MAVSDK


def _side_samples(params, velocity_ned_mps: np.ndarray, pattern: DemoPattern) -> list[np.ndarray]:
    """Velocities in the steady-state window of one square side, flown in lockstep."""
    vehicle = Multirotor(params)
    vehicle.reset(np.array([0.0, 0.0, -3.0]), 0.0)
    vehicle.set_velocity_setpoint(velocity_ned_mps, yaw_rad=0.0)
    dt_s = 0.05
    steps = round(pattern.square_leg_s / dt_s)
    states = [vehicle.step(dt_s) for _ in range(steps)]
    window = states[round(steps * (1.0 - pattern.settle_fraction)) :]
    return [np.asarray(s.velocity_ned_mps) for s in window]


def test_velocity_grading_passes_a_healthy_px4_and_fails_a_broken_one():
    """The grading fly-pattern applies to PX4 SITL and the hil vehicle alike, on the PX4
    controller: default gains pass; a halved velocity gain, a wrong frame or a unit error fail."""
    pattern = DemoPattern()
    command = np.array([2.0, 0.0, 0.0])
    healthy = VehicleSimParams()
    _, ok, why = _velocity_verdict(_side_samples(healthy, command, pattern), command, pattern)
    assert ok, why
    sluggish = healthy.model_copy(update={"xy_vel_p": 0.6, "xy_vel_i": 0.1})
    _, ok, why = _velocity_verdict(_side_samples(sluggish, command, pattern), command, pattern)
    assert not ok and "of the speed along" in why
    # east flown when north was asked (a frame swap), twice the speed (a unit error)
    samples = _side_samples(healthy, command, pattern)
    swapped = [s[[1, 0, 2]] for s in samples]
    assert not _velocity_verdict(swapped, command, pattern)[1]
    assert not _velocity_verdict([2.0 * s for s in samples], command, pattern)[1]
    assert not _velocity_verdict([], command, pattern)[1]
