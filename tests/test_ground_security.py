"""Only an authenticated ground station may command: the shipped mosquitto configuration
(password file, ACL, TLS) run for real on loopback, with only its ports and file paths
changed (`ground_broker.secured`)."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Iterator
from pathlib import Path

import aiomqtt
import pytest
from ground_broker import PASSWORDS, Mosquitto, Recorder, make_ca, running, secured, until

from companion.ground.client import broker_client
from companion.ground.link import GroundLink
from companion.ground.params import GroundParams, MqttVersion
from companion.ground.protocol import Status, parse_command, vehicle_topics
from companion.ground.station import GroundStation

HOLD = b'{"v":1,"id":"%s","type":"hold"}'


@pytest.fixture
def broker(tmp_path: Path) -> Iterator[Mosquitto]:
    mosquitto = secured(tmp_path)
    mosquitto.start()
    yield mosquitto
    mosquitto.stop()


def account(broker: Mosquitto, folder: Path, user: str, **fields: object) -> GroundParams:
    """Connection settings for `user`, password in a file, over TLS unless told otherwise."""
    password = folder / f"{user}.password"
    password.write_text(PASSWORDS.get(user, "wrong") + "\n")
    values = {
        "broker_url": broker.tls_url,
        "tls_ca_file": str(broker.folder / "ca.crt"),
        "username": user,
        "password_file": str(password),
        **fields,
    }
    return GroundParams.model_validate(values)


@contextlib.asynccontextmanager
async def vehicle(params: GroundParams) -> AsyncIterator[tuple[GroundLink, Recorder]]:
    recorder = Recorder()
    async with running(params, recorder, status=lambda: Status(mode="idle")) as link:
        yield link, recorder


async def test_the_ground_station_commands_over_tls(broker: Mosquitto, tmp_path: Path) -> None:
    async with (
        vehicle(account(broker, tmp_path, "drone1")) as (_, recorder),
        GroundStation(account(broker, tmp_path, "gcs")) as gcs,
    ):
        status = await gcs.next_status(3.0)
        assert status is not None and status.online and status.mode == "idle"
        command = parse_command(HOLD % b"ok")
        ack = await gcs.send(command, 3.0)  # type: ignore[arg-type]
        assert ack is not None and ack.accepted
        assert [c.id for c in recorder.commands] == ["ok"]


async def test_unauthenticated_and_unauthorised_clients_cannot_command(
    broker: Mosquitto, tmp_path: Path
) -> None:
    async with (
        vehicle(account(broker, tmp_path, "drone1")) as (link, recorder),
        GroundStation(account(broker, tmp_path, "gcs")) as gcs,
    ):
        # no credentials at all, then a wrong password: the broker refuses the connection
        anonymous = GroundParams(broker_url=broker.tls_url, tls_ca_file=gcs.params.tls_ca_file)
        with pytest.raises(aiomqtt.MqttError, match=r"Not authorized"):
            async with GroundStation(anonymous):
                pass
        wrong = account(broker, tmp_path, "gcs", password_file=str(tmp_path / "guess"))
        (tmp_path / "guess").write_text("gcs-secret2\n")
        with pytest.raises(aiomqtt.MqttError, match=r"Not authorized|Bad user name or password"):
            async with GroundStation(wrong):
                pass
        # logged in, but not allowed to command drone1: the intruder, another vehicle, and
        # drone1 itself writing to its own cmd topic (over plain MQTT on localhost too)
        for user, fields in [
            ("intruder", {}),
            ("drone2", {}),
            ("drone1", {"broker_url": broker.url, "tls_ca_file": ""}),
        ]:
            async with GroundStation(account(broker, tmp_path, user, **fields)) as other:
                await other.publish(HOLD % user.encode())
                await other.publish(HOLD % (user + "-retained").encode(), retain=True)
        # the ground station's own command behind them all is the first the vehicle sees
        ack = await gcs.send(parse_command(HOLD % b"gcs"), 3.0)  # type: ignore[arg-type]
        assert ack is not None and ack.accepted
        assert [c.id for c in recorder.commands] == ["gcs"]
        assert [a.id for a in gcs.acks] == ["gcs"]
        assert link.health().commands_rejected == 0  # the broker dropped them, not the vehicle


async def test_no_one_but_the_vehicle_writes_its_status(broker: Mosquitto, tmp_path: Path) -> None:
    async with vehicle(account(broker, tmp_path, "drone1", status_rate_hz=2.0)):
        gcs = account(broker, tmp_path, "gcs")
        topic = vehicle_topics("drone1").status
        async with broker_client(gcs, identifier="watch", version=MqttVersion.V5) as watcher:
            await watcher.subscribe(topic, qos=1)
            spoof = Status(vehicle_id="drone1", mode="landed").model_dump_json().encode()
            for user in ("gcs", "drone2", "intruder"):
                params = account(broker, tmp_path, user)
                async with broker_client(params, identifier=user, version=MqttVersion.V5) as c:
                    await c.publish(topic, spoof, qos=1, retain=True)
            modes = []
            async with asyncio.timeout(5.0):
                async for message in watcher.messages:
                    modes.append(Status.model_validate_json(message.payload).mode)  # type: ignore[arg-type]
                    if len(modes) == 3:
                        break
        assert modes == ["idle", "idle", "idle"]  # the retained one, then the vehicle's own


async def test_tls_checks_the_broker_certificate(broker: Mosquitto, tmp_path: Path) -> None:
    other_ca, _ = make_ca(tmp_path, "other-ca")
    impostor_trust = account(broker, tmp_path, "drone1", tls_ca_file=str(other_ca))
    async with running(impostor_trust, connect=False) as link:
        await until(lambda: "CERTIFICATE_VERIFY_FAILED" in link.health().last_error, 5.0)
        assert not link.health().connected
    plain_url = f"mqtt://127.0.0.1:{broker.tls_port}"
    plain_to_tls = account(broker, tmp_path, "gcs", broker_url=plain_url, tls_ca_file="")
    with pytest.raises(aiomqtt.MqttError):
        async with GroundStation(plain_to_tls.model_copy(update={"connect_timeout_s": 1.0})):
            pass


async def test_a_missing_password_file_is_reported_and_retried(
    broker: Mosquitto, tmp_path: Path
) -> None:
    params = account(broker, tmp_path, "drone1", password_file=str(tmp_path / "later"))
    async with running(params.model_copy(update={"reconnect_max_s": 0.2}), connect=False) as link:
        await until(lambda: "FileNotFoundError" in link.health().last_error, 10.0)
        (tmp_path / "later").write_text(PASSWORDS["drone1"])  # the operator fixes it
        await until(lambda: link.health().connected, 10.0)
