"""The telemetry a PX4 streams on its onboard link, built from the simulated vehicle.

Everything reported is the *estimate* (`Px4Vehicle.estimate`: the truth plus the estimator's
error); rates are in simulated time and MAV_CMD_SET_MESSAGE_INTERVAL changes them. Besides what
MAVSDK needs (HEARTBEAT, SYS_STATUS, EXTENDED_SYS_STATE, ATTITUDE(_QUATERNION),
LOCAL/GLOBAL_POSITION, GPS_RAW_INT, HOME_POSITION, BATTERY_STATUS) it streams what a ground
station displays, as PX4 does: ALTITUDE, VFR_HUD, ATTITUDE_TARGET, POSITION_TARGET_LOCAL_NED,
HIGHRES_IMU, ODOMETRY, ESTIMATOR_STATUS, SYSTEM_TIME, CURRENT_MODE, PING and
CURRENT_EVENT_SEQUENCE.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from geometry.geodetic import lat_lon_deg
from geometry.rotation import rotation_from_quaternion
from hil.mavlink import extra_messages as xm
from hil.mavlink.dialect import mavlink
from hil.mavlink.events import EventSender, HealthReport, health_report
from hil.vehicle.params import VehicleSimParams
from hil.vehicle.px4_controller import GRAVITY_MPS2
from hil.vehicle.px4_modes import PX4_MAIN_MODE_AUTO, PX4_MAIN_MODE_OFFBOARD, Px4Mode, Px4Vehicle
from hil.vehicle.state import RigidBodyState

HEALTH_REPORT_PERIOD_S = 2.0
SEA_LEVEL_PRESSURE_HPA = 1013.25
_SENSORS = (
    mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO
    | mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    | mavlink.MAV_SYS_STATUS_SENSOR_3D_MAG
    | mavlink.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
    | mavlink.MAV_SYS_STATUS_SENSOR_GPS
    | mavlink.MAV_SYS_STATUS_AHRS
    | mavlink.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
    | mavlink.MAV_SYS_STATUS_SENSOR_BATTERY
)
# MAV_STANDARD_MODE of each mode (AVAILABLE_MODES / CURRENT_MODE) and its name in PX4
STANDARD_MODES: dict[Px4Mode, tuple[int, str]] = {
    Px4Mode.HOLD: (mavlink.MAV_STANDARD_MODE_POSITION_HOLD, "Hold"),
    Px4Mode.TAKEOFF: (mavlink.MAV_STANDARD_MODE_TAKEOFF, "Takeoff"),
    Px4Mode.LAND: (mavlink.MAV_STANDARD_MODE_LAND, "Land"),
    Px4Mode.RTL: (mavlink.MAV_STANDARD_MODE_SAFE_RECOVERY, "Return"),
    Px4Mode.OFFBOARD: (mavlink.MAV_STANDARD_MODE_NON_STANDARD, "Offboard"),
}


def global_from_local(
    position_ned_m: np.ndarray, params: VehicleSimParams
) -> tuple[float, float, float]:
    """(lat deg, lon deg, alt AMSL m) of a local NED position; flat earth around home
    (`geometry.geodetic`)."""
    north_m, east_m = float(position_ned_m[0]), float(position_ned_m[1])
    lat, lon = lat_lon_deg(north_m, east_m, params.home_lat_deg, params.home_lon_deg)
    return lat, lon, params.home_alt_amsl_m - float(position_ned_m[2])


class TelemetryStreams:
    """Sends due telemetry on `conn` for `vehicle` (call `emit_due` after each physics step)."""

    def __init__(self, conn: Any, vehicle: Px4Vehicle, params: VehicleSimParams) -> None:
        self.conn = conn
        self.vehicle = vehicle
        self.params = params
        self.events = EventSender()
        self._boot_unix_us = int(time.time() * 1e6)
        self._ping_seq = 0
        self._reported_mode: Px4Mode | None = None
        self._reported_health: HealthReport | None = None
        self._health_due_s = 0.0
        p = params
        fast, display = 1.0 / p.attitude_rate_hz, 1.0 / p.display_rate_hz
        position, status, slow = (
            1.0 / p.position_rate_hz,
            1.0 / p.status_rate_hz,
            1.0 / p.slow_rate_hz,
        )
        self._senders: dict[int, tuple[float, Callable[[], None]]] = {
            mavlink.MAVLINK_MSG_ID_HEARTBEAT: (1.0 / p.heartbeat_rate_hz, self.send_heartbeat),
            mavlink.MAVLINK_MSG_ID_SYS_STATUS: (status, self._send_sys_status),
            mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: (status, self._send_extended_sys_state),
            mavlink.MAVLINK_MSG_ID_GPS_RAW_INT: (status, self._send_gps_raw),
            mavlink.MAVLINK_MSG_ID_ATTITUDE: (fast, self._send_attitude),
            mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: (fast, self._send_attitude_quaternion),
            mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: (position, self._send_local_position),
            mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: (position, self._send_global_position),
            mavlink.MAVLINK_MSG_ID_ALTITUDE: (display, self._send_altitude),
            mavlink.MAVLINK_MSG_ID_VFR_HUD: (display, self._send_vfr_hud),
            mavlink.MAVLINK_MSG_ID_ATTITUDE_TARGET: (display, self._send_attitude_target),
            mavlink.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED: (display, self._send_position_target),
            mavlink.MAVLINK_MSG_ID_HIGHRES_IMU: (display, self._send_highres_imu),
            mavlink.MAVLINK_MSG_ID_ODOMETRY: (display, self._send_odometry),
            mavlink.MAVLINK_MSG_ID_HOME_POSITION: (slow, self.send_home_position),
            mavlink.MAVLINK_MSG_ID_BATTERY_STATUS: (slow, self._send_battery_status),
            mavlink.MAVLINK_MSG_ID_ESTIMATOR_STATUS: (slow, self._send_estimator_status),
            mavlink.MAVLINK_MSG_ID_SYSTEM_TIME: (slow, self._send_system_time),
            mavlink.MAVLINK_MSG_ID_CURRENT_MODE: (slow, self.send_current_mode),
            mavlink.MAVLINK_MSG_ID_PING: (slow, self._send_ping),
            xm.CURRENT_EVENT_SEQUENCE.msg_id: (slow, self._send_current_event_sequence),
        }
        self.intervals_s = {mid: interval for mid, (interval, _send) in self._senders.items()}
        self._default_intervals_s = dict(self.intervals_s)
        self._next_due_s = dict.fromkeys(self.intervals_s, 0.0)

    # --- scheduling ---------------------------------------------------------------------------
    def can_send(self, msg_id: int) -> bool:
        """Whether `msg_id` is one of the streamed messages."""
        return msg_id in self._senders

    def send_now(self, msg_id: int) -> None:
        """Send one `msg_id` at once (MAV_CMD_REQUEST_MESSAGE)."""
        self._senders[msg_id][1]()

    def set_interval(self, msg_id: int, interval_us: float) -> None:
        """MAV_CMD_SET_MESSAGE_INTERVAL: 0 default, < 0 off, else the interval in us."""
        if interval_us == 0:
            self.intervals_s[msg_id] = self._default_intervals_s[msg_id]
        elif interval_us < 0:
            self.intervals_s[msg_id] = math.inf
        else:
            self.intervals_s[msg_id] = max(interval_us * 1e-6, 1.0 / self.params.physics_rate_hz)
        self._next_due_s[msg_id] = self.vehicle.time_s

    def emit_due(self) -> None:
        """Send what is due now, the vehicle's new STATUSTEXTs and events, mode changes."""
        now = self.vehicle.time_s
        for mid, due in self._next_due_s.items():
            if now + 1e-9 >= due:
                self._senders[mid][1]()
                interval = self.intervals_s[mid]
                # accumulate deadlines (no drift); skip missed ones rather than burst
                self._next_due_s[mid] = (
                    max(due + interval, now) if math.isfinite(interval) else math.inf
                )
        v = self.vehicle
        while v.status_texts:
            text = v.status_texts.popleft()
            self.conn.mav.statustext_send(text.severity, text.text.encode())
        while v.events:
            self.conn.mav.send(self.events.encode(v.events.popleft(), self._time_boot_ms()))
        if v.mode is not self._reported_mode:
            # PX4 sends CURRENT_MODE (and a HEARTBEAT) at once when the mode changes
            self.send_current_mode()
        report = health_report(v)
        if report != self._reported_health or now >= self._health_due_s:
            self.send_health_report(report)

    def send_health_report(self, report: HealthReport | None = None) -> None:
        """PX4's health and arming check report as events (on change, every 2 s, on request)."""
        report = report or health_report(self.vehicle)
        for event, level in report.events():
            self.conn.mav.send(self.events.encode(event, self._time_boot_ms(), level))
        self._reported_health = report
        self._health_due_s = self.vehicle.time_s + HEALTH_REPORT_PERIOD_S

    # --- helpers ---------------------------------------------------------------------------------
    def _time_boot_ms(self) -> int:
        return int(self.vehicle.time_s * 1000.0) & 0xFFFFFFFF

    def _time_usec(self) -> int:
        return round(self.vehicle.time_s * 1e6)

    def unix_usec(self) -> int:
        """Wall-clock-anchored UTC of the simulated instant, us."""
        return self._boot_unix_us + self._time_usec()

    def _estimate(self) -> RigidBodyState:
        return self.vehicle.estimate

    def _battery(self) -> tuple[float, int]:
        """(voltage V, remaining %) from a linear discharge over the hover endurance."""
        p = self.params
        flown_fraction = min(self.vehicle.time_s / p.battery_endurance_s, 1.0)
        remaining = 1.0 - flown_fraction if self.vehicle.armed else 1.0 - 0.5 * flown_fraction
        voltage = p.battery_cells * (3.5 + 0.7 * remaining)
        return voltage, round(100 * remaining)

    # --- the messages ----------------------------------------------------------------------------
    def send_heartbeat(self) -> None:
        """HEARTBEAT: base_mode as PX4 sets it (Offboard: custom | stabilize, as PX4)."""
        v = self.vehicle
        base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        main_mode = v.mode.value[0]
        if main_mode == PX4_MAIN_MODE_AUTO:
            base |= (
                mavlink.MAV_MODE_FLAG_AUTO_ENABLED
                | mavlink.MAV_MODE_FLAG_GUIDED_ENABLED
                | mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED
            )
        elif main_mode == PX4_MAIN_MODE_OFFBOARD:
            base |= mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED
        if v.armed:
            base |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        if not v.healthy:
            state = mavlink.MAV_STATE_BOOT
        elif v.failsafe_active:
            state = mavlink.MAV_STATE_CRITICAL
        else:
            state = mavlink.MAV_STATE_ACTIVE if v.armed else mavlink.MAV_STATE_STANDBY
        self.conn.mav.heartbeat_send(
            mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, base, v.mode.custom_mode, state
        )

    def send_current_mode(self) -> None:
        """CURRENT_MODE: the standard mode, the custom mode and the user's intended one."""
        v = self.vehicle
        self._reported_mode = v.mode
        standard, _name = STANDARD_MODES[v.mode]
        self.conn.mav.current_mode_send(standard, v.mode.custom_mode, v.intended_mode.custom_mode)

    def send_available_modes(self, index: int) -> None:
        """AVAILABLE_MODES: mode `index` (1-based), or every mode for 0."""
        modes = list(STANDARD_MODES.items())
        chosen = range(1, len(modes) + 1) if index == 0 else [index]
        for i in chosen:
            mode, (standard, name) = modes[i - 1]
            properties = (
                0
                if mode in (Px4Mode.HOLD, Px4Mode.RTL, Px4Mode.LAND, Px4Mode.TAKEOFF)
                else (mavlink.MAV_MODE_PROPERTY_ADVANCED)
            )
            self.conn.mav.available_modes_send(
                len(modes), i, standard, mode.custom_mode, properties, name.encode()
            )

    def _send_sys_status(self) -> None:
        v = self.vehicle
        # healthy sensors and pre-arm bit once the estimator converged (MAVSDK: health_all_ok,
        # is_armable); arming may still be denied for a while after that (see Px4Vehicle.arm)
        present = _SENSORS | mavlink.MAV_SYS_STATUS_PREARM_CHECK
        health = present if v.healthy else 0
        voltage, remaining = self._battery()
        self.conn.mav.sys_status_send(
            present, present, health, 250, round(voltage * 1000), -1, remaining, 0, 0, 0, 0, 0, 0
        )

    def _send_battery_status(self) -> None:
        voltage, remaining = self._battery()
        voltages = [round(voltage * 1000)] + [65535] * 9
        self.conn.mav.battery_status_send(
            0,
            mavlink.MAV_BATTERY_FUNCTION_ALL,
            mavlink.MAV_BATTERY_TYPE_LIPO,
            32767,
            voltages,
            -1,
            -1,
            -1,
            remaining,
        )

    def _send_extended_sys_state(self) -> None:
        self.conn.mav.extended_sys_state_send(
            mavlink.MAV_VTOL_STATE_MC, int(self.vehicle.landed_state)
        )

    def _send_attitude(self) -> None:
        s = self._estimate()
        roll, pitch, yaw = s.euler_rad()
        w = s.angular_velocity_frd_radps
        self.conn.mav.attitude_send(
            self._time_boot_ms(), roll, pitch, yaw, float(w[0]), float(w[1]), float(w[2])
        )

    def _send_attitude_quaternion(self) -> None:
        s = self._estimate()
        w = s.angular_velocity_frd_radps
        self.conn.mav.attitude_quaternion_send(
            self._time_boot_ms(),
            *map(float, s.attitude_wxyz),
            float(w[0]),
            float(w[1]),
            float(w[2]),
        )

    def _send_local_position(self) -> None:
        s = self._estimate()
        p, v = s.position_ned_m, s.velocity_ned_mps
        self.conn.mav.local_position_ned_send(self._time_boot_ms(), *map(float, p), *map(float, v))

    def _send_global_position(self) -> None:
        s = self._estimate()
        lat, lon, alt = global_from_local(s.position_ned_m, self.params)
        v = s.velocity_ned_mps
        heading_cdeg = round(math.degrees(s.yaw_rad) % 360.0 * 100) % 36000
        self.conn.mav.global_position_int_send(
            self._time_boot_ms(),
            round(lat * 1e7),
            round(lon * 1e7),
            round(alt * 1000),
            round(-float(s.position_ned_m[2]) * 1000),
            *(int(np.clip(round(x * 100), -32768, 32767)) for x in v),
            heading_cdeg,
        )

    def _send_gps_raw(self) -> None:
        s = self._estimate()
        lat, lon, alt = global_from_local(s.position_ned_m, self.params)
        v = s.velocity_ned_mps
        ground_speed = float(np.hypot(v[0], v[1]))
        cog = round(math.degrees(math.atan2(v[1], v[0])) % 360.0 * 100) % 36000
        self.conn.mav.gps_raw_int_send(
            self._time_usec(),
            mavlink.GPS_FIX_TYPE_3D_FIX if self.vehicle.healthy else mavlink.GPS_FIX_TYPE_NO_FIX,
            round(lat * 1e7),
            round(lon * 1e7),
            round(alt * 1000),
            70,
            90,
            round(ground_speed * 100),
            cog,
            12,
        )

    def send_home_position(self) -> None:
        """HOME_POSITION: home at the local origin, on the ground."""
        p = self.params
        self.conn.mav.home_position_send(
            round(p.home_lat_deg * 1e7),
            round(p.home_lon_deg * 1e7),
            round(p.home_alt_amsl_m * 1000),
            0.0,
            0.0,
            0.0,
            [1.0, 0.0, 0.0, 0.0],
            0.0,
            0.0,
            0.0,
            self._time_usec(),
        )

    def _send_altitude(self) -> None:
        s = self._estimate()
        height = -float(s.position_ned_m[2])
        amsl = self.params.home_alt_amsl_m + height
        self.conn.mav.altitude_send(
            self._time_usec(), amsl, amsl, height, height, math.nan, max(height, 0.0)
        )

    def _send_vfr_hud(self) -> None:
        s = self._estimate()
        v = s.velocity_ned_mps
        ground_speed = float(np.hypot(v[0], v[1]))
        air = v - np.asarray(self.vehicle.truth.wind_ned_mps)
        control = self.vehicle.body.last_control
        throttle = 0 if control is None else round(100 * min(control.collective, 1.0))
        self.conn.mav.vfr_hud_send(
            float(np.hypot(air[0], air[1])),
            ground_speed,
            round(math.degrees(s.yaw_rad) % 360.0) % 360,
            throttle,
            self.params.home_alt_amsl_m - float(s.position_ned_m[2]),
            -float(v[2]),
        )

    def _send_attitude_target(self) -> None:
        body = self.vehicle.body
        control = body.last_control
        self.conn.mav.attitude_target_send(
            self._time_boot_ms(),
            0,
            [float(x) for x in body.attitude_setpoint_wxyz],
            *(float(x) for x in body.rate_setpoint_frd_radps),
            0.0 if control is None else control.collective,
        )

    def _send_position_target(self) -> None:
        setpoint = self.vehicle.body.setpoint
        control = self.vehicle.body.last_control
        pos = setpoint.position_ned_m
        vel = setpoint.velocity_ned_mps if control is None else control.velocity_setpoint_ned_mps
        acc = np.zeros(3) if control is None else control.acceleration_setpoint_ned_mps2
        mask = 0
        for i, bit in enumerate((1, 2, 4)):
            if not math.isfinite(pos[i]):
                mask |= bit
        for i, bit in enumerate((8, 16, 32)):
            if not math.isfinite(vel[i]):
                mask |= bit
        yaw = setpoint.yaw_rad
        if not math.isfinite(yaw):
            mask |= mavlink.POSITION_TARGET_TYPEMASK_YAW_IGNORE
        finite = [float(x) if math.isfinite(x) else math.nan for x in (*pos, *vel, *acc)]
        self.conn.mav.position_target_local_ned_send(
            self._time_boot_ms(),
            mavlink.MAV_FRAME_LOCAL_NED,
            mask,
            *finite,
            float(yaw),
            float(setpoint.yaw_rate_radps),
        )

    def _send_highres_imu(self) -> None:
        truth = self.vehicle.truth
        r = rotation_from_quaternion(truth.attitude_wxyz)
        specific_force = r.T @ (np.asarray(truth.acceleration_ned_mps2) - [0.0, 0.0, GRAVITY_MPS2])
        mag = r.T @ np.array([0.21, 0.01, 0.42])  # gauss, roughly Zurich's field
        w = truth.angular_velocity_frd_radps
        height = -float(truth.position_ned_m[2])
        pressure = (
            SEA_LEVEL_PRESSURE_HPA
            * (1.0 - 2.25577e-5 * (self.params.home_alt_amsl_m + height)) ** 5.25588
        )
        self.conn.mav.highres_imu_send(
            self._time_usec(),
            *map(float, specific_force),
            *map(float, w),
            *map(float, mag),
            pressure,
            0.0,
            self.params.home_alt_amsl_m + height,
            25.0,
            0x1FFF,
        )

    def _send_odometry(self) -> None:
        s = self._estimate()
        r = rotation_from_quaternion(s.attitude_wxyz)
        v_body = r.T @ np.asarray(s.velocity_ned_mps)
        w = s.angular_velocity_frd_radps
        self.conn.mav.odometry_send(
            self._time_usec(),
            mavlink.MAV_FRAME_LOCAL_NED,
            mavlink.MAV_FRAME_BODY_FRD,
            *map(float, s.position_ned_m),
            [float(x) for x in s.attitude_wxyz],
            *map(float, v_body),
            *map(float, w),
            [math.nan] * 21,
            [math.nan] * 21,
            0,
            mavlink.MAV_ESTIMATOR_TYPE_AUTOPILOT,
            100,
        )

    def _send_estimator_status(self) -> None:
        flags = (
            mavlink.ESTIMATOR_ATTITUDE
            | mavlink.ESTIMATOR_VELOCITY_HORIZ
            | mavlink.ESTIMATOR_VELOCITY_VERT
            | mavlink.ESTIMATOR_POS_HORIZ_REL
            | mavlink.ESTIMATOR_POS_HORIZ_ABS
            | mavlink.ESTIMATOR_POS_VERT_ABS
            | mavlink.ESTIMATOR_PRED_POS_HORIZ_REL
            | mavlink.ESTIMATOR_PRED_POS_HORIZ_ABS
        )
        if not self.vehicle.healthy:
            flags = 0
        self.conn.mav.estimator_status_send(
            self._time_usec(), flags, 0.1, 0.1, 0.1, 0.1, 0.0, 0.0, 0.5, 0.8
        )

    def _send_system_time(self) -> None:
        self.conn.mav.system_time_send(self.unix_usec(), self._time_boot_ms())

    def _send_ping(self) -> None:
        self._ping_seq = (self._ping_seq + 1) & 0xFFFFFFFF
        self.conn.mav.ping_send(self._time_usec(), self._ping_seq, 0, 0)

    def _send_current_event_sequence(self) -> None:
        self.conn.mav.send(
            xm.message(xm.CURRENT_EVENT_SEQUENCE, sequence=self.events.last_sequence, flags=0)
        )
