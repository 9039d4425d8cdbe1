"""PX4's events and health/arming-check reports, as the flight link reports them.

PX4 tells mode changes, arming results, failsafes and landings as EVENT messages (the events
protocol), not STATUSTEXT; their text lives in metadata the autopilot serves over MAVFTP.
MAVSDK's events plugin downloads it and decodes both the events and PX4's health and arming
check reports (which problems keep which modes from arming or running). These functions turn
MAVSDK's objects into the link's one-line details: `event_detail` for a `LinkEventKind.
VEHICLE_EVENT`, `arming_report_detail` for a `LinkEventKind.ARMING_CHECK` (reported when it
changes). Pure: MAVSDK objects in (duck-typed), strings out.
"""

from __future__ import annotations

from typing import Any


def _level(log_level: Any) -> str:
    """'info', 'warning', ... of a MAVSDK `LogLevel` (or its name)."""
    return str(getattr(log_level, "name", log_level)).lower()


def event_detail(event: Any) -> str:
    """ "level: message (namespace/name)" of a MAVSDK `Event`."""
    return (
        f"{_level(event.log_level)}: {event.message} ({event.event_namespace}/{event.event_name})"
    )


def arming_report_detail(report: Any) -> str:
    """The current mode's readiness and its problems, of a MAVSDK `HealthAndArmingCheckReport`:
    "Hold: can arm; warning: No manual control input (remote_control)"."""
    mode = report.current_mode_intention
    ready = "can arm" if mode.can_arm_or_run else "cannot arm or run"
    problems = "; ".join(
        f"{_level(p.log_level)}: {p.message} ({p.health_component})" for p in mode.problems
    )
    return f"{mode.mode_name}: {ready}" + (f"; {problems}" if problems else "")
