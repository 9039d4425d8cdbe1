"""The SIL vehicle over real UDP MAVLink 2, driven by a pymavlink client (lockstep mostly)."""

from __future__ import annotations

import math
import os
import socket
import subprocess
import sys
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from hil.mavlink.server import VehicleServer, mavlink, mavutil, wait_for
from hil.vehicle.params import VehicleSimParams
from hil.vehicle.px4_modes import Px4Mode

NAN = math.nan
# SET_POSITION_TARGET_LOCAL_NED type masks (a set bit ignores the field)
VELOCITY_YAW_MASK = 0b0000_1001_1100_0111  # use vx, vy, vz, yaw
POSITION_YAW_MASK = 0b0000_1001_1111_1000  # use x, y, z, yaw


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Client:
    """A pymavlink ground station listening where the vehicle sends (like MAVSDK udpin)."""

    def __init__(self, port: int, server: VehicleServer) -> None:
        self.server = server
        self.conn = mavutil.mavlink_connection(
            f"udpin:127.0.0.1:{port}", source_system=245, source_component=190
        )
        self.received: list[Any] = []

    def close(self) -> None:
        self.conn.close()

    def drain(self) -> list[Any]:
        out = []
        while (msg := self.conn.recv_msg()) is not None:
            if msg.get_type() != "BAD_DATA":
                out.append(msg)
        self.received.extend(out)
        return out

    def advance(self, dt_s: float) -> list[Any]:
        """Advance the lockstep vehicle in 0.1 s chunks, draining so no datagram is dropped."""
        out = []
        remaining = dt_s
        while remaining > 1e-9:
            chunk = min(0.1, remaining)
            self.server.advance(chunk)
            out += self.drain()
            remaining -= chunk
        return out

    def last(self, kind: str, messages: list[Any] | None = None) -> Any:
        matching = [m for m in (messages or self.received) if m.get_type() == kind]
        assert matching, f"no {kind} received"
        return matching[-1]

    def command(self, cmd: int, *params: float, use_int: bool = False) -> int:
        """Send COMMAND_LONG (or COMMAND_INT) and return the ACK's result."""
        p = [*params, *([NAN] * (7 - len(params)))]
        if use_int:
            x = 0 if math.isnan(p[4]) else int(p[4])
            y = 0 if math.isnan(p[5]) else int(p[5])
            self.conn.mav.command_int_send(1, 1, 0, cmd, 0, 0, *p[:4], x, y, p[6])
        else:
            self.conn.mav.command_long_send(1, 1, cmd, 0, *p)
        acks = [m for m in self.advance(0.02) if m.get_type() == "COMMAND_ACK"]
        assert len(acks) == 1, f"expected one ACK for {cmd}, got {acks}"
        assert acks[0].command == cmd
        assert (acks[0].target_system, acks[0].target_component) == (245, 190)
        return acks[0].result

    def setpoint(self, mask: int, x=0.0, y=0.0, z=0.0, vx=0.0, vy=0.0, vz=0.0, yaw=0.0) -> None:
        self.conn.mav.set_position_target_local_ned_send(
            0, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, mask, x, y, z, vx, vy, vz, 0, 0, 0, yaw, 0
        )

    def stream_setpoints(self, duration_s: float, mask: int, **fields: float) -> None:
        t_end = self.server.time_s + duration_s
        while self.server.time_s < t_end - 1e-9:
            self.setpoint(mask, **fields)
            self.advance(0.05)


@pytest.fixture
def link() -> Iterator[Client]:
    port = free_udp_port()
    params = VehicleSimParams(health_ok_after_boot_s=1.0, arm_denied_after_boot_s=2.0)
    server = VehicleServer(params, port, lockstep=True)
    client = Client(port, server)
    server.start()
    client.drain()  # a udpin client learns where to reply from the first datagram
    try:
        yield client
    finally:
        server.stop()
        client.close()
    assert not server.message_errors


def take_off(link: Client) -> None:
    """Arm and take off to MIS_TAKEOFF_ALT; back once PX4's takeoff switched to Hold."""
    link.advance(2.1)
    assert link.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mavlink.MAV_RESULT_ACCEPTED
    assert link.command(mavlink.MAV_CMD_NAV_TAKEOFF) == mavlink.MAV_RESULT_ACCEPTED
    # spool-up, the takeoff ramp and the climb: about 7 s, as PX4 SITL's SIH takes
    for _ in range(120):
        link.advance(0.1)
        if link.server.flight_mode is Px4Mode.HOLD:
            break
    assert link.server.flight_mode is Px4Mode.HOLD


