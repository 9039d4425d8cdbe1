"""What a ground station (QGroundControl) asks of the hil vehicle on connect, answered as PX4 does.

A pymavlink client in lockstep: mission/geofence/rally lists, REQUEST_MESSAGE of the protocol
version, component metadata, modes and flight information, PING, TIMESYNC, the component
metadata over MAVFTP, PX4's 888 parameters (integers byte-wise), the streamed display
messages, and PX4's events with their definitions.
"""

from __future__ import annotations

import json
import lzma
import socket
import struct
from collections.abc import Iterator
from typing import Any

import pytest

from hil.mavlink import extra_messages as xm
from hil.mavlink import ftp
from hil.mavlink.events import DEFINITIONS
from hil.mavlink.server import VehicleServer, mavlink, mavutil
from hil.vehicle.params import VehicleSimParams
from hil.vehicle.px4_modes import Px4Mode


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Gcs:
    """A ground station on the vehicle's link (sysid 255, compid 190)."""

    def __init__(self, port: int, server: VehicleServer) -> None:
        self.server = server
        self.conn = mavutil.mavlink_connection(
            f"udpin:127.0.0.1:{port}", source_system=255, source_component=190
        )

    def advance(self, dt_s: float = 0.02) -> list[Any]:
        out: list[Any] = []
        remaining = dt_s
        while remaining > 1e-9:
            self.server.advance(min(0.1, remaining))
            while (msg := self.conn.recv_msg()) is not None:
                if msg.get_type() != "BAD_DATA":
                    out.append(msg)
            remaining -= 0.1
        return out

    def command(self, cmd: int, *params: float) -> tuple[int, list[Any]]:
        p = [*params, *([0.0] * (7 - len(params)))]
        self.conn.mav.command_long_send(1, 1, cmd, 0, *p)
        messages = self.advance(0.02)
        acks = [m for m in messages if m.get_type() == "COMMAND_ACK" and m.command == cmd]
        assert len(acks) == 1
        return acks[0].result, messages


@pytest.fixture
def gcs() -> Iterator[Gcs]:
    port = _free_udp_port()
    server = VehicleServer(VehicleSimParams(arm_denied_after_boot_s=1.5), port, lockstep=True)
    client = Gcs(port, server)
    server.start()
    client.advance(0.02)
    try:
        yield client
    finally:
        server.stop()
        client.conn.close()
    assert not server.message_errors


def test_mission_fence_and_rally_lists_are_empty(gcs: Gcs) -> None:
    for mission_type in (
        mavlink.MAV_MISSION_TYPE_MISSION,
        mavlink.MAV_MISSION_TYPE_FENCE,
        mavlink.MAV_MISSION_TYPE_RALLY,
    ):
        gcs.conn.mav.mission_request_list_send(1, 1, mission_type)
        counts = [m for m in gcs.advance() if m.get_type() == "MISSION_COUNT"]
        assert [(c.count, c.mission_type, c.target_system) for c in counts] == [
            (0, mission_type, 255)
        ]
    gcs.conn.mav.mission_count_send(1, 1, 0, mavlink.MAV_MISSION_TYPE_MISSION)
    acks = [m for m in gcs.advance() if m.get_type() == "MISSION_ACK"]
    assert acks[0].type == mavlink.MAV_MISSION_ACCEPTED


