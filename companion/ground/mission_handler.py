"""The ground station's commands carried out by the mission: the `CommandHandler` of the link.

Each command is checked against the geofence first (goals and the straight legs to them, from
where the vehicle is), converted to local NED (a geographic goal needs the home position) and
handed to the mission state machine, whose `Verdict` becomes the command's one `Ack`. A refused
command changes nothing: neither the mission's queue nor its state.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from companion.ground.geofence import Geofence, HomePosition, target_ned_m
from companion.ground.protocol import (
    AbortCommand,
    Ack,
    Command,
    GotoCommand,
    HoldCommand,
    LandCommand,
    MissionCommand,
    ResumeCommand,
    RtlCommand,
    SetSpeedCommand,
    TakeoffCommand,
)
from companion.mission import Mission, Verdict


class MissionCommands:
    """`CommandHandler` over a `Mission`.

    position: the vehicle's local NED position now (None when unknown); home: the home
    position (None until the autopilot reported it).
    """

    def __init__(
        self,
        mission: Mission,
        geofence: Geofence,
        position: Callable[[], np.ndarray | None],
        home: Callable[[], HomePosition | None],
    ) -> None:
        self._mission = mission
        self._geofence = geofence
        self._position = position
        self._home = home
        self.command_ids: dict[int, str] = {}  # goal index -> id of the command that set it

    def handle(self, command: Command, now_s: float) -> Ack:
        """Carry `command` out or refuse it: its one `Ack`."""
        home = self._home()
        problem = self._geofence.command_violation(command, self._position(), home)
        if problem:
            return Ack.reject(command, problem, now_s)
        verdict = self._verdict(command, home)
        if not verdict.accepted:
            return Ack.reject(command, verdict.reason, now_s)
        if isinstance(command, GotoCommand | MissionCommand):
            count = 1 if isinstance(command, GotoCommand) else len(command.waypoints)
            self.command_ids = dict.fromkeys(range(count), command.id)
        return Ack.accept(command, now_s)

    def _verdict(self, command: Command, home: HomePosition | None) -> Verdict:
        m = self._mission
        if isinstance(command, TakeoffCommand):
            return m.takeoff(command.altitude_m)
        if isinstance(command, GotoCommand | MissionCommand):
            waypoints = [command] if isinstance(command, GotoCommand) else command.waypoints
            goals = [target_ned_m(w.target, home) for w in waypoints]
            unplaced = [g for g in goals if isinstance(g, str)]
            if unplaced:
                return Verdict(False, unplaced[0])
            return m.goto(goals, waypoints[0].speed_mps)
        if isinstance(command, HoldCommand):
            return m.hold()
        if isinstance(command, ResumeCommand):
            return m.resume()
        if isinstance(command, LandCommand):
            return m.land()
        if isinstance(command, RtlCommand):
            return m.rtl()
        if isinstance(command, AbortCommand):
            return m.abort()
        if isinstance(command, SetSpeedCommand):
            return m.set_speed(command.speed_mps)
        return Verdict(False, f"command {type(command).__name__} is not supported")
