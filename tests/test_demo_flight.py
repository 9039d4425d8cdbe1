"""The README's main command: `wireavoid fly-pattern` flies the hil vehicle and reports."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from companion.cli import app
from companion.demo_flight import DemoPattern, FlightSummary, LegResult, verdict
from companion.vehicle_link import LinkEvent, LinkEventKind


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


def test_demo_pattern_defaults_fly_a_closed_square():
    p = DemoPattern()
    assert p.square_speed_mps > 0 and p.square_leg_s > 0
    assert 0 < p.settle_fraction < 1


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
