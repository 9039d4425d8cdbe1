"""The SIL vehicle on the wire: a `Px4Vehicle` speaking MAVLink 2 over UDP like PX4 SITL.

Like PX4 SITL's offboard link, it *sends* to HOST:PORT (the client listens there, e.g. MAVSDK
`udpin://0.0.0.0:PORT`) and reads the client's replies on the same socket (pymavlink `udpout:`).
Identity: sysid 1, compid 1 (autopilot), MAV_AUTOPILOT_PX4, MAV_TYPE_QUADROTOR.

Time: fixed physics steps of 1/`physics_rate_hz` simulated seconds. With `speed` (real-time
factor, 1.0 = real time) a thread paces them against the wall clock; with `lockstep=True` no
thread runs and the caller advances simulated time with `advance(dt_s)`, which is deterministic
for a given seed and message order. Telemetry rates are in simulated time.

What MAVSDK needs and gets (checked in MAVSDK's telemetry/action/offboard/system impls):
health from SYS_STATUS present/health bits (gyro, accel, mag, GPS -> local/global position) and
the pre-arm bit (is_armable), home from HOME_POSITION, flight mode from HEARTBEAT.custom_mode,
landed state from EXTENDED_SYS_STATE, COMMAND_ACK for every COMMAND_LONG/INT, AUTOPILOT_VERSION
on MAV_CMD_REQUEST_MESSAGE, PARAM_VALUE echoes for PARAM_SET (MIS_TAKEOFF_ALT).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import os
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

os.environ.setdefault("MAVLINK20", "1")

import numpy as np
from pymavlink import mavutil

from hil.attitude import euler_from_quaternion, quaternion_from_euler
from hil.clock import RealTimePacer
from hil.multirotor import VehicleState
from hil.params import VehicleSimParams, px4_parameter_table
from hil.px4_controller import TrajectorySetpoint
from hil.px4_modes import (
    PX4_MAIN_MODE_AUTO,
    PX4_MAIN_MODE_OFFBOARD,
    CommandResult,
    FlightMode,
    LandedState,
    Px4Vehicle,
)

if mavutil.mavlink.WIRE_PROTOCOL_VERSION != "2.0":
    # mavutil was imported earlier without MAVLINK20: switch its dialect to MAVLink 2
    os.environ["MAVLINK20"] = "1"
    mavutil.set_dialect(mavutil.current_dialect)
mavlink = mavutil.mavlink
_log = logging.getLogger(__name__)

EARTH_RADIUS_M = 6_378_137.0
PX4_VERSION = (1, 14, 0)
FORCE_MAGIC = 21196
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
_CAPABILITIES = (
    mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT
    | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
    | mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
)
_COMPANION_COMPONENTS = range(
    mavlink.MAV_COMP_ID_ONBOARD_COMPUTER, mavlink.MAV_COMP_ID_ONBOARD_COMPUTER4 + 1
)


def global_from_local(
    position_ned_m: np.ndarray, params: VehicleSimParams
) -> tuple[float, float, float]:
    """(lat deg, lon deg, alt AMSL m) of a local NED position; flat earth around home."""
    lat0 = math.radians(params.home_lat_deg)
    lat = params.home_lat_deg + math.degrees(position_ned_m[0] / EARTH_RADIUS_M)
    lon = params.home_lon_deg + math.degrees(position_ned_m[1] / (EARTH_RADIUS_M * math.cos(lat0)))
    return lat, lon, params.home_alt_amsl_m - float(position_ned_m[2])


def _finite(value: float) -> float | None:
    return float(value) if value is not None and math.isfinite(value) else None


def setpoint_from_position_target(msg: Any, yaw_now_rad: float) -> TrajectorySetpoint:
    """A `TrajectorySetpoint` from SET_POSITION_TARGET_LOCAL_NED honouring its type_mask.

    Ignored or non-finite fields become NaN (uncontrolled). Body frames (BODY_NED, BODY_FRD,
    BODY_OFFSET_NED) rotate x/y by the current yaw like PX4; position in them is an offset.
    Acceleration/force fields are not supported and ignored.
    """
    mask = msg.type_mask
    ignore = mavlink.POSITION_TARGET_TYPEMASK_X_IGNORE
    pos = np.array(
        [
            msg.x if not mask & ignore else np.nan,
            msg.y if not mask & mavlink.POSITION_TARGET_TYPEMASK_Y_IGNORE else np.nan,
            msg.z if not mask & mavlink.POSITION_TARGET_TYPEMASK_Z_IGNORE else np.nan,
        ],
        dtype=float,
    )
    vel = np.array(
        [
            msg.vx if not mask & mavlink.POSITION_TARGET_TYPEMASK_VX_IGNORE else np.nan,
            msg.vy if not mask & mavlink.POSITION_TARGET_TYPEMASK_VY_IGNORE else np.nan,
            msg.vz if not mask & mavlink.POSITION_TARGET_TYPEMASK_VZ_IGNORE else np.nan,
        ],
        dtype=float,
    )
    yaw = msg.yaw if not mask & mavlink.POSITION_TARGET_TYPEMASK_YAW_IGNORE else math.nan
    yaw_rate = (
        msg.yaw_rate if not mask & mavlink.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE else math.nan
    )
    if msg.coordinate_frame in (
        mavlink.MAV_FRAME_BODY_NED,
        mavlink.MAV_FRAME_BODY_FRD,
        mavlink.MAV_FRAME_BODY_OFFSET_NED,
    ):
        c, s = math.cos(yaw_now_rad), math.sin(yaw_now_rad)
        rot = np.array([[c, -s], [s, c]])
        vel[:2] = rot @ vel[:2]
        pos[:2] = rot @ pos[:2]
    return TrajectorySetpoint(
        position_ned_m=pos,
        velocity_ned_mps=vel,
        yaw_rad=float(yaw) if math.isfinite(yaw) else math.nan,
        yaw_rate_radps=float(yaw_rate) if math.isfinite(yaw_rate) else math.nan,
    )


class VehicleServer:
    """A PX4-like vehicle reachable over MAVLink 2 / UDP. Thread-safe accessors.

    `start()` opens the socket (and in real-time mode starts the simulation thread); `stop()`
    joins and closes, idempotent. `start()` after `stop()` reboots the vehicle (fresh state,
    time 0), which is how a client's reconnection is tested. A context manager starts/stops.
    """

    def __init__(
        self,
        params: VehicleSimParams,
        port: int,
        *,
        speed: float = 1.0,
        host: str = "127.0.0.1",
        lockstep: bool = False,
    ) -> None:
        if speed <= 0.0:
            raise ValueError("speed must be > 0")
        self.params = params.model_copy(deep=True)
        self.port = port
        self.host = host
        self.speed = speed
        self.lockstep = lockstep
        self._lock = threading.RLock()
        self._stop_event = threading.Event()
        self._thread: threading.Thread | None = None
        self._conn: Any = None
        self._pacer: RealTimePacer | None = None
        self._param_table = px4_parameter_table()
        self._param_names = sorted(self._param_table)
        self._vehicle = Px4Vehicle(self.params)
        self._reset_streams()
        self.error: BaseException | None = None
        self.message_errors: deque[str] = deque(maxlen=32)

    # --- lifecycle --------------------------------------------------------------------------
    def start(self) -> VehicleServer:
        """Boot the vehicle and open the link; returns once it is running."""
        with self._lock:
            if self._conn is not None:
                return self
            self._vehicle = Px4Vehicle(self.params)
            self._sensor_rng = np.random.default_rng([self._vehicle.seed, 0x5E5])
            self._reset_streams()
            self._conn = mavutil.mavlink_connection(
                f"udpout:{self.host}:{self.port}", source_system=1, source_component=1
            )
            self._conn.mav.srcSystem, self._conn.mav.srcComponent = 1, 1
            self._stop_event.clear()
            self._emit_due()
        if not self.lockstep:
            self._pacer = RealTimePacer(self.speed)
            self._thread = threading.Thread(
                target=self._run, name=f"vehicle-sim:{self.port}", daemon=True
            )
            self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the simulation thread and close the socket (idempotent)."""
        self._stop_event.set()
        thread, self._thread = self._thread, None
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=5.0)
        with self._lock:
            if self._conn is not None:
                self._conn.close()
                self._conn = None

    def __enter__(self) -> VehicleServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def running(self) -> bool:
        """The link is open."""
        return self._conn is not None

    # --- accessors for tests and the harness --------------------------------------------------
    def truth(self) -> VehicleState:
        """Ground-truth state now (an immutable snapshot)."""
        with self._lock:
            return self._vehicle.truth

    @property
    def time_s(self) -> float:
        """Simulated seconds since boot."""
        with self._lock:
            return self._vehicle.time_s

    @property
    def flight_mode(self) -> FlightMode:
        """The current flight mode."""
        with self._lock:
            return self._vehicle.mode

    @property
    def armed(self) -> bool:
        """Motors armed."""
        with self._lock:
            return self._vehicle.armed

    @property
    def landed_state(self) -> LandedState:
        """The land detector's state."""
        with self._lock:
            return self._vehicle.landed_state

    @property
    def lag_s(self) -> float:
        """Real-time mode: how late simulated time runs behind the wall clock, s (0 lockstep)."""
        if self._pacer is None:
            return 0.0
        return max(self._pacer.lag_s(self.time_s), 0.0) + self._pacer.dropped_lag_s

    def with_vehicle(self, fn: Callable[[Px4Vehicle], Any]) -> Any:
        """Run `fn(vehicle)` under the lock (fault injection in tests)."""
        with self._lock:
            return fn(self._vehicle)

    # --- simulation -------------------------------------------------------------------------
    def advance(self, dt_s: float) -> VehicleState:
        """Lockstep: advance simulated time `dt_s` (physics, message handling, telemetry)."""
        if not self.lockstep:
            raise RuntimeError("advance() is for lockstep mode; the thread paces real-time mode")
        h = 1.0 / self.params.physics_rate_hz
        steps = max(1, round(dt_s / h))
        for _ in range(steps):
            self._tick(h)
        return self.truth()

    def _run(self) -> None:
        h = 1.0 / self.params.physics_rate_hz
        assert self._pacer is not None
        try:
            while not self._stop_event.is_set():
                self._tick(h)
                self._pacer.wait_until(self.time_s)
        except BaseException as exc:  # surfaced to tests and the CLI, never swallowed
            self.error = exc
            raise

    def _tick(self, h: float) -> None:
        with self._lock:
            if self._conn is None:
                return
            self._receive_all()
            self._vehicle.step(h)
            self._emit_due()

    # --- receiving --------------------------------------------------------------------------
    def _receive_all(self) -> None:
        while True:
            try:
                msg = self._conn.recv_msg()
            except OSError:
                return
            if msg is None:
                return
            try:
                self._handle(msg)
            except Exception as exc:  # a malformed message must never stop the vehicle
                self.message_errors.append(f"{msg.get_type()}: {exc!r}")
                _log.warning("vehicle-sim: failed to handle %s: %r", msg.get_type(), exc)

    def _handle(self, msg: Any) -> None:
        kind = msg.get_type()
        if kind == "HEARTBEAT":
            self._handle_heartbeat(msg)
            return
        if getattr(msg, "target_system", 1) not in (0, 1):
            return
        if getattr(msg, "target_component", 1) not in (0, 1):
            return
        if kind in ("COMMAND_LONG", "COMMAND_INT"):
            self._handle_command(msg)
        elif kind == "SET_POSITION_TARGET_LOCAL_NED":
            yaw = euler_from_quaternion(self._vehicle.truth.attitude_wxyz)[2]
            self._vehicle.offboard_setpoint(setpoint_from_position_target(msg, yaw))
        elif kind == "PARAM_REQUEST_READ":
            self._handle_param_read(msg)
        elif kind == "PARAM_REQUEST_LIST":
            for index in range(len(self._param_names)):
                self._send_param(index)
        elif kind == "PARAM_SET":
            self._handle_param_set(msg)
        elif kind == "TIMESYNC" and msg.tc1 == 0:
            self._conn.mav.timesync_send(int(self._vehicle.time_s * 1e9), msg.ts1)

    def _handle_heartbeat(self, msg: Any) -> None:
        src_component = msg.get_srcComponent()
        if msg.type == mavlink.MAV_TYPE_GCS:
            return
        if (
            msg.type == mavlink.MAV_TYPE_ONBOARD_CONTROLLER
            or src_component in _COMPANION_COMPONENTS
        ):
            self._vehicle.companion_heartbeat()

    def _handle_command(self, msg: Any) -> None:
        try:
            result = self._command_result(msg)
        except (ValueError, OverflowError, TypeError):
            result = CommandResult.DENIED
        self._conn.mav.command_ack_send(
            msg.command,
            int(result),
            0,
            0,
            msg.get_srcSystem(),
            msg.get_srcComponent(),
        )

    def _command_result(self, msg: Any) -> CommandResult:
        """Execute one COMMAND_LONG / COMMAND_INT; unknown commands are UNSUPPORTED."""
        vehicle = self._vehicle
        cmd = msg.command
        is_int = msg.get_type() == "COMMAND_INT"
        p1, p2, p3 = msg.param1, msg.param2, msg.param3
        p7 = msg.z if is_int else msg.param7
        if cmd == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            arm = _finite(p1)
            if arm is None or round(arm) not in (0, 1):
                return CommandResult.DENIED
            force = _finite(p2) == FORCE_MAGIC
            return vehicle.arm(force) if round(arm) == 1 else vehicle.disarm(force)
        if cmd == mavlink.MAV_CMD_NAV_TAKEOFF:
            return vehicle.takeoff(float(p7) if _finite(p7) is not None else math.nan)
        if cmd == mavlink.MAV_CMD_NAV_LAND:
            return vehicle.land()
        if cmd == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            return vehicle.return_to_launch()
        if cmd == mavlink.MAV_CMD_DO_SET_MODE:
            return self._set_mode(p1, p2, p3)
        if cmd == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
            return self._set_message_interval(p1, p2)
        if cmd == mavlink.MAV_CMD_REQUEST_MESSAGE:
            return self._send_requested(p1)
        if cmd == mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            self._send_autopilot_version()
            return CommandResult.ACCEPTED
        if cmd == mavlink.MAV_CMD_GET_HOME_POSITION:
            self._send_home_position()
            return CommandResult.ACCEPTED
        return CommandResult.UNSUPPORTED

    def _set_mode(self, base: float, main: float, sub: float) -> CommandResult:
        base_mode, main_mode = _finite(base), _finite(main)
        if base_mode is None or main_mode is None:
            return CommandResult.DENIED
        if not int(base_mode) & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return CommandResult.UNSUPPORTED
        sub_mode = _finite(sub)
        mode = FlightMode.from_px4(round(main_mode), round(sub_mode or 0.0))
        if mode is None:
            # manual modes need RC, missions need a mission: PX4 rejects the transition
            return CommandResult.TEMPORARILY_REJECTED
        return self._vehicle.request_mode(mode)

    # --- parameters -------------------------------------------------------------------------
    def _send_param(self, index: int) -> None:
        name = self._param_names[index]
        value = float(getattr(self.params, self._param_table[name]))
        self._conn.mav.param_value_send(
            name.encode(),
            value,
            mavlink.MAV_PARAM_TYPE_REAL32,
            len(self._param_names),
            index,
        )

    def _param_index(self, param_id: Any) -> int | None:
        name = param_id.decode() if isinstance(param_id, bytes) else str(param_id)
        name = name.rstrip("\x00")
        return self._param_names.index(name) if name in self._param_table else None

    def _handle_param_read(self, msg: Any) -> None:
        index = msg.param_index if msg.param_index >= 0 else self._param_index(msg.param_id)
        if index is not None and 0 <= index < len(self._param_names):
            self._send_param(index)

    def _handle_param_set(self, msg: Any) -> None:
        index = self._param_index(msg.param_id)
        if index is None:
            return
        field = self._param_table[self._param_names[index]]
        if math.isfinite(msg.param_value):
            try:
                checked = VehicleSimParams.model_validate(
                    {**self.params.model_dump(), field: float(msg.param_value)}
                )
            except ValueError:
                checked = None
            if checked is not None:
                # the same params object is shared by controller and commander: update in place
                setattr(self.params, field, getattr(checked, field))
        self._send_param(index)  # echo (the old value when rejected), as PX4 does

    # --- telemetry --------------------------------------------------------------------------
    def _reset_streams(self) -> None:
        p = self.params
        self._intervals_s: dict[int, float] = {
            mavlink.MAVLINK_MSG_ID_HEARTBEAT: 1.0 / p.heartbeat_rate_hz,
            mavlink.MAVLINK_MSG_ID_SYS_STATUS: 1.0 / p.status_rate_hz,
            mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 1.0 / p.status_rate_hz,
            mavlink.MAVLINK_MSG_ID_GPS_RAW_INT: 1.0 / p.status_rate_hz,
            mavlink.MAVLINK_MSG_ID_ATTITUDE: 1.0 / p.attitude_rate_hz,
            mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: 1.0 / p.attitude_rate_hz,
            mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 1.0 / p.position_rate_hz,
            mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 1.0 / p.position_rate_hz,
            mavlink.MAVLINK_MSG_ID_HOME_POSITION: 1.0 / p.slow_rate_hz,
            mavlink.MAVLINK_MSG_ID_BATTERY_STATUS: 1.0 / p.slow_rate_hz,
        }
        self._default_intervals_s = dict(self._intervals_s)
        self._next_due_s = dict.fromkeys(self._intervals_s, 0.0)
        self._measured: VehicleState | None = None

    def _set_message_interval(self, msg_id: float, interval_us: float) -> CommandResult:
        mid, interval = _finite(msg_id), _finite(interval_us)
        if mid is None or interval is None:
            return CommandResult.DENIED
        mid = round(mid)
        if mid not in self._intervals_s:
            return CommandResult.ACCEPTED if interval < 0 else CommandResult.UNSUPPORTED
        if interval == 0:
            self._intervals_s[mid] = self._default_intervals_s[mid]
        elif interval < 0:
            self._intervals_s[mid] = math.inf
        else:
            self._intervals_s[mid] = max(interval * 1e-6, 1.0 / self.params.physics_rate_hz)
        self._next_due_s[mid] = self._vehicle.time_s
        return CommandResult.ACCEPTED

    def _send_requested(self, msg_id: float) -> CommandResult:
        mid = _finite(msg_id)
        if mid is None:
            return CommandResult.DENIED
        mid = round(mid)
        if mid == mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            self._send_autopilot_version()
        elif mid in self._intervals_s:
            self._senders()[mid]()
        else:
            return CommandResult.UNSUPPORTED
        return CommandResult.ACCEPTED

    def _senders(self) -> dict[int, Callable[[], None]]:
        return {
            mavlink.MAVLINK_MSG_ID_HEARTBEAT: self._send_heartbeat,
            mavlink.MAVLINK_MSG_ID_SYS_STATUS: self._send_sys_status,
            mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: self._send_extended_sys_state,
            mavlink.MAVLINK_MSG_ID_GPS_RAW_INT: self._send_gps_raw,
            mavlink.MAVLINK_MSG_ID_ATTITUDE: self._send_attitude,
            mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: self._send_attitude_quaternion,
            mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: self._send_local_position,
            mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: self._send_global_position,
            mavlink.MAVLINK_MSG_ID_HOME_POSITION: self._send_home_position,
            mavlink.MAVLINK_MSG_ID_BATTERY_STATUS: self._send_battery_status,
        }

    def _emit_due(self) -> None:
        now = self._vehicle.time_s
        self._measured = None
        senders = self._senders()
        for mid, due in self._next_due_s.items():
            if now + 1e-9 >= due:
                senders[mid]()
                interval = self._intervals_s[mid]
                # accumulate deadlines (no drift); skip missed ones rather than burst
                self._next_due_s[mid] = (
                    max(due + interval, now) if math.isfinite(interval) else (math.inf)
                )
        while self._vehicle.status_texts:
            text = self._vehicle.status_texts.popleft()
            self._conn.mav.statustext_send(text.severity, text.text.encode())

    def _estimate(self) -> VehicleState:
        """What the EKF reports: truth plus configured white noise (seeded), cached per step."""
        if self._measured is not None:
            return self._measured
        truth = self._vehicle.truth
        p = self.params
        if (
            p.position_noise_std_m == 0.0
            and p.velocity_noise_std_mps == 0.0
            and p.attitude_noise_std_rad == 0.0
        ):
            self._measured = truth
            return truth
        rng = self._sensor_rng
        euler = np.array(truth.euler_rad()) + rng.normal(0.0, p.attitude_noise_std_rad, 3)
        self._measured = dataclasses.replace(
            truth,
            position_ned_m=truth.position_ned_m + rng.normal(0.0, p.position_noise_std_m, 3),
            velocity_ned_mps=truth.velocity_ned_mps + rng.normal(0.0, p.velocity_noise_std_mps, 3),
            attitude_wxyz=quaternion_from_euler(*euler),
        )
        return self._measured

    def _time_boot_ms(self) -> int:
        return int(self._vehicle.time_s * 1000.0) & 0xFFFFFFFF

    def _send_heartbeat(self) -> None:
        v = self._vehicle
        base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        main_mode = v.mode.value[0]
        if main_mode == PX4_MAIN_MODE_AUTO:
            base |= (
                mavlink.MAV_MODE_FLAG_AUTO_ENABLED
                | mavlink.MAV_MODE_FLAG_GUIDED_ENABLED
                | mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED
            )
        elif main_mode == PX4_MAIN_MODE_OFFBOARD:
            base |= mavlink.MAV_MODE_FLAG_GUIDED_ENABLED | mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED
        if v.armed:
            base |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        if not v.healthy:
            state = mavlink.MAV_STATE_BOOT
        else:
            state = mavlink.MAV_STATE_ACTIVE if v.armed else mavlink.MAV_STATE_STANDBY
        self._conn.mav.heartbeat_send(
            mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, base, v.mode.custom_mode, state
        )

    def _battery(self) -> tuple[float, int]:
        """(voltage V, remaining %) from a linear discharge over the hover endurance."""
        p = self.params
        flown_fraction = min(self._vehicle.time_s / p.battery_endurance_s, 1.0)
        remaining = 1.0 - flown_fraction if self._vehicle.armed else 1.0 - 0.5 * flown_fraction
        voltage = p.battery_cells * (3.5 + 0.7 * remaining)
        return voltage, round(100 * remaining)

    def _send_sys_status(self) -> None:
        v = self._vehicle
        # healthy sensors and pre-arm bit once the estimator converged (MAVSDK: health_all_ok,
        # is_armable); arming may still be denied for a while after that (see Px4Vehicle.arm)
        health = _SENSORS | mavlink.MAV_SYS_STATUS_PREARM_CHECK if v.healthy else 0
        voltage, remaining = self._battery()
        self._conn.mav.sys_status_send(
            _SENSORS | mavlink.MAV_SYS_STATUS_PREARM_CHECK,
            _SENSORS | mavlink.MAV_SYS_STATUS_PREARM_CHECK,
            health,
            250,
            round(voltage * 1000),
            -1,
            remaining,
            0,
            0,
            0,
            0,
            0,
            0,
        )

    def _send_battery_status(self) -> None:
        voltage, remaining = self._battery()
        voltages = [round(voltage * 1000)] + [65535] * 9
        self._conn.mav.battery_status_send(
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
        self._conn.mav.extended_sys_state_send(
            mavlink.MAV_VTOL_STATE_UNDEFINED, int(self._vehicle.landed_state)
        )

    def _send_attitude(self) -> None:
        s = self._estimate()
        roll, pitch, yaw = s.euler_rad()
        w = s.angular_velocity_frd_radps
        self._conn.mav.attitude_send(
            self._time_boot_ms(), roll, pitch, yaw, float(w[0]), float(w[1]), float(w[2])
        )

    def _send_attitude_quaternion(self) -> None:
        s = self._estimate()
        w = s.angular_velocity_frd_radps
        self._conn.mav.attitude_quaternion_send(
            self._time_boot_ms(),
            *map(float, s.attitude_wxyz),
            float(w[0]),
            float(w[1]),
            float(w[2]),
        )

    def _send_local_position(self) -> None:
        s = self._estimate()
        p, v = s.position_ned_m, s.velocity_ned_mps
        self._conn.mav.local_position_ned_send(self._time_boot_ms(), *map(float, p), *map(float, v))

    def _send_global_position(self) -> None:
        s = self._estimate()
        lat, lon, alt = global_from_local(s.position_ned_m, self.params)
        v = s.velocity_ned_mps
        heading_cdeg = round(math.degrees(s.yaw_rad) % 360.0 * 100) % 36000
        self._conn.mav.global_position_int_send(
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
        self._conn.mav.gps_raw_int_send(
            round(self._vehicle.time_s * 1e6),
            mavlink.GPS_FIX_TYPE_3D_FIX if self._vehicle.healthy else mavlink.GPS_FIX_TYPE_NO_FIX,
            round(lat * 1e7),
            round(lon * 1e7),
            round(alt * 1000),
            70,
            90,
            round(ground_speed * 100),
            cog,
            12,
        )

    def _send_home_position(self) -> None:
        p = self.params
        self._conn.mav.home_position_send(
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
            round(self._vehicle.time_s * 1e6),
        )

    def _send_autopilot_version(self) -> None:
        major, minor, patch = PX4_VERSION
        version = (major << 24) | (minor << 16) | (patch << 8) | 255  # FIRMWARE_VERSION_TYPE
        self._conn.mav.autopilot_version_send(
            _CAPABILITIES,
            version,
            version,
            0,
            0,
            [0] * 8,
            [0] * 8,
            [0] * 8,
            0,
            0,
            0x5157_4145_0000_0000 + (self._vehicle.seed & 0xFFFF),
        )


def wait_for(predicate: Callable[[], bool], timeout_s: float, poll_s: float = 0.01) -> bool:
    """Wall-clock wait (real-time mode helper for tests and the CLI): True once `predicate()`."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(poll_s)
    return predicate()
