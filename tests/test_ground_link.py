"""The vehicle's ground link against a real mosquitto on loopback: acks, status, events, the
Last Will, refusals, the geofence, a broker restart, MQTT 3.1.1."""

from __future__ import annotations

import asyncio
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import aiomqtt
import numpy as np
import pytest
from ground_broker import CLOCK, Mosquitto, Mqtt311Proxy, Recorder, hold_status, running, until

from companion.ground.geofence import Geofence
from companion.ground.link import GroundLink, reconnect_delay_s
from companion.ground.params import GeofenceParams, GroundParams
from companion.ground.protocol import (
    Ack,
    Command,
    Event,
    Status,
    parse_command,
)
from companion.ground.station import GroundStation


@pytest.fixture
def broker(tmp_path: Path) -> Iterator[Mosquitto]:
    mosquitto = Mosquitto.open(tmp_path)
    mosquitto.start()
    yield mosquitto
    mosquitto.stop()


def cmd(text: str) -> Command:
    command = parse_command(text.encode())
    assert not hasattr(command, "reason"), command
    return command  # type: ignore[return-value]


GOTO = '{"v":1,"id":"%s","type":"goto","target":{"north_m":%s,"east_m":0,"down_m":-3}}'


async def test_commands_round_trip_with_one_ack_each(broker: Mosquitto) -> None:
    params = GroundParams(broker_url=broker.url)
    recorder = Recorder()
    commands = [
        cmd('{"v":1,"id":"t1","type":"takeoff","altitude_m":3}'),
        cmd(GOTO % ("g1", 10)),
        cmd(
            '{"v":1,"id":"m1","type":"mission","waypoints":[{"target":{"lat_deg":47,"lon_deg":8,'
            '"altitude_m":5},"speed_mps":2,"yaw":"goal"}]}'
        ),
        *(cmd(f'{{"v":1,"id":"{k}1","type":"{k}"}}') for k in ("hold", "resume", "abort")),
        *(cmd(f'{{"v":1,"id":"{k}1","type":"{k}"}}') for k in ("land", "rtl")),
        cmd('{"v":1,"id":"s1","type":"set_speed","speed_mps":3.5}'),
    ]
    async with running(params, recorder) as link, GroundStation(params) as station:
        status = await station.next_status(3.0)  # the retained one, at once
        assert status is not None and status.online and status.vehicle_id == "drone1"
        assert status.mode == "hold" and status.position_ned_m == (1.0, 2.0, -3.0)
        assert status.stages["perception"].latency_ms == 45.0 and status.stamp_s is not None
        for command in commands:
            ack = await station.send(command, 3.0)
            assert ack is not None and ack.accepted, ack
            assert (ack.id, ack.command) == (command.id, command.type)
        assert recorder.commands == commands
        await asyncio.sleep(0.1)
        assert len(station.acks) == len(commands)  # exactly one each
        health = link.health()
        assert (health.commands_accepted, health.commands_rejected) == (len(commands), 0)
        assert health.protocol == "5" and health.last_command_s is not None
        assert health.lost_for_s(CLOCK.now_s()) == 0.0


async def test_bad_commands_are_acked_as_rejected_and_change_nothing(broker: Mosquitto) -> None:
    params = GroundParams(broker_url=broker.url, max_payload_bytes=4096)
    recorder = Recorder()
    async with running(params, recorder) as link, GroundStation(params) as station:
        bad_json = await station.send_raw(b'{"v":1,"id":"x1","type":')
        assert bad_json is not None and bad_json.id is None and not bad_json.accepted
        assert bad_json.reason.startswith("not valid JSON")
        nan = await station.send_raw(
            b'{"v":1,"id":"x2","type":"goto","target":{"north_m":NaN,"east_m":0,"down_m":-3}}'
        )
        assert nan is not None and nan.id == "x2" and not nan.accepted
        assert nan.reason == "target.north_m: NaN and infinities are not allowed"
        typed = await station.send_raw(b'{"v":1,"id":"x3","type":"takeoff","altitude_m":"3"}')
        assert typed is not None and typed.id == "x3" and "altitude_m" in typed.reason
        oversized = await station.send_raw(
            b'{"v":1,"id":"x4","type":"hold","pad":"' + b"x" * 5000 + b'"}'
        )
        assert oversized is not None and "exceeds the limit of 4096 bytes" in oversized.reason
        await station.publish((GOTO % ("x5", 1)).encode(), retain=True)
        retained = await station.ack_for("x5", 3.0)
        assert retained is not None and not retained.accepted
        assert "retained commands are refused" in retained.reason
        first = await station.send(cmd(GOTO % ("x6", 1)))
        again = await station.send_raw((GOTO % ("x6", 2)).encode())
        assert first is not None and first.accepted
        assert again is not None and not again.accepted and "was used before" in again.reason
        assert [c.id for c in recorder.commands] == ["x6"]  # nothing else got through
        assert link.health().commands_rejected == 6


