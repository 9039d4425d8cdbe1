"""Before a flight: the vehicle's own limits for the planner, and its failsafes near wires.

Once the link is up, the autopilot's parameters are read once (`VehicleLink.read_parameters`):
- the trajectory library and the tracker take the vehicle's speed, acceleration, jerk,
  climb and yaw-rate limits and the braking distance its velocity loop really flies
  (`companion.link.px4_limits`), capped by `planning.max_speed_mps`: never constants tuned
  on a simulator;
- PX4's failsafe actions are checked for a flight at the mission's height and reach
  (`companion.link.preflight`): with `link.failsafe_check = "refuse"`, a failsafe that would
  climb or fly home blind through wires keeps the mission on the ground; with "warn" it is
  reported.
The adopted limits go into the flight's settings, so a recording carries them and a replay
plans as the flight did.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np

from companion.config import Settings
from companion.link.preflight import PREFLIGHT_PARAMETERS, FailsafeReport, failsafe_report
from companion.link.px4_limits import PX4_LIMIT_PARAMETERS, VehicleLimits, vehicle_limits
from companion.link.vehicle_link import LinkError, VehicleLink

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class VehicleCheck:
    """What the autopilot's parameters say about this flight.

    settings: the flight's settings with the planner's limits taken from the vehicle.
    refusal: why the mission must not fly ("" when it may).
    warnings: what the operator should know (failsafe findings, parameters not readable).
    """

    settings: Settings
    limits: VehicleLimits | None
    failsafes: FailsafeReport | None
    refusal: str
    warnings: tuple[str, ...]


def mission_reach_m(settings: Settings) -> tuple[float, float]:
    """(highest altitude above home, farthest distance from home) the mission's configured
    goals and take-off reach, m (an operator's later goals are checked by the geofence)."""
    goals = np.asarray(settings.mission.goals_ned_m, dtype=np.float64).reshape(-1, 3)
    height = max([settings.mission.takeoff_altitude_m, *(-goals[:, 2]).tolist()])
    reach = float(np.max(np.hypot(goals[:, 0], goals[:, 1]))) if len(goals) else 0.0
    return float(height), reach


def vehicle_check(settings: Settings, parameters: dict[str, float | int | None]) -> VehicleCheck:
    """The check on parameters already read (pure)."""
    limits = vehicle_limits(parameters, settings.planning.max_speed_mps)
    # the planner never plans above the geofence's ceiling (there it would be a failsafe)
    ceiling_m = min(settings.planning.max_altitude_m, settings.geofence.max_altitude_m)
    planning = settings.planning.model_copy(
        update={**limits.planning_overrides(), "max_altitude_m": ceiling_m}
    )
    height_m, reach_m = mission_reach_m(settings)
    report = failsafe_report(
        parameters,
        flight_height_m=height_m,
        max_speed_mps=limits.max_speed_mps,
        home_distance_m=reach_m if reach_m > 0 else math.inf,
    )
    policy = settings.link.failsafe_check
    problems = [f.text() for f in report.problems] if policy != "off" else []
    refusal = ""
    if policy == "refuse" and report.refuse:
        refusal = "PX4's failsafes would fly blind near wires: " + "; ".join(problems)
    return VehicleCheck(
        settings.model_copy(update={"planning": planning}),
        limits,
        report,
        refusal,
        tuple(problems),
    )


async def check_vehicle(settings: Settings, link: VehicleLink) -> VehicleCheck:
    """Read the autopilot's parameters and check them (see the module docstring). An
    autopilot whose parameters cannot be read flies with the configured limits, and says so."""
    names = (*PX4_LIMIT_PARAMETERS, *PREFLIGHT_PARAMETERS)
    try:
        parameters = await link.read_parameters(names)
    except LinkError as e:
        text = f"cannot read the autopilot's parameters ({e}): flying the configured limits"
        log.warning("%s", text)
        return VehicleCheck(settings, None, None, "", (text,))
    check = vehicle_check(settings, parameters)
    p = check.settings.planning
    log.info(
        "planning with the vehicle's limits: %.1f m/s, %.2f m/s^2, jerk %.1f m/s^3, braking "
        "%.2f m from cruise",
        p.max_speed_mps,
        p.max_accel_mps2,
        p.max_jerk_mps3,
        float(check.limits.braking_distance_m(p.max_speed_mps)),
    )
    for warning in check.warnings:
        log.warning("pre-flight: %s", warning)
    return check