def test_requested_messages_qgc_asks_for(gcs: Gcs) -> None:
    def requested(msg_id: int, param2: float = 0.0) -> list[Any]:
        result, messages = gcs.command(mavlink.MAV_CMD_REQUEST_MESSAGE, msg_id, param2)
        assert result == mavlink.MAV_RESULT_ACCEPTED
        return messages

    version = [xm.parse_unknown(m) for m in requested(xm.PROTOCOL_VERSION.msg_id)]
    assert [v[1]["version"] for v in version if v and v[0] is xm.PROTOCOL_VERSION] == [200]
    metadata = [xm.parse_unknown(m) for m in requested(xm.COMPONENT_METADATA.msg_id)]
    uris = [v[1]["uri"].rstrip(b"\0") for v in metadata if v and v[0] is xm.COMPONENT_METADATA]
    assert uris == [b"mftp://etc/extras/component_general.json.xz"]
    modes = [
        m
        for m in requested(mavlink.MAVLINK_MSG_ID_AVAILABLE_MODES)
        if m.get_type() == "AVAILABLE_MODES"
    ]
    assert {m.mode_name for m in modes} == {"Hold", "Takeoff", "Land", "Return", "Offboard"}
    assert {m.custom_mode for m in modes} == {mode.custom_mode for mode in Px4Mode}
    assert all(m.number_modes == 5 for m in modes)
    current = [
        m for m in requested(mavlink.MAVLINK_MSG_ID_CURRENT_MODE) if m.get_type() == "CURRENT_MODE"
    ]
    assert current[-1].custom_mode == Px4Mode.HOLD.custom_mode
    assert current[-1].standard_mode == mavlink.MAV_STANDARD_MODE_POSITION_HOLD
    info = [
        m
        for m in requested(mavlink.MAVLINK_MSG_ID_FLIGHT_INFORMATION)
        if m.get_type() == "FLIGHT_INFORMATION"
    ]
    assert info and info[0].arming_time_utc == 0  # not armed yet
    result, _ = gcs.command(mavlink.MAV_CMD_REQUEST_MESSAGE, 31000)
    assert result == mavlink.MAV_RESULT_UNSUPPORTED


def test_ping_and_timesync_are_answered(gcs: Gcs) -> None:
    gcs.conn.mav.ping_send(123456, 7, 0, 0)
    gcs.conn.mav.timesync_send(0, 42)
    messages = gcs.advance()
    pings = [m for m in messages if m.get_type() == "PING" and m.target_system == 255]
    assert [(p.seq, p.time_usec, p.target_component) for p in pings] == [(7, 123456, 190)]
    syncs = [m for m in messages if m.get_type() == "TIMESYNC" and m.ts1 == 42]
    assert syncs and syncs[0].tc1 > 0


def _ftp(gcs: Gcs, seq: int, opcode: int, *, session: int = 0, offset: int = 0, data: bytes = b""):
    payload = ftp.HEADER.pack(seq, session, opcode, len(data), 0, 0, 0, offset) + data
    gcs.conn.mav.file_transfer_protocol_send(0, 1, 1, list(payload.ljust(251, b"\0")))
    replies = [m for m in gcs.advance() if m.get_type() == "FILE_TRANSFER_PROTOCOL"]
    return [(ftp.HEADER.unpack_from(bytes(r.payload)), bytes(r.payload)[12:]) for r in replies]


def test_component_metadata_downloads_over_mavftp(gcs: Gcs) -> None:
    path = b"etc/extras/component_general.json.xz"
    [(header, data)] = _ftp(gcs, 10, ftp.OP_OPEN_FILE_RO, data=path)
    assert header[2] == ftp.OP_ACK and header[0] == 11
    session, size = header[1], struct.unpack("<I", data[:4])[0]
    content = b""
    while len(content) < size:
        [(header, data)] = _ftp(gcs, 20, ftp.OP_READ_FILE, session=session, offset=len(content))
        content += data[: header[3]]
    general = json.loads(lzma.decompress(content))
    [events] = [t for t in general["metadataTypes"] if t["type"] == 4]
    assert events["uri"] == "mftp://etc/extras/px4_events.json.xz"
    _ftp(gcs, 30, ftp.OP_TERMINATE_SESSION, session=session)
    # burst: every packet numbered, the last one marked complete
    [(header, data)] = _ftp(gcs, 40, ftp.OP_OPEN_FILE_RO, data=b"etc/extras/px4_events.json.xz")
    burst = _ftp(gcs, 41, ftp.OP_BURST_READ_FILE, session=header[1])
    assert [h[0] for h, _ in burst] == list(range(42, 42 + len(burst)))
    assert [h[5] for h, _ in burst] == [0] * (len(burst) - 1) + [1]
    definitions = json.loads(lzma.decompress(b"".join(d[: h[3]] for h, d in burst)))
    assert definitions["components"]["1"]["namespace"] == "px4"
    [(header, data)] = _ftp(gcs, 50, ftp.OP_OPEN_FILE_RO, data=b"fs/microsd/none")
    assert header[2] == ftp.OP_NAK and data[0] == ftp.ERR_FILE_NOT_FOUND


