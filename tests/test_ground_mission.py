"""Ground commands carried out by the mission (`companion.ground.mission_handler`): the fence
first, goals placed in local NED, the mission's verdict as the ack; a refusal changes nothing."""

from __future__ import annotations

import numpy as np

from companion.ground.geofence import Geofence, HomePosition
from companion.ground.mission_handler import MissionCommands
from companion.ground.params import GeofenceParams
from companion.ground.protocol import Command, parse_command
from companion.mission import Mission, MissionParams, MissionState

HOME = HomePosition(47.397742, 8.545594, np.zeros(3))


def command(text: str) -> Command:
    parsed = parse_command(text.encode())
    assert not hasattr(parsed, "reason"), parsed
    return parsed  # type: ignore[return-value]


def handler(home: HomePosition | None = HOME, position=(0.0, 0.0, 0.0)):
    mission = Mission(MissionParams())
    fence = Geofence(GeofenceParams(radius_m=50.0, max_altitude_m=20.0))
    return mission, MissionCommands(mission, fence, lambda: np.asarray(position), lambda: home)


def test_a_goto_inside_the_fence_becomes_the_missions_goal_and_starts_it() -> None:
    mission, commands = handler()
    ack = commands.handle(
        command('{"v":1,"id":"g1","type":"goto","target":{"north_m":10,"east_m":2,"down_m":-3}}'),
        1.0,
    )
    assert ack.accepted and ack.id == "g1" and ack.command == "goto"
    np.testing.assert_array_equal(mission.goals_ned_m[0], [10.0, 2.0, -3.0])
    assert commands.command_ids == {0: "g1"}
    decision = mission.step(1.1, _grounded(), _fresh(), None)
    assert decision.state is MissionState.ARMING  # from the ground: arm and take off first


def test_refused_commands_say_why_and_change_nothing() -> None:
    mission, commands = handler(home=None)
    outside = command(
        '{"v":1,"id":"far","type":"goto","target":{"north_m":80,"east_m":0,"down_m":-3}}'
    )
    ack = commands.handle(outside, 1.0)
    assert not ack.accepted and "geofence.radius_m" in ack.reason
    too_high = command(
        '{"v":1,"id":"hi","type":"goto","target":{"north_m":5,"east_m":0,"down_m":-30}}'
    )
    assert "geofence.max_altitude_m" in commands.handle(too_high, 1.0).reason
    geo = command(
        '{"v":1,"id":"geo","type":"goto","target":{"lat_deg":47.3978,"lon_deg":8.5456,'
        '"altitude_m":3}}'
    )
    ack = commands.handle(geo, 1.0)
    assert not ack.accepted and "home position not known" in ack.reason
    hold = commands.handle(command('{"v":1,"id":"h","type":"hold"}'), 1.0)
    assert not hold.accepted and "cannot hold while idle" in hold.reason
    assert mission.goals_ned_m == [] and mission.state is MissionState.IDLE
    assert commands.command_ids == {}


def test_a_geographic_goal_is_placed_through_the_home_position() -> None:
    mission, commands = handler()
    ack = commands.handle(
        command(
            '{"v":1,"id":"geo","type":"mission","waypoints":['
            '{"target":{"lat_deg":47.397832,"lon_deg":8.545594,"altitude_m":4}},'
            '{"target":{"north_m":0,"east_m":5,"down_m":-4},"speed_mps":1.5}]}'
        ),
        1.0,
    )
    assert ack.accepted, ack.reason
    north, east, down = mission.goals_ned_m[0]
    assert abs(north - 10.0) < 0.1 and abs(east) < 0.01 and down == -4.0  # 1e-4 deg ~ 10 m
    np.testing.assert_array_equal(mission.goals_ned_m[1], [0.0, 5.0, -4.0])
    assert commands.command_ids == {0: "geo", 1: "geo"}


def test_speed_and_state_commands_reach_the_mission() -> None:
    mission, commands = handler()
    assert commands.handle(
        command('{"v":1,"id":"s","type":"set_speed","speed_mps":3}'), 1.0
    ).accepted
    fast = commands.handle(command('{"v":1,"id":"s2","type":"set_speed","speed_mps":18}'), 1.0)
    assert not fast.accepted and "outside (0, 15]" in fast.reason
    land = commands.handle(command('{"v":1,"id":"l","type":"land"}'), 1.0)
    assert not land.accepted and "idle" in land.reason
    takeoff = commands.handle(command('{"v":1,"id":"t","type":"takeoff","altitude_m":4}'), 1.0)
    assert takeoff.accepted and mission.takeoff_altitude_m == 4.0


def _grounded():
    from companion.mission import VehicleStatus

    return VehicleStatus(True, False, False, False, np.zeros(3))


def _fresh():
    from companion.mission import StageHealth

    return StageHealth(perception_fresh=True, planner_fresh=True)