async def test_a_failing_handler_rejects_the_command_and_the_link_goes_on(
    broker: Mosquitto,
) -> None:
    class Flaky:
        calls = 0

        def handle(self, command: Command, now_s: float) -> Ack:
            self.calls += 1
            if self.calls == 1:
                raise RuntimeError("bug in the mission")
            return Ack.reject(command, "not now: landing", now_s).model_copy(
                update={"id": "forged", "command": "forged"}
            )

    params = GroundParams(broker_url=broker.url)
    async with running(params, Flaky()) as link, GroundStation(params) as station:
        crashed = await station.send(cmd('{"v":1,"id":"h1","type":"hold"}'))
        assert crashed is not None and not crashed.accepted
        assert crashed.reason == "internal error handling the command (RuntimeError)"
        refused = await station.send(cmd('{"v":1,"id":"h2","type":"hold"}'))
        assert refused is not None and (refused.id, refused.command) == ("h2", "hold")
        assert refused.reason == "not now: landing"
        assert link.health().connected


class FenceHandler:
    """Accepts a command when the geofence does (from the vehicle's position)."""

    def __init__(self, fence: Geofence) -> None:
        self.fence = fence
        self.accepted: list[Command] = []

    def handle(self, command: Command, now_s: float) -> Ack:
        problem = self.fence.command_violation(command, np.array([0.0, 0.0, -3.0]), None)
        if problem:
            return Ack.reject(command, problem, now_s)
        self.accepted.append(command)
        return Ack.accept(command, now_s)


async def test_goals_outside_the_geofence_are_rejected(broker: Mosquitto) -> None:
    params = GroundParams(broker_url=broker.url)
    handler = FenceHandler(Geofence(GeofenceParams(radius_m=50.0, max_altitude_m=20.0)))
    async with running(params, handler), GroundStation(params) as station:
        far = await station.send(cmd(GOTO % ("far", 60)))
        assert far is not None and not far.accepted
        assert far.reason.startswith("goal: (60.0, 0.0) m is 60.0 m from the fence centre")
        high = await station.send(cmd('{"v":1,"id":"hi","type":"takeoff","altitude_m":30}'))
        assert high is not None and "over the fence ceiling of 20.0 m" in high.reason
        near = await station.send(cmd(GOTO % ("near", 40)))
        assert near is not None and near.accepted
        assert [c.id for c in handler.accepted] == ["near"]


async def test_status_flows_at_its_rate_and_events_are_published(broker: Mosquitto) -> None:
    params = GroundParams(broker_url=broker.url, status_rate_hz=2.0)
    failing = {"now": False}

    def status() -> Status:
        if failing["now"]:
            raise ValueError("stage table broken")
        return hold_status()

    async with running(params, status=status) as link, GroundStation(params) as station:
        await station.next_status(2.0)
        start = station.status_count
        await asyncio.sleep(2.0)
        assert 3 <= station.status_count - start <= 5  # 2 Hz
        link.publish_event(Event(kind="transition", state="navigate", text="to goal 0"))
        link.publish_event(Event(kind="failsafe", severity="warning", text="perception stale"))
        assert await station.wait_for(lambda: len(station.events) >= 2, 3.0)
        received = [(e.kind, e.severity, e.state, e.text) for e in station.events]
        assert received == [
            ("transition", "info", "navigate", "to goal 0"),
            ("failsafe", "warning", None, "perception stale"),
        ]
        assert all(e.vehicle_id == "drone1" and e.stamp_s is not None for e in station.events)
        failing["now"] = True
        bare = await station.next_status(2.0)
        assert bare is not None and bare.online and bare.mode is None  # still flowing
        failing["now"] = False
        assert (await station.next_status(2.0)).mode == "hold"  # type: ignore[union-attr]


async def test_events_pushed_while_the_broker_is_away_are_delivered_later(
    broker: Mosquitto,
) -> None:
    params = GroundParams(broker_url=broker.url, reconnect_min_s=0.5)
    async with running(params) as link, GroundStation(params) as station:
        # a second client with the vehicle's client id takes its session over: the link drops
        async with aiomqtt.Client("127.0.0.1", broker.port, identifier=params.mqtt_client_id):
            await until(lambda: not link.health().connected, 3.0)
        for i in range(3):
            link.publish_event(Event(kind="transition", text=f"while away {i}"))
        await until(lambda: link.health().connected, 5.0)
        assert await station.wait_for(
            lambda: sum("while away" in e.text for e in station.events) == 3, 3.0
        )
        texts = [e.text for e in station.events if "while away" in e.text]
        assert texts == ["while away 0", "while away 1", "while away 2"]
        assert link.health().connections == 2 and link.health().events_dropped == 0