def test_telemetry_streams_identify_a_px4_quadrotor(link: Client) -> None:
    messages = link.advance(2.05)
    kinds = {m.get_type() for m in messages}
    assert {
        "HEARTBEAT",
        "SYS_STATUS",
        "ATTITUDE",
        "ATTITUDE_QUATERNION",
        "LOCAL_POSITION_NED",
        "GLOBAL_POSITION_INT",
        "HOME_POSITION",
        "GPS_RAW_INT",
        "EXTENDED_SYS_STATE",
        "BATTERY_STATUS",
    } <= kinds
    heartbeats = [m for m in messages if m.get_type() == "HEARTBEAT"]
    assert len(heartbeats) == 2  # 1 Hz in simulated time: t = 1 and 2 s
    hb = heartbeats[-1]
    assert hb.get_srcSystem() == 1 and hb.get_srcComponent() == 1
    assert hb.type == mavlink.MAV_TYPE_QUADROTOR
    assert hb.autopilot == mavlink.MAV_AUTOPILOT_PX4
    assert hb.custom_mode == (4 << 16) | (3 << 24)  # AUTO / LOITER (Hold)
    assert hb.base_mode & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    assert not hb.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    assert messages[0].get_msgbuf()[0] == 0xFD  # MAVLink 2 framing
    home = link.last("HOME_POSITION", messages)
    assert home.latitude == round(link.server.params.home_lat_deg * 1e7)
    assert link.last("EXTENDED_SYS_STATE", messages).landed_state == 1  # on ground


def test_sys_status_health_and_prearm_bit_after_boot(link: Client) -> None:
    early = link.advance(0.5)
    assert link.last("SYS_STATUS", early).onboard_control_sensors_health == 0
    late = link.advance(1.0)
    status = link.last("SYS_STATUS", late)
    for bit in (
        mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO,
        mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL,
        mavlink.MAV_SYS_STATUS_SENSOR_3D_MAG,
        mavlink.MAV_SYS_STATUS_SENSOR_GPS,
        mavlink.MAV_SYS_STATUS_PREARM_CHECK,
    ):
        assert status.onboard_control_sensors_present & bit
        assert status.onboard_control_sensors_health & bit
    assert link.last("GPS_RAW_INT", late).fix_type == mavlink.GPS_FIX_TYPE_3D_FIX


def test_every_command_is_acked_and_nan_params_never_crash(link: Client) -> None:
    assert link.command(31999) == mavlink.MAV_RESULT_UNSUPPORTED
    assert link.command(mavlink.MAV_CMD_DO_REPOSITION, NAN, 1, NAN, NAN, 47, 8, 500) == 3
    assert link.command(mavlink.MAV_CMD_DO_SET_MODE) == mavlink.MAV_RESULT_DENIED
    assert link.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM) == mavlink.MAV_RESULT_DENIED
    assert link.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, NAN, NAN) == 2
    assert link.command(mavlink.MAV_CMD_REQUEST_MESSAGE, NAN) == mavlink.MAV_RESULT_DENIED
    assert link.command(mavlink.MAV_CMD_DO_SET_MODE, 1, 3, 0) == 1  # POSCTL: no RC, rejected
    assert link.command(31999, use_int=True) == mavlink.MAV_RESULT_UNSUPPORTED
    assert link.server.flight_mode is Px4Mode.HOLD
    assert not link.server.armed


def test_autopilot_version_on_request(link: Client) -> None:
    assert link.command(mavlink.MAV_CMD_REQUEST_MESSAGE, 148) == mavlink.MAV_RESULT_ACCEPTED
    version = link.last("AUTOPILOT_VERSION")
    assert version.capabilities & mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    assert version.flight_sw_version >> 24 == 1
    assert link.command(mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, 1) == 0


def test_set_message_interval_changes_a_stream_rate(link: Client) -> None:
    link.advance(0.5)
    assert link.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 30, 100_000) == 0  # 10 Hz
    messages = link.advance(2.0)
    assert 19 <= sum(m.get_type() == "ATTITUDE" for m in messages) <= 21
    assert link.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 30, -1) == 0  # off
    assert not any(m.get_type() == "ATTITUDE" for m in link.advance(1.0))


def test_arming_denied_right_after_boot_then_allowed(link: Client) -> None:
    link.advance(1.2)  # healthy, pre-arm bit set, but still too early
    assert link.last("SYS_STATUS").onboard_control_sensors_health & (
        mavlink.MAV_SYS_STATUS_PREARM_CHECK
    )
    assert link.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == (
        mavlink.MAV_RESULT_TEMPORARILY_REJECTED
    )
    assert any(m.get_type() == "STATUSTEXT" and "Arming denied" in m.text for m in link.received)
    link.advance(1.0)
    assert link.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == 0
    heartbeats = [m for m in link.advance(1.1) if m.get_type() == "HEARTBEAT"]
    assert heartbeats[-1].base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED


