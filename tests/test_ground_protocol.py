"""The ground-station protocol (pure): commands parse strictly, every refusal says why, the
parser never raises on hostile input, and outgoing messages carry unknowns as null."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from ground_payloads import payloads
from hypothesis import given, settings
from pydantic import ValidationError

from companion.config import Settings, load_settings
from companion.ground.options import apply_ground_options
from companion.ground.params import GroundParams, broker_address
from companion.ground.protocol import (
    Ack,
    GeoTarget,
    GotoCommand,
    MissionCommand,
    NedTarget,
    Rejection,
    SetSpeedCommand,
    Status,
    TakeoffCommand,
    offline_status,
    parse_command,
    vehicle_topics,
)
from planning.params import YawPolicy


def command(**fields: object) -> bytes:
    return json.dumps({"v": 1, "id": "c-1", **fields}).encode()


GOTO = {"type": "goto", "target": {"north_m": 10, "east_m": 0, "down_m": -3}}


def test_every_command_type_parses() -> None:
    goto = parse_command(command(**GOTO, speed_mps=2, yaw="fixed", yaw_rad=1.5))
    assert isinstance(goto, GotoCommand)
    assert isinstance(goto.target, NedTarget)
    np.testing.assert_array_equal(goto.target.ned_m, [10.0, 0.0, -3.0])
    assert (goto.speed_mps, goto.yaw, goto.yaw_rad) == (2.0, YawPolicy.FIXED, 1.5)
    geo = parse_command(
        command(type="goto", target={"lat_deg": 47.4, "lon_deg": 8.5, "altitude_m": 12})
    )
    assert isinstance(geo, GotoCommand) and isinstance(geo.target, GeoTarget)
    assert geo.target.altitude_m == 12.0 and geo.speed_mps is None and geo.yaw is None
    takeoff = parse_command(command(type="takeoff", altitude_m=3))
    assert isinstance(takeoff, TakeoffCommand) and takeoff.altitude_m == 3.0
    mission = parse_command(
        command(type="mission", waypoints=[{"target": GOTO["target"]}, {"target": GOTO["target"]}])
    )
    assert isinstance(mission, MissionCommand) and len(mission.waypoints) == 2
    speed = parse_command(command(type="set_speed", speed_mps=4.5))
    assert isinstance(speed, SetSpeedCommand) and speed.speed_mps == 4.5
    for kind in ("hold", "resume", "land", "rtl", "abort"):
        parsed = parse_command(command(type=kind))
        assert not isinstance(parsed, Rejection), parsed
        assert (parsed.type, parsed.id) == (kind, "c-1")


@pytest.mark.parametrize(
    ("payload", "command_id", "reason"),
    [
        (b'{"v": 1, "id": "x", "type": "hold"', None, "not valid JSON"),
        (b"\xff\xfe garbage", None, "not valid JSON"),
        (b"[1, 2]", None, "a command is a JSON object, got an array"),
        (command(type="hold", extra=1), "c-1", "unknown field extra"),
        (command(type="takeoff", altitude_m="3"), "c-1", "altitude_m: Input should be a valid"),
        (command(type="takeoff", altitude_m=True), "c-1", "altitude_m: Input should be a valid"),
        (command(type="takeoff", altitude_m=0), "c-1", "altitude_m: Input should be greater"),
        (command(type="set_speed", speed_mps=25), "c-1", "speed_mps: Input should be less"),
        (
            command(type="goto", target={"north_m": 1e999, "east_m": 0, "down_m": -3}),
            "c-1",
            "target.north_m: NaN and infinities are not allowed",
        ),
        (
            b'{"v":1,"id":"n","type":"set_speed","speed_mps":NaN}',
            "n",
            "speed_mps: NaN and infinities are not allowed",
        ),
        (
            command(type="goto", target={"lat_deg": 95, "lon_deg": 0, "altitude_m": 3}),
            "c-1",
            "target.lat_deg: Input should be less than or equal to 90",
        ),
        (
            command(type="goto", target={"lat_deg": 45, "lon_deg": 0, "down_m": -3}),
            "c-1",
            "target.altitude_m: Field required; unknown field target.down_m",
        ),
        (command(**GOTO, yaw="fixed"), "c-1", 'yaw_rad is required with yaw "fixed"'),
        (command(**GOTO, yaw="sideways"), "c-1", "yaw: Input should be 'motion', 'goal' or"),
        (command(type="mission", waypoints=[]), "c-1", "waypoints: List should have at least 1"),
        (
            command(type="mission", waypoints=[{"target": GOTO["target"]}] * 201),
            "c-1",
            "waypoints: List should have at most 200",
        ),
        (json.dumps({"id": "a", "type": "hold"}).encode(), "a", "no protocol version: this v"),
        (json.dumps({"v": 2, "id": "a", "type": "hold"}).encode(), "a", "protocol version 2:"),
        (command(type="fly"), "c-1", "unknown type 'fly'; expected one of: takeoff, goto"),
        (command(), "c-1", "no command type; expected one of"),
        (json.dumps({"v": 1, "id": "a b", "type": "hold"}).encode(), None, "id: use 1-64"),
        (json.dumps({"v": 1, "type": "hold"}).encode(), None, "id: Field required"),
    ],
)
def test_bad_input_is_refused_with_a_reason(
    payload: bytes, command_id: str | None, reason: str
) -> None:
    rejection = parse_command(payload)
    assert isinstance(rejection, Rejection)
    assert rejection.command_id == command_id
    assert reason in rejection.reason, rejection.reason


def test_payload_size_limit_is_checked_before_reading() -> None:
    big = command(type="hold", pad="x" * 40_000)
    rejection = parse_command(big)
    assert isinstance(rejection, Rejection)
    assert rejection.reason == f"payload of {len(big)} bytes exceeds the limit of 32768 bytes"
    small_limit = parse_command(command(type="hold"), max_payload_bytes=10)
    assert isinstance(small_limit, Rejection) and "limit of 10 bytes" in small_limit.reason


def test_hostile_field_names_do_not_bloat_or_break_the_reason() -> None:
    rejection = parse_command(command(type="hold", **{"\x1b[31m" + "k" * 5000: 1}))
    assert isinstance(rejection, Rejection)
    assert len(rejection.reason) < 100 and "\x1b" not in rejection.reason
    assert rejection.reason.startswith("unknown field \\x1b[31mkkk")
    deep = parse_command(b'{"v":1,"id":"d","type":"hold","x":' + b"[" * 5000 + b"]" * 5000 + b"}")
    assert isinstance(deep, Rejection) and "recursion limit" in deep.reason


FINITE_BOUND = 100_000.0


def _numbers(value: object) -> list[float]:
    if isinstance(value, dict):
        return [x for v in value.values() for x in _numbers(v)]
    if isinstance(value, list):
        return [x for v in value for x in _numbers(v)]
    return [float(value)] if isinstance(value, (int, float)) and not isinstance(value, bool) else []


@settings(max_examples=400, deadline=None, database=None)
@given(payloads())
def test_fuzz_the_parser_never_raises_and_accepts_only_valid_commands(
    case: tuple[bytes, str],
) -> None:
    payload, expected = case
    parsed = parse_command(payload)  # must not raise
    if expected == "valid":
        assert not isinstance(parsed, Rejection), (payload, parsed)
    if expected == "invalid":
        assert isinstance(parsed, Rejection), payload
    if isinstance(parsed, Rejection):
        assert 0 < len(parsed.reason) <= 400
        return
    dumped = json.loads(parsed.model_dump_json())
    assert all(math.isfinite(x) and abs(x) <= FINITE_BOUND for x in _numbers(dumped))
    assert parse_command(parsed.model_dump_json().encode()) == parsed


def test_acks_and_status_serialise_unknowns_as_null() -> None:
    goto = parse_command(command(**GOTO))
    assert isinstance(goto, GotoCommand)
    ack = Ack.accept(goto, 12.5)
    assert json.loads(ack.model_dump_json()) == {
        "v": 1,
        "id": "c-1",
        "command": "goto",
        "accepted": True,
        "reason": "",
        "stamp_s": 12.5,
    }
    refused = Ack.reject(Rejection(None, None, "x" * 1000), "x" * 1000, 1.0)
    assert refused.id is None and len(refused.reason) == 400
    status = Status(
        position_ned_m=np.array([1.0, 2.0, math.nan]),
        velocity_ned_mps=np.array([0.5, 0.0, 0.0]),
        yaw_rad=math.inf,
        battery={"voltage_v": 12.4, "remaining_frac": math.nan},
    )
    text = status.model_dump_json()
    assert "NaN" not in text and "Infinity" not in text
    back = Status.model_validate_json(text)
    assert back.position_ned_m is None and back.velocity_ned_mps == (0.5, 0.0, 0.0)
    assert back.yaw_rad is None and back.battery is not None
    assert back.battery.voltage_v == 12.4 and back.battery.remaining_frac is None
    offline = json.loads(offline_status("drone1").model_dump_json())
    assert offline["online"] is False and offline["vehicle_id"] == "drone1"
    newer = Status.model_validate_json(b'{"v": 1, "online": true, "field_of_v2": 3}')
    assert newer.online  # a station reads a newer vehicle's status


def test_topic_scheme() -> None:
    topics = vehicle_topics("drone1")
    assert (topics.cmd, topics.ack, topics.status, topics.events) == (
        "wireavoid/drone1/cmd",
        "wireavoid/drone1/ack",
        "wireavoid/drone1/status",
        "wireavoid/drone1/events",
    )
    for bad in ("", "a/b", "+", "#", "x" * 65):
        with pytest.raises(ValueError, match="vehicle id"):
            vehicle_topics(bad)


def test_ground_params_validate_the_connection() -> None:
    assert not load_settings().ground.enabled  # nothing connects unless a broker is set
    assert broker_address("mqtt://gcs.local") == broker_address("mqtt://gcs.local:1883")
    assert broker_address("mqtts://gcs.local").port == 8883
    assert broker_address("mqtts://gcs.local:9000").tls
    for url, message in [
        ("tcp://h", "scheme"),
        ("mqtt://user:pw@h", "no credentials"),
        ("mqtt://h/topic", "nothing else"),
        ("mqtt://:1883", "no host"),
        ("mqtt://h:99999", "Port out of range"),
    ]:
        with pytest.raises(ValidationError, match=message):
            GroundParams(broker_url=url)
    with pytest.raises(ValidationError, match="use mqtts://"):
        GroundParams(broker_url="mqtt://h", tls_ca_file="/ca.crt")
    with pytest.raises(ValidationError, match="go together"):
        GroundParams(broker_url="mqtts://h", tls_cert_file="/c.crt")
    with pytest.raises(ValidationError, match="without a username"):
        GroundParams(broker_url="mqtt://h", password_file="/pw")
    with pytest.raises(ValidationError, match="vehicle_id"):
        GroundParams(vehicle_id="a/b")
    assert GroundParams(vehicle_id="d7").mqtt_client_id == "wireavoid-d7"


def test_fly_and_sim_options_apply_to_settings() -> None:
    settings = Settings()
    assert apply_ground_options(settings, None, None) is settings
    applied = apply_ground_options(settings, "mqtts://gcs.local:8883", "d2")
    assert (applied.ground.broker_url, applied.ground.vehicle_id) == (
        "mqtts://gcs.local:8883",
        "d2",
    )
    assert applied.mapping == settings.mapping and settings.ground.broker_url == ""
    with pytest.raises(ValidationError, match="scheme"):
        apply_ground_options(settings, "http://x", None)
