"""mqtt_restart: the ground link's broker (a real mosquitto the simulation runs itself) stops
and starts again on the same port mid-flight. The flight neither collides nor is interrupted
(a lost ground link only matters as `mission.ground_lost_action` says: continue), the link
reconnects at its backoff's next attempt, the status flows again and the mission completes."""

from __future__ import annotations

import asyncio
import json
import socket
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from companion.cli import app
from companion.cli.settings import SimSettings
from companion.cli.sim_faults import FaultAddon
from companion.ground.link import reconnect_delay_s
from companion.ground.params import GroundParams
from hil.broker import Mosquitto
from hil.faults import BrokerRestart, FaultSchedule, FaultSpec

DATA = Path(__file__).parent / "data"
FIELD = Path(__file__).parents[1] / "hil" / "world" / "examples" / "fault-field.toml"


def _listening(port: int) -> bool:
    with socket.socket() as s:
        return s.connect_ex(("127.0.0.1", port)) == 0


def test_the_broker_stops_when_the_fault_begins_and_listens_again_when_it_ends(
    tmp_path: Path,
) -> None:
    now = [0.0]
    schedule = FaultSchedule([FaultSpec(kind="mqtt_restart", start_s=1.0)], lambda: now[0])
    schedule.start(0.0)
    broker = Mosquitto.open(tmp_path)
    broker.start()
    restart = BrokerRestart(schedule, broker)
    log = schedule.logs[0]
    try:
        asyncio.run(restart.tick())
        assert _listening(broker.port) and log.affected == 0
        now[0] = 1.5
        asyncio.run(restart.tick())
        assert not _listening(broker.port) and not broker.running
        assert log.first_effect_s == 1.5 and log.affected == 1
        now[0] = 3.0  # the fault's 2 s are over: the same port again
        asyncio.run(restart.tick())
        assert _listening(broker.port) and log.cleared_s == 3.0
    finally:
        broker.stop()
    assert not _listening(broker.port)


def test_the_fault_runs_its_own_broker_and_leaves_a_configured_one_alone() -> None:
    own = FaultAddon([FaultSpec(kind="mqtt_restart")])
    try:
        settings = own.settings(SimSettings())
        assert own.restarts_broker and settings.ground.broker_url.startswith("mqtt://127.0.0.1:")
        port = int(settings.ground.broker_url.rsplit(":", 1)[1])
        assert _listening(port)
    finally:
        own.release()
    assert not _listening(port)
    configured = FaultAddon([FaultSpec(kind="mqtt_restart")])
    given = SimSettings(ground=GroundParams(broker_url="mqtt://127.0.0.1:1"))
    assert configured.settings(given) is given and not configured.restarts_broker
    assert "not the simulation's to restart" in configured.broker_note


def test_the_matrix_skips_the_broker_restart_when_given_another_broker() -> None:
    result = CliRunner().invoke(
        app, ["faults", "--only", "mqtt_restart", "--mqtt", "mqtt://127.0.0.1:1", "--json"]
    )
    summary = json.loads(result.stdout)
    assert summary["skipped"] == ["mqtt_restart"] and summary["faults"] == []
    assert result.exit_code == 1 and not summary["all_ok"]


@pytest.mark.slow
@pytest.mark.timeout(240)
def test_a_broker_restart_mid_flight_neither_interrupts_it_nor_silences_the_status(
    tmp_path: Path,
) -> None:
    """`sim --world` with a `[[fault]]` table: the fault field's first wire, the goal 8 m past
    it, the broker down for 2 s from 2 s after offboard engaged; the small camera."""
    text = FIELD.read_text()
    field = text[: text.index("[[pole]]\nposition_ne_m = [28.0")]  # poles and wire at 12 m
    world = tmp_path / "short-field.toml"
    world.write_text(
        field.replace("[220.0, 0.0, -3.0]", "[20.0, 0.0, -3.0]")
        + '[[fault]]\nkind = "mqtt_restart"\nstart_s = 2.0\nduration_s = 2.0\n'
    )
    assert "[20.0, 0.0, -3.0]" in world.read_text()
    config = tmp_path / "camera.toml"
    # The small camera's 64x48 colour image is below the CNN's trained scale: at the weights'
    # threshold its false wire pixels lay the 4-20 m wire prior over the goal, which then
    # counts as unreachable. A stricter mask lets this short flight finish its mission.
    config.write_text(
        (DATA / "tiny-camera.toml").read_text().replace("timeout_s = 18.0", "timeout_s = 60.0")
        + "\n[perception]\nmask_threshold_from_weights = false\nconfidence_threshold = 0.9999\n"
    )
    result = CliRunner().invoke(
        app,
        ["sim", "--world", str(world), "--config", str(config), "--json",
         "--out", str(tmp_path / "flight.png")],
    )  # fmt: skip
    flight = json.loads(result.stdout.strip().splitlines()[-1])
    (row,) = flight["faults"]
    print(json.dumps(row, indent=1))  # the row, for the log of a failure
    assert result.exit_code == 0, flight
    assert flight["success"] and flight["collisions"] == 0 and flight["mission_completed"]
    assert flight["mission_state"] == "landed" and all(flight["goals_reached"])
    assert row["name"] == "mqtt_restart" and row["injected"] and row["ok"], row
    assert row["collisions"] == 0 and not row["interrupted"] and not row["reaction_expected"]
    assert row["ground_lost_action"] == "continue"
    # the closed connection is noticed at once, not after 1.5 keepalives (7.5 s)
    assert row["broker_down_s"] >= 2.0 and row["detected_after_s"] < 0.5
    # back at the backoff's next attempt (0.5, 1, 2 s ... apart: 3.5 s after the loss)
    attempts_s = np.cumsum([reconnect_delay_s(i, GroundParams()) for i in range(8)])
    outage_s = row["broker_down_s"] - (row["detected_after_s"] - row["detectable_after_s"])
    next_attempt_s = float(attempts_s[attempts_s >= outage_s][0]) - outage_s
    assert row["reconnected_after_s"] <= next_attempt_s + 0.5, (next_attempt_s, row)
    # a ground station hears the vehicle within one status period of the reconnection
    assert row["reconnected_after_s"] <= row["status_resumed_after_s"]
    assert row["status_resumed_after_s"] <= row["reconnected_after_s"] + 0.5 + 0.1
    assert row["recovered"] and row["statuses_received"] > 10