def test_takeoff_uses_mis_takeoff_alt_param_then_lands_and_disarms(link: Client) -> None:
    link.conn.mav.param_set_send(1, 1, b"MIS_TAKEOFF_ALT", 4.0, mavlink.MAV_PARAM_TYPE_REAL32)
    link.advance(0.02)
    echo = link.last("PARAM_VALUE")
    assert (echo.param_id, echo.param_value) == ("MIS_TAKEOFF_ALT", pytest.approx(4.0))
    link.conn.mav.param_set_send(1, 1, b"MIS_TAKEOFF_ALT", -3.0, mavlink.MAV_PARAM_TYPE_REAL32)
    link.advance(0.02)
    assert link.last("PARAM_VALUE").param_value == pytest.approx(4.0)  # out of bounds: kept
    link.conn.mav.param_request_read_send(1, 1, b"MPC_TILTMAX_AIR", -1)
    link.advance(0.02)
    assert link.last("PARAM_VALUE").param_value == pytest.approx(45.0)

    take_off(link)
    modes = [m.custom_mode for m in link.received if m.get_type() == "HEARTBEAT"]
    assert (4 << 16) | (2 << 24) in modes  # AUTO / TAKEOFF was reported on the way up
    link.advance(6.0)  # Hold climbs the last NAV_MC_ALT_RAD smoothly
    assert link.server.truth().position_ned_m[2] == pytest.approx(-4.0, abs=0.1)
    assert link.last("GLOBAL_POSITION_INT").relative_alt == pytest.approx(4000, abs=100)
    assert link.last("EXTENDED_SYS_STATE").landed_state == 2  # in air
    assert link.command(mavlink.MAV_CMD_NAV_LAND, 0, 0, 0, NAN, NAN, NAN, NAN) == 0
    link.advance(20.0)  # descent, PX4's slow touchdown detection, COM_DISARM_LAND
    assert not link.server.armed
    assert link.last("EXTENDED_SYS_STATE").landed_state == 1
    assert not link.last("HEARTBEAT").base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED


def test_offboard_refused_without_setpoint_then_velocity_flight_and_loss(link: Client) -> None:
    take_off(link)
    set_offboard = (mavlink.MAV_CMD_DO_SET_MODE, 1, 6, 0)
    assert link.command(*set_offboard) == mavlink.MAV_RESULT_TEMPORARILY_REJECTED
    link.stream_setpoints(0.5, VELOCITY_YAW_MASK, vx=1.0)
    assert link.command(*set_offboard) == mavlink.MAV_RESULT_ACCEPTED
    link.stream_setpoints(4.0, VELOCITY_YAW_MASK, vx=1.0)
    # SIH's drag: PX4's velocity integrator approaches 1 m/s slowly (0.8 after 4 s)
    assert 0.75 < link.server.truth().velocity_ned_mps[0] < 1.0
    heartbeat = link.last("HEARTBEAT")
    assert heartbeat.custom_mode == 6 << 16
    assert heartbeat.base_mode == 145  # armed | stabilize | custom, as PX4 sends Offboard
    assert link.last("LOCAL_POSITION_NED").vx == pytest.approx(
        link.server.truth().velocity_ned_mps[0], abs=0.05
    )
    link.advance(0.9)
    assert link.server.flight_mode is Px4Mode.OFFBOARD
    link.advance(0.3)  # COM_OF_LOSS_T = 1 s since the last setpoint
    # COM_OBL_RC_ACT 0 without RC: Return, as PX4 does
    assert link.server.flight_mode is Px4Mode.RTL
    link.advance(1.0)
    assert link.last("HEARTBEAT").custom_mode == (4 << 16) | (5 << 24)
    assert link.last("CURRENT_MODE").intended_custom_mode == 6 << 16


def test_position_setpoint_through_type_mask(link: Client) -> None:
    take_off(link)
    link.stream_setpoints(0.3, POSITION_YAW_MASK, x=3.0, y=-2.0, z=-3.0, yaw=0.5)
    assert link.command(mavlink.MAV_CMD_DO_SET_MODE, 1, 6, 0) == 0
    link.stream_setpoints(8.0, POSITION_YAW_MASK, x=3.0, y=-2.0, z=-3.0, yaw=0.5)
    truth = link.server.truth()
    assert truth.position_ned_m == pytest.approx([3.0, -2.0, -3.0], abs=0.1)
    assert truth.yaw_rad == pytest.approx(0.5, abs=0.02)
    assert link.last("ATTITUDE").yaw == pytest.approx(0.5, abs=0.02)
    # MAVSDK's return_to_launch(): DO_SET_MODE AUTO / RTL
    assert link.command(mavlink.MAV_CMD_DO_SET_MODE, 1, 4, 5) == 0
    link.advance(1.1)
    assert link.server.flight_mode is Px4Mode.RTL
    assert link.last("HEARTBEAT").custom_mode == (4 << 16) | (5 << 24)
    # MAVSDK's hold(): DO_SET_MODE AUTO / LOITER
    assert link.command(mavlink.MAV_CMD_DO_SET_MODE, 1, 4, 3) == 0
    assert link.server.flight_mode is Px4Mode.HOLD


