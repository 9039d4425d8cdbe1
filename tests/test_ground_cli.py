"""`wireavoid gcs`: an operator commands a vehicle and reads its status through a real broker."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import pytest
from ground_broker import LinkThread, Mosquitto, free_port
from typer.testing import CliRunner

from companion.cli import app
from companion.ground.params import GroundParams
from companion.ground.protocol import Ack, Command, GotoCommand, MissionCommand

runner = CliRunner()


class RefuseLanding:
    """Accepts every command but land, which it refuses as the mission would on the ground."""

    def __init__(self) -> None:
        self.commands: list[Command] = []

    def handle(self, command: Command, now_s: float) -> Ack:
        if command.type == "land":
            return Ack.reject(command, "cannot land while idle", now_s)
        self.commands.append(command)
        return Ack.accept(command, now_s)


@pytest.fixture
def vehicle(tmp_path: Path) -> Iterator[tuple[Mosquitto, LinkThread]]:
    broker = Mosquitto.open(tmp_path)
    broker.start()
    with LinkThread(GroundParams(broker_url=broker.url), RefuseLanding()) as link:
        yield broker, link
    broker.stop()


def gcs(broker: Mosquitto, *args: str) -> tuple[int, str]:
    result = runner.invoke(app, ["gcs", "--mqtt", broker.url, "--timeout", "3", *args])
    return result.exit_code, result.output


def test_gcs_commands_and_reads_the_status(
    vehicle: tuple[Mosquitto, LinkThread], tmp_path: Path
) -> None:
    broker, link = vehicle
    code, out = gcs(broker, "goto", "--north", "10", "--east", "0", "--down", "-3", "--speed", "2")
    assert code == 0 and out.startswith("accepted goto gcs-"), out
    code, out = gcs(broker, "goto", "--lat", "47.1", "--lon", "8.5", "--altitude", "12")
    assert code == 0, out
    plan = tmp_path / "plan.json"
    plan.write_text(
        json.dumps({"waypoints": [{"target": {"north_m": 5, "east_m": 5, "down_m": -4}}]})
    )
    assert gcs(broker, "mission", str(plan))[0] == 0
    for words in (["takeoff", "--altitude", "4"], ["hold"], ["resume"], ["abort"], ["rtl"]):
        assert gcs(broker, *words)[0] == 0, words
    assert gcs(broker, "set-speed", "3")[0] == 0
    code, out = gcs(broker, "land")
    assert code == 1 and "rejected land" in out and "cannot land while idle" in out
    commands = link.handler.commands  # type: ignore[attr-defined]
    goto, geo, mission = commands[:3]
    assert isinstance(goto, GotoCommand) and goto.target.ned_m.tolist() == [10.0, 0.0, -3.0]
    assert goto.speed_mps == 2.0 and isinstance(mission, MissionCommand)
    assert geo.target.lat_deg == 47.1  # type: ignore[union-attr]
    assert [c.type for c in commands[3:]] == [
        "takeoff",
        "hold",
        "resume",
        "abort",
        "rtl",
        "set_speed",
    ]
    code, out = gcs(broker, "status")
    assert code == 0 and out.startswith("drone1: online  mode hold"), out
    assert "position NED m 1.00, 2.00, -3.00" in out
    code, out = gcs(broker, "--json", "status")
    assert code == 0 and json.loads(out)["position_ned_m"] == [1.0, 2.0, -3.0]


def test_gcs_refuses_bad_input_before_sending_and_says_when_no_one_answers(
    vehicle: tuple[Mosquitto, LinkThread], tmp_path: Path
) -> None:
    broker, link = vehicle
    code, out = gcs(broker, "goto", "--north", "10", "--east", "0")
    assert code == 2 and "not sent: target.down_m: Field required" in out
    code, out = gcs(broker, "set-speed", "50")
    assert code == 2 and "speed_mps: Input should be less than or equal to 20" in out
    code, out = gcs(broker, "goto", "--north", "1", "--east", "0", "--down", "-3", "--lat", "4")
    assert code == 2 and "not both" in out
    raw = tmp_path / "raw.json"
    raw.write_text('{"v": 1, "id": "r1", "type": "hold", "extra": true}')
    code, out = gcs(broker, "send", str(raw))
    assert code == 1 and "rejected hold r1: unknown field extra" in out  # the vehicle's answer
    assert link.handler.commands == []  # type: ignore[attr-defined]
    code, out = gcs(broker, "--vehicle-id", "nobody", "--timeout", "0.5", "hold")
    assert code == 3 and "no ack from nobody in 0.5 s" in out
    nothing = runner.invoke(app, ["gcs", "--mqtt", f"mqtt://127.0.0.1:{free_port()}", "hold"])
    assert nothing.exit_code == 3 and "cannot reach mqtt://127.0.0.1:" in nothing.output
    unset = runner.invoke(app, ["gcs", "hold"])
    assert unset.exit_code == 2 and "no broker: pass --mqtt URL" in unset.output
