"""The flight process seen from the ground station: its status, its events, the fence.

`GroundConnection` runs the MQTT `GroundLink` inside the flight process when
`ground.broker_url` is set: commands go to the mission (`MissionCommands`), the retained status
is built from the process' state (`flight_status`), every mission event is published, and the
link's health feeds the mission's ground-link-lost failsafe. The geofence is the one of
`[geofence]`: it checks every operator goal, and a vehicle flying outside its outline or above
its ceiling is a mission failsafe (the floor is the planner's, `planning.min_altitude_m`).
"""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np

from companion.clock import Clock
from companion.config import Settings
from companion.flight.timing import StageTimes
from companion.ground.geofence import Geofence, HomePosition
from companion.ground.link import GroundLink
from companion.ground.mission_handler import MissionCommands
from companion.ground.protocol import (
    BatteryReport,
    Event,
    GoalReport,
    StageReport,
    Status,
)
from companion.link.telemetry import LandedState, TelemetrySnapshot
from companion.link.vehicle_link import VehicleLink
from companion.mission import Decision, Mission, MissionEvent
from companion.topics import Bus, Stamped


class FlightState(Protocol):
    """What the ground connection reads of the flight process (`FlightProcess` has it)."""

    settings: Settings
    link: VehicleLink
    clock: Clock
    bus: Bus
    times: StageTimes
    mission: Mission
    decision: Decision | None


# stage -> (topic it publishes, its latency in flight.timing)
_STAGES = {
    "camera": ("camera", "ingest"),
    "perception": ("perception", "cnn"),
    "map": ("map", "map"),
    "planner": ("plan", "plan"),
    "setpoints": ("setpoint", "frame_to_setpoint"),
}


def home_position(snap: TelemetrySnapshot) -> HomePosition | None:
    """The autopilot's home for geographic goals, or None before it reported a valid one."""
    home = snap.home
    if home is None or not (math.isfinite(home.lat_deg) and math.isfinite(home.lon_deg)):
        return None
    local = home.position_ned_m if np.all(np.isfinite(home.position_ned_m)) else np.zeros(3)
    return HomePosition(home.lat_deg, home.lon_deg, local)


class GroundConnection:
    """The ground link of one flight process (see the module docstring)."""

    def __init__(self, process: FlightState) -> None:
        self._process = process
        settings = process.settings
        self.geofence = Geofence(settings.geofence)
        self.commands = MissionCommands(process.mission, self.geofence, self._position, self._home)
        self.link = (
            GroundLink(settings.ground, process.clock, self.commands, self.status)
            if settings.ground.enabled
            else None
        )
        process.bus.subscribe(self._forward)

    async def run(self) -> None:
        """Run the MQTT link until cancelled (returns at once without a broker)."""
        if self.link is not None:
            await self.link.run()

    def ground_link_ok(self, now_s: float) -> bool | None:
        """False once the ground has been unreachable for `mission.ground_lost_s`; None
        without a ground link."""
        if self.link is None:
            return None
        lost_s = self.link.health().lost_for_s(now_s)
        return lost_s <= self._process.settings.mission.ground_lost_s

    def inside_geofence(self) -> bool:
        """The vehicle is inside the fence's outline and under its ceiling (or unknown)."""
        position = self._position()
        if position is None:
            return True
        home = self._home()
        home_ned = np.zeros(3) if home is None else np.asarray(home.position_ned_m)
        altitude_m = float(home_ned[2] - position[2])
        return (
            not self.geofence.horizontal_violation(position)
            and altitude_m <= self.geofence.params.max_altitude_m
        )

    def status(self) -> Status:
        """The retained status: mission and PX4 mode, pose, goal, planner, battery, stages."""
        process = self._process
        snap = process.link.telemetry()
        mission = process.mission
        decision = process.decision
        pose = snap.pose
        goals = mission.goals_ned_m
        index = mission.goal_index
        plan = process.bus.latest("plan")
        return Status(
            vehicle_id=process.settings.ground.vehicle_id,
            stamp_s=process.clock.now_s(),
            mode=mission.state.value,
            failsafe=None if decision is None or decision.cause is None else decision.cause.value,
            flight_mode=snap.flight_mode.value,
            armed=snap.armed,
            in_air=None
            if snap.landed_state is LandedState.UNKNOWN
            else snap.landed_state is LandedState.IN_AIR,
            position_ned_m=None if pose is None else pose.position_ned_m.tolist(),
            velocity_ned_mps=None if pose is None else pose.velocity_ned_mps.tolist(),
            yaw_rad=None if snap.attitude is None else snap.attitude.yaw_rad,
            speed_mps=None if pose is None else pose.speed_mps,
            active_goal=GoalReport(
                index=index,
                count=len(goals),
                target_ned_m=goals[index].tolist() if index < len(goals) else None,
                command_id=self.commands.command_ids.get(index),
            ),
            planner_state=None if plan is None else plan.message.output.state.value,
            battery=None
            if snap.battery is None
            else BatteryReport(
                voltage_v=snap.battery.voltage_v, remaining_frac=snap.battery.remaining_frac
            ),
            stages=self._stages(),
        )

    def _stages(self) -> dict[str, StageReport]:
        process = self._process
        reports = {}
        for name, (topic, timing) in _STAGES.items():
            age_s = process.bus.age_s(topic)
            summary = process.times.summary(timing)
            limit_s = process.settings.flight.perception_max_age_s
            reports[name] = StageReport(
                ok=age_s <= limit_s,
                latency_ms=summary.p50_ms,
                age_s=age_s if math.isfinite(age_s) else None,
                detail="" if age_s <= limit_s else f"nothing for {age_s:.1f} s",
            )
        reports["vehicle_link"] = StageReport(
            ok=process.link.state.value == "connected", detail=process.link.state.value
        )
        return reports

    def _position(self) -> np.ndarray | None:
        pose = self._process.link.telemetry().pose
        return None if pose is None else pose.position_ned_m

    def _home(self) -> HomePosition | None:
        return home_position(self._process.link.telemetry())

    def _forward(self, stamped: Stamped) -> None:
        """Every mission event onto the ground link's events topic."""
        if self.link is None or stamped.topic != "mission":
            return
        event: MissionEvent = stamped.message
        self.link.publish_event(
            Event(
                vehicle_id=self._process.settings.ground.vehicle_id,
                stamp_s=event.stamp_s,
                kind="mission",
                severity="warning" if event.warning else "info",
                state=event.state.value,
                text=event.text,
            )
        )