async def test_a_broker_restart_is_survived_without_stalling_the_loop(
    broker: Mosquitto,
) -> None:
    params = GroundParams(broker_url=broker.url, reconnect_min_s=0.2, reconnect_max_s=1.0)
    recorder = Recorder()
    async with running(params, recorder) as link:
        lateness_s: list[float] = []

        async def ticker() -> None:  # stands in for the flight loop: 100 Hz
            while True:
                due = time.monotonic() + 0.01
                await asyncio.sleep(0.01)
                lateness_s.append(time.monotonic() - due)

        tick = asyncio.create_task(ticker())
        broker.stop()
        await until(lambda: not link.health().connected, 5.0)
        lost_at = CLOCK.now_s()
        await asyncio.sleep(1.5)  # several reconnection attempts fail meanwhile
        assert link.health().lost_for_s(CLOCK.now_s()) >= 1.5
        broker.start()
        await until(lambda: link.health().connected, 5.0)
        tick.cancel()
        back_after_s = CLOCK.now_s() - lost_at
        assert back_after_s < 1.5 + 1.5  # at most one reconnect_max_s after the broker is back
        assert max(lateness_s) < 0.1, f"the event loop stalled {max(lateness_s):.3f} s"
        async with GroundStation(params) as station:
            status = await station.next_status(3.0)
            assert status is not None and status.online
            ack = await station.send(cmd(GOTO % ("after", 5)))
            assert ack is not None and ack.accepted
        assert [c.id for c in recorder.commands] == ["after"]
        assert link.health().connections == 2


LINK_SCRIPT = """
import asyncio, sys
from companion.clock import WallClock
from companion.ground.link import GroundLink
from companion.ground.params import GroundParams
from companion.ground.protocol import Ack, Status

class Accept:
    def handle(self, command, now_s):
        return Ack.accept(command, now_s)

async def main():
    link = GroundLink(GroundParams(broker_url=sys.argv[1]), WallClock(), Accept(), Status)
    task = asyncio.ensure_future(link.run())
    while not link.health().connected:
        await asyncio.sleep(0.01)
    print("connected", flush=True)
    await task

asyncio.run(main())
"""


async def test_the_last_will_marks_a_vehicle_that_drops_off_offline(broker: Mosquitto) -> None:
    params = GroundParams(broker_url=broker.url)
    vehicle = subprocess.Popen(
        [sys.executable, "-c", LINK_SCRIPT, broker.url], stdout=subprocess.PIPE, text=True
    )
    try:
        assert vehicle.stdout is not None and vehicle.stdout.readline() == "connected\n"
        async with GroundStation(params) as station:
            online = await station.next_status(3.0)
            assert online is not None and online.online
            vehicle.send_signal(signal.SIGKILL)  # no DISCONNECT: the broker sends the will
            assert await station.wait_for(lambda: not station.status.online, 5.0)  # type: ignore[union-attr]
    finally:
        vehicle.kill()
        vehicle.wait()
    async with GroundStation(params) as late:  # and keeps it for stations that come later
        offline = await late.next_status(3.0)
        assert offline is not None and not offline.online and offline.vehicle_id == "drone1"


async def test_a_clean_stop_leaves_the_vehicle_marked_offline(broker: Mosquitto) -> None:
    params = GroundParams(broker_url=broker.url)
    async with GroundStation(params) as station:
        async with running(params):
            assert await station.wait_for(
                lambda: station.status is not None and station.status.online, 3.0
            )
        assert await station.wait_for(lambda: not station.status.online, 3.0)  # type: ignore[union-attr]
        last = station.status
        assert last is not None and last.mode == hold_status().mode  # how it ended, kept
        assert last.position_ned_m == hold_status().position_ned_m


async def test_mqtt_311_forced_and_as_the_fallback_of_auto(broker: Mosquitto) -> None:
    forced = GroundParams(broker_url=broker.url, mqtt_version="3.1.1")
    async with running(forced) as link, GroundStation(forced) as station:
        assert link.health().protocol == "3.1.1"
        ack = await station.send(cmd('{"v":1,"id":"a","type":"hold"}'))
        assert ack is not None and ack.accepted
    async with Mqtt311Proxy(broker.port) as old_broker:
        auto = GroundParams(broker_url=f"mqtt://127.0.0.1:{old_broker.port}")
        async with running(auto) as link, GroundStation(auto) as station:
            assert old_broker.refused_v5 >= 1 and link.health().protocol == "3.1.1"
            ack = await station.send(cmd('{"v":1,"id":"b","type":"hold"}'))
            assert ack is not None and ack.accepted
        only_5 = GroundParams(broker_url=f"mqtt://127.0.0.1:{old_broker.port}", mqtt_version="5")
        async with running(only_5, connect=False) as link:
            await until(lambda: "Unsupported protocol version" in link.health().last_error, 3.0)
            assert not link.health().connected


def test_reconnect_backoff_doubles_up_to_its_maximum() -> None:
    params = GroundParams(reconnect_min_s=0.5, reconnect_max_s=10.0)
    delays = [reconnect_delay_s(n, params) for n in range(8)]
    assert delays == [0.5, 1.0, 2.0, 4.0, 8.0, 10.0, 10.0, 10.0]
    assert reconnect_delay_s(10_000, params) == 10.0


def test_a_disabled_ground_link_does_not_start() -> None:
    with pytest.raises(ValueError, match="broker_url is empty"):
        GroundLink(GroundParams(), CLOCK, Recorder(), Status)