def test_companion_heartbeat_loss_is_reported_not_acted_on(link: Client) -> None:
    take_off(link)
    # a companion computer's heartbeat: MAV_TYPE_ONBOARD_CONTROLLER from component 191
    link.conn.mav.srcComponent = mavlink.MAV_COMP_ID_ONBOARD_COMPUTER
    link.conn.mav.heartbeat_send(mavlink.MAV_TYPE_ONBOARD_CONTROLLER, 8, 0, 0, 4)
    link.conn.mav.srcComponent = 190
    link.stream_setpoints(0.3, VELOCITY_YAW_MASK)
    assert link.command(mavlink.MAV_CMD_DO_SET_MODE, 1, 6, 0) == 0
    timeout_s = link.server.params.companion_loss_timeout_s
    # setpoints continue (MAVSDK re-sends them by itself), heartbeats have stopped
    link.stream_setpoints(timeout_s - 0.5, VELOCITY_YAW_MASK)
    assert link.server.flight_mode is Px4Mode.OFFBOARD
    link.stream_setpoints(1.0, VELOCITY_YAW_MASK)
    # PX4 main warns (COM_OBC_LOSS_T), keeps flying the setpoints it still gets
    assert link.server.flight_mode is Px4Mode.OFFBOARD
    assert any(m.get_type() == "STATUSTEXT" and "onboard" in m.text for m in link.received)


def test_restart_on_the_same_port_reboots_the_vehicle(link: Client) -> None:
    take_off(link)
    link.server.stop()
    link.server.stop()  # idempotent
    link.drain()
    assert link.server.time_s > 6.0
    link.server.start()
    messages = link.advance(0.5)
    assert link.server.time_s == pytest.approx(0.5)
    assert link.server.truth().on_ground
    assert any(m.get_type() == "HEARTBEAT" for m in messages)


def test_real_time_mode_runs_its_own_clock() -> None:
    port = free_udp_port()
    conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=245)
    try:
        with VehicleServer(VehicleSimParams(), port, speed=4.0) as server:
            heartbeat = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=5.0)
            assert heartbeat is not None and heartbeat.autopilot == mavlink.MAV_AUTOPILOT_PX4
            assert wait_for(lambda: server.time_s > 1.0, timeout_s=10.0)
            assert server.error is None
        assert not server.running
        with pytest.raises(RuntimeError):
            server.advance(0.1)
    finally:
        conn.close()


def drifting_estimates(seed: int) -> list[tuple[float, float, float, float]]:
    port = free_udp_port()
    params = VehicleSimParams(
        seed=seed,
        ekf_velocity_error_std_mps=0.2,
        ekf_altitude_error_std_m=0.3,
        ekf_heading_error_std_deg=5.0,
        wind_gust_std_mps=0.5,
    )
    server = VehicleServer(params, port, lockstep=True)
    client = Client(port, server)
    server.start()
    try:
        messages = client.advance(3.0)
        assert server.truth().position_ned_m.tolist() == [0.0, 0.0, 0.0]  # still on the ground
    finally:
        server.stop()
        client.close()
    positions = [(m.x, m.y, m.z) for m in messages if m.get_type() == "LOCAL_POSITION_NED"]
    yaws = [m.yaw for m in messages if m.get_type() == "ATTITUDE"]
    return [
        (*p, yaw) for p, yaw in zip(positions, yaws[:: len(yaws) // len(positions)], strict=False)
    ]


def test_lockstep_telemetry_is_deterministic_from_the_seed_and_drifts() -> None:
    first = drifting_estimates(11)
    assert len(first) == 91  # 30 Hz from t = 0 to 3 s of simulated time, both included
    assert first == drifting_estimates(11)
    assert first != drifting_estimates(12)
    # the truth rests at the origin; the estimate wanders off it, by PX4-like amounts
    errors = np.abs(np.array(first))
    assert 0.005 < errors[:, :3].max() < 1.5
    assert 0.001 < errors[:, 3].max() < np.radians(25.0)


def test_mavlink2_even_when_mavutil_was_imported_without_it() -> None:
    code = (
        "from pymavlink import mavutil\n"
        "assert mavutil.mavlink.WIRE_PROTOCOL_VERSION == '1.0'\n"
        "from hil.mavlink.server import mavlink\n"
        "print(mavlink.WIRE_PROTOCOL_VERSION, mavutil.mavlink.WIRE_PROTOCOL_VERSION)\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "MAVLINK20"}
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    assert out.stdout.split() == ["2.0", "2.0"]