def test_px4s_888_parameters_with_their_types(gcs: Gcs) -> None:
    gcs.conn.mav.param_request_list_send(1, 1)
    values = {m.param_id: m for m in gcs.advance(1.0) if m.get_type() == "PARAM_VALUE"}
    assert len(values) == 888 and {m.param_count for m in values.values()} == {888}
    obl = values["COM_OBL_RC_ACT"]
    assert obl.param_type == mavlink.MAV_PARAM_TYPE_INT32
    assert struct.unpack("<i", struct.pack("<f", obl.param_value))[0] == 0  # byte-wise
    assert values["MPC_XY_VEL_P_ACC"].param_value == pytest.approx(1.8)
    assert values["SIH_KDV"].param_value == pytest.approx(1.0)
    # an integer set byte-wise changes what the simulated failsafe does
    hold = struct.unpack("<f", struct.pack("<i", 5))[0]
    gcs.conn.mav.param_set_send(1, 1, b"COM_OBL_RC_ACT", hold, mavlink.MAV_PARAM_TYPE_INT32)
    echo = [m for m in gcs.advance() if m.get_type() == "PARAM_VALUE"][-1]
    assert struct.unpack("<i", struct.pack("<f", echo.param_value))[0] == 5
    assert gcs.server.params.offboard_loss_action == 5
    # one it does not simulate is stored and echoed, like PX4
    gcs.conn.mav.param_set_send(1, 1, b"BAT1_CAPACITY", 5000.0, mavlink.MAV_PARAM_TYPE_REAL32)
    assert [m for m in gcs.advance() if m.get_type() == "PARAM_VALUE"][-1].param_value == 5000.0


def test_display_streams_and_px4_events(gcs: Gcs) -> None:
    messages = gcs.advance(2.0)
    kinds = {m.get_type() for m in messages}
    assert {
        "ALTITUDE",
        "VFR_HUD",
        "ATTITUDE_TARGET",
        "POSITION_TARGET_LOCAL_NED",
        "HIGHRES_IMU",
        "ODOMETRY",
        "ESTIMATOR_STATUS",
        "SYSTEM_TIME",
        "CURRENT_MODE",
        "PING",
    } <= kinds
    imu = [m for m in messages if m.get_type() == "HIGHRES_IMU"][-1]
    assert imu.zacc == pytest.approx(-9.81, abs=0.05)  # resting: the specific force is -g
    result, messages = gcs.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    assert result == mavlink.MAV_RESULT_ACCEPTED
    events = [xm.parse_unknown(m) for m in messages + gcs.advance(0.1)]
    events = [e[1] for e in events if e and e[0] is xm.EVENT]
    armed = DEFINITIONS["commander_armed_by"]
    [event] = [e for e in events if e["id"] == armed.event_id]
    assert event["arguments"][0] == 4  # arm_disarm_reason_t: command_external
    # RUN_PREARM_CHECKS: the health and arming check report, in libevents' order
    result, messages = gcs.command(mavlink.MAV_CMD_RUN_PREARM_CHECKS)
    assert result == mavlink.MAV_RESULT_ACCEPTED
    events = [xm.parse_unknown(m) for m in messages]
    events = [e[1] for e in events if e and e[0] is xm.EVENT]
    ids = [e["id"] & 0xFFFFFF for e in events]
    summary = DEFINITIONS["commander_arming_check_summary"].event_id & 0xFFFFFF
    health = DEFINITIONS["commander_health_summary"].event_id & 0xFFFFFF
    manual = DEFINITIONS["check_modes_manual_control"].event_id & 0xFFFFFF
    assert ids.index(summary) < ids.index(manual) < ids.index(health)
    sequences = [e["sequence"] for e in events]
    assert sequences == sorted(sequences) and len(set(sequences)) == len(sequences)
