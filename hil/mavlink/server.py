"""The SIL vehicle on the wire: a `Px4Vehicle` speaking MAVLink 2 over UDP like PX4 SITL.

Like PX4 SITL's offboard link, it *sends* to HOST:PORT (the client listens there, e.g. MAVSDK
`udpin://0.0.0.0:PORT`) and reads the client's replies on the same socket (pymavlink `udpout:`).
Identity: sysid 1, compid 1 (autopilot), MAV_AUTOPILOT_PX4, MAV_TYPE_QUADROTOR.

Time: fixed physics steps of 1/`physics_rate_hz` simulated seconds. With `speed` (real-time
factor, 1.0 = real time) a thread paces them against the wall clock; with `lockstep=True` no
thread runs and the caller advances simulated time with `advance(dt_s)`, which is deterministic
for a given seed and message order. Telemetry rates are in simulated time (`streams`).

What it answers, as PX4 does:
- commands (COMMAND_LONG / COMMAND_INT, each ACKed): arm/disarm, takeoff, land, RTL,
  DO_SET_MODE, SET_MESSAGE_INTERVAL, REQUEST_MESSAGE (AUTOPILOT_VERSION, PROTOCOL_VERSION,
  COMPONENT_METADATA, AVAILABLE_MODES, CURRENT_MODE, FLIGHT_INFORMATION, HOME_POSITION and
  every streamed message), REQUEST_AUTOPILOT_CAPABILITIES, REQUEST_PROTOCOL_VERSION,
  REQUEST_FLIGHT_INFORMATION, RUN_PREARM_CHECKS (the health and arming check report),
  GET_HOME_POSITION; others UNSUPPORTED;
- SET_POSITION_TARGET_LOCAL_NED (offboard), the companion's HEARTBEAT (COM_OBC_LOSS_T);
- PX4's 888 parameters (`hil.vehicle.px4_parameters`; the simulated ones live);
- mission, geofence and rally lists (count 0; uploads of an empty list ACKed), PING, TIMESYNC,
  MAVFTP (`ftp`: the component metadata) and REQUEST_EVENT (`events`).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

import numpy as np

from geometry.rotation import euler_from_quaternion
from hil.clock import RealTimePacer
from hil.mavlink import extra_messages as xm
from hil.mavlink.dialect import mavlink, mavutil
from hil.mavlink.events import general_metadata_uri_and_crc, metadata_files
from hil.mavlink.ftp import FtpServer
from hil.mavlink.streams import TelemetryStreams, global_from_local
from hil.vehicle.params import VehicleSimParams
from hil.vehicle.px4_controller import TrajectorySetpoint
from hil.vehicle.px4_modes import CommandResult, MavLandedState, Px4Mode, Px4Vehicle
from hil.vehicle.px4_parameters import ParameterValue, Px4ParameterTable, encode_param_value
from hil.vehicle.state import RigidBodyState

__all__ = ["VehicleServer", "global_from_local", "mavlink", "mavutil", "wait_for"]

_log = logging.getLogger(__name__)

PX4_VERSION = (1, 17, 0)  # PX4-Autopilot main, March 2026
FORCE_MAGIC = 21196
_CAPABILITIES = (
    mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT
    | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
    | mavlink.MAV_PROTOCOL_CAPABILITY_FTP
    | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
    | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE
    | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY
    | mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
)
_COMPANION_COMPONENTS = range(
    mavlink.MAV_COMP_ID_ONBOARD_COMPUTER, mavlink.MAV_COMP_ID_ONBOARD_COMPUTER4 + 1
)
MAVLINK_PROTOCOL_VERSION = 200
PARAMS_PER_TICK = 4  # PARAM_VALUEs of a PARAM_REQUEST_LIST per physics step (1000/s at 250 Hz)


def _finite(value: float) -> float | None:
    return float(value) if value is not None and math.isfinite(value) else None


def setpoint_from_position_target(msg: Any, yaw_now_rad: float) -> TrajectorySetpoint:
    """A `TrajectorySetpoint` from SET_POSITION_TARGET_LOCAL_NED honouring its type_mask.

    Ignored or non-finite fields become NaN (uncontrolled). Body frames (BODY_NED, BODY_FRD,
    BODY_OFFSET_NED) rotate x/y by the current yaw like PX4; position in them is an offset.
    The acceleration is a feed-forward (PX4's trajectory_setpoint); as force it is ignored.
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
    as_force = mask & mavlink.POSITION_TARGET_TYPEMASK_FORCE_SET
    acc_ignore = (
        mavlink.POSITION_TARGET_TYPEMASK_AX_IGNORE,
        mavlink.POSITION_TARGET_TYPEMASK_AY_IGNORE,
        mavlink.POSITION_TARGET_TYPEMASK_AZ_IGNORE,
    )
    acc = np.array(
        [
            value if not mask & bit and not as_force else np.nan
            for value, bit in zip((msg.afx, msg.afy, msg.afz), acc_ignore, strict=True)
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
        acc[:2] = rot @ acc[:2]
    return TrajectorySetpoint(
        position_ned_m=pos,
        velocity_ned_mps=vel,
        acceleration_ned_mps2=acc,
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
        self._parameters = Px4ParameterTable(self.params)
        self._ftp = FtpServer(metadata_files())
        self._vehicle = Px4Vehicle(self.params)
        self._streams: TelemetryStreams | None = None
        self._arming_time_s: float | None = None
        self._takeoff_time_s: float | None = None
        self._param_queue: deque[int] = deque()
        self.error: BaseException | None = None
        self.message_errors: deque[str] = deque(maxlen=32)

    # --- lifecycle --------------------------------------------------------------------------
    def start(self) -> VehicleServer:
        """Boot the vehicle and open the link; returns once it is running."""
        with self._lock:
            if self._conn is not None:
                return self
            self._vehicle = Px4Vehicle(self.params)
            self._conn = mavutil.mavlink_connection(
                f"udpout:{self.host}:{self.port}", source_system=1, source_component=1
            )
            self._conn.mav.srcSystem, self._conn.mav.srcComponent = 1, 1
            self._streams = TelemetryStreams(self._conn, self._vehicle, self.params)
            self._arming_time_s = self._takeoff_time_s = None
            self._param_queue.clear()
            self._stop_event.clear()
            self._streams.emit_due()
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
    def truth(self) -> RigidBodyState:
        """Ground-truth state now (an immutable snapshot)."""
        with self._lock:
            return self._vehicle.truth

    @property
    def time_s(self) -> float:
        """Simulated seconds since boot."""
        with self._lock:
            return self._vehicle.time_s

    @property
    def flight_mode(self) -> Px4Mode:
        """The current flight mode."""
        with self._lock:
            return self._vehicle.mode

    @property
    def armed(self) -> bool:
        """Motors armed."""
        with self._lock:
            return self._vehicle.armed

    @property
    def landed_state(self) -> MavLandedState:
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
    def advance(self, dt_s: float) -> RigidBodyState:
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
            if self._conn is None or self._streams is None:
                return
            self._receive_all()
            was_armed, was_landed = self._vehicle.armed, self._vehicle.landed
            self._vehicle.step(h)
            if self._vehicle.armed and not was_armed:
                self._arming_time_s, self._takeoff_time_s = self._vehicle.time_s, None
            if was_landed and not self._vehicle.landed and self._vehicle.armed:
                self._takeoff_time_s = self._vehicle.time_s
            self._streams.emit_due()
            for _ in range(min(PARAMS_PER_TICK, len(self._param_queue))):
                self._send_param(self._parameters.at(self._param_queue.popleft()))

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
        if kind.startswith("UNKNOWN_"):
            self._handle_extra(msg)
            return
        if getattr(msg, "target_system", 1) not in (0, 1):
            return
        if getattr(msg, "target_component", 1) not in (0, 1):
            return
        handler = self._handlers().get(kind)
        if handler is not None:
            handler(msg)

    def _handlers(self) -> dict[str, Callable[[Any], None]]:
        return {
            "COMMAND_LONG": self._handle_command,
            "COMMAND_INT": self._handle_command,
            "SET_POSITION_TARGET_LOCAL_NED": self._handle_position_target,
            "PARAM_REQUEST_READ": self._handle_param_read,
            "PARAM_REQUEST_LIST": self._handle_param_list,
            "PARAM_SET": self._handle_param_set,
            "TIMESYNC": self._handle_timesync,
            "PING": self._handle_ping,
            "MISSION_REQUEST_LIST": self._handle_mission_request_list,
            "MISSION_COUNT": self._handle_mission_count,
            "MISSION_CLEAR_ALL": self._handle_mission_clear_all,
            "FILE_TRANSFER_PROTOCOL": self._handle_ftp,
        }

    def _handle_heartbeat(self, msg: Any) -> None:
        if msg.type == mavlink.MAV_TYPE_GCS:
            return
        if (
            msg.type == mavlink.MAV_TYPE_ONBOARD_CONTROLLER
            or msg.get_srcComponent() in _COMPANION_COMPONENTS
        ):
            self._vehicle.companion_heartbeat()

    def _handle_position_target(self, msg: Any) -> None:
        yaw = euler_from_quaternion(self._vehicle.estimate.attitude_wxyz)[2]
        self._vehicle.offboard_setpoint(setpoint_from_position_target(msg, yaw))

    def _handle_timesync(self, msg: Any) -> None:
        if msg.tc1 == 0:
            self._conn.mav.timesync_send(int(self._vehicle.time_s * 1e9), msg.ts1)

    def _handle_ping(self, msg: Any) -> None:
        if msg.target_system == 0:  # a request (a reply to our own ping names us)
            self._conn.mav.ping_send(
                msg.time_usec, msg.seq, msg.get_srcSystem(), msg.get_srcComponent()
            )

    def _handle_mission_request_list(self, msg: Any) -> None:
        # no mission, geofence or rally points: PX4 answers the count (0) of the asked type
        self._conn.mav.mission_count_send(
            msg.get_srcSystem(), msg.get_srcComponent(), 0, msg.mission_type
        )

    def _handle_mission_count(self, msg: Any) -> None:
        result = mavlink.MAV_MISSION_ACCEPTED if msg.count == 0 else mavlink.MAV_MISSION_UNSUPPORTED
        self._conn.mav.mission_ack_send(
            msg.get_srcSystem(), msg.get_srcComponent(), result, msg.mission_type
        )

    def _handle_mission_clear_all(self, msg: Any) -> None:
        self._conn.mav.mission_ack_send(
            msg.get_srcSystem(),
            msg.get_srcComponent(),
            mavlink.MAV_MISSION_ACCEPTED,
            msg.mission_type,
        )

    def _handle_ftp(self, msg: Any) -> None:
        for payload in self._ftp.handle(msg.payload):
            self._conn.mav.file_transfer_protocol_send(
                0, msg.get_srcSystem(), msg.get_srcComponent(), list(payload)
            )

    def _handle_extra(self, msg: Any) -> None:
        parsed = xm.parse_unknown(msg)
        if parsed is None or self._streams is None:
            return
        definition, fields = parsed
        if definition is xm.REQUEST_EVENT and fields["target_system"] in (0, 1):
            for answer in self._streams.events.requested(fields, xm.source_of(msg)):
                self._conn.mav.send(answer)

    # --- commands ---------------------------------------------------------------------------
    def _handle_command(self, msg: Any) -> None:
        try:
            result = self._command_result(msg)
        except (ValueError, OverflowError, TypeError):
            result = CommandResult.DENIED
        self._conn.mav.command_ack_send(
            msg.command, int(result), 0, 0, msg.get_srcSystem(), msg.get_srcComponent()
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
            return self._send_requested(p1, p2)
        if cmd == mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            self._send_autopilot_version()
            return CommandResult.ACCEPTED
        if cmd == mavlink.MAV_CMD_REQUEST_PROTOCOL_VERSION:
            self._send_protocol_version()
            return CommandResult.ACCEPTED
        if cmd == mavlink.MAV_CMD_REQUEST_FLIGHT_INFORMATION:
            self._send_flight_information()
            return CommandResult.ACCEPTED
        if cmd == mavlink.MAV_CMD_RUN_PREARM_CHECKS:
            assert self._streams is not None
            self._streams.send_health_report()
            return CommandResult.ACCEPTED
        if cmd == mavlink.MAV_CMD_GET_HOME_POSITION:
            assert self._streams is not None
            self._streams.send_home_position()
            return CommandResult.ACCEPTED
        return CommandResult.UNSUPPORTED

    def _set_mode(self, base: float, main: float, sub: float) -> CommandResult:
        base_mode, main_mode = _finite(base), _finite(main)
        if base_mode is None or main_mode is None:
            return CommandResult.DENIED
        if not int(base_mode) & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return CommandResult.UNSUPPORTED
        sub_mode = _finite(sub)
        mode = Px4Mode.from_px4(round(main_mode), round(sub_mode or 0.0))
        if mode is None:
            # manual modes need RC, missions need a mission: PX4 rejects the transition
            return CommandResult.TEMPORARILY_REJECTED
        return self._vehicle.request_mode(mode)

    def _set_message_interval(self, msg_id: float, interval_us: float) -> CommandResult:
        assert self._streams is not None
        mid, interval = _finite(msg_id), _finite(interval_us)
        if mid is None or interval is None:
            return CommandResult.DENIED
        mid = round(mid)
        if not self._streams.can_send(mid):
            return CommandResult.ACCEPTED if interval < 0 else CommandResult.UNSUPPORTED
        self._streams.set_interval(mid, interval)
        return CommandResult.ACCEPTED

    def _send_requested(self, msg_id: float, param2: float) -> CommandResult:
        assert self._streams is not None
        mid = _finite(msg_id)
        if mid is None:
            return CommandResult.DENIED
        mid = round(mid)
        one_off: dict[int, Callable[[], None]] = {
            mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION: self._send_autopilot_version,
            xm.PROTOCOL_VERSION.msg_id: self._send_protocol_version,
            xm.COMPONENT_METADATA.msg_id: self._send_component_metadata,
            mavlink.MAVLINK_MSG_ID_FLIGHT_INFORMATION: self._send_flight_information,
            mavlink.MAVLINK_MSG_ID_AVAILABLE_MODES: lambda: self._streams.send_available_modes(
                round(_finite(param2) or 0.0)
            ),
        }
        if mid in one_off:
            one_off[mid]()
        elif self._streams.can_send(mid):
            self._streams.send_now(mid)
        else:
            return CommandResult.UNSUPPORTED
        return CommandResult.ACCEPTED

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

    def _send_protocol_version(self) -> None:
        self._conn.mav.send(
            xm.message(
                xm.PROTOCOL_VERSION,
                version=MAVLINK_PROTOCOL_VERSION,
                min_version=100,
                max_version=MAVLINK_PROTOCOL_VERSION,
                spec_version_hash=bytes(8),
                library_version_hash=bytes(8),
            )
        )

    def _send_component_metadata(self) -> None:
        uri, crc = general_metadata_uri_and_crc()
        self._conn.mav.send(
            xm.message(
                xm.COMPONENT_METADATA,
                time_boot_ms=int(self._vehicle.time_s * 1000) & 0xFFFFFFFF,
                file_crc=crc,
                uri=uri.encode(),
            )
        )

    def _send_flight_information(self) -> None:
        assert self._streams is not None
        boot_unix_us = self._streams.unix_usec() - round(self._vehicle.time_s * 1e6)

        def utc(t_s: float | None) -> int:
            return 0 if t_s is None else boot_unix_us + round(t_s * 1e6)

        self._conn.mav.flight_information_send(
            int(self._vehicle.time_s * 1000) & 0xFFFFFFFF,
            utc(self._arming_time_s),
            utc(self._takeoff_time_s),
            self._vehicle.seed & 0xFFFFFFFFFFFFFFFF,
            0,
        )

    # --- parameters -------------------------------------------------------------------------
    def _send_param(self, value: ParameterValue) -> None:
        self._conn.mav.param_value_send(
            value.name.encode(),
            encode_param_value(value.value, value.param_type),
            value.param_type,
            value.count,
            value.index,
        )

    @staticmethod
    def _param_name(param_id: Any) -> str:
        name = param_id.decode() if isinstance(param_id, bytes) else str(param_id)
        return name.rstrip("\x00")

    def _handle_param_read(self, msg: Any) -> None:
        table = self._parameters
        if msg.param_index >= 0:
            if msg.param_index < len(table):
                self._send_param(table.at(msg.param_index))
            return
        name = self._param_name(msg.param_id)
        if table.index_of(name) is not None:
            self._send_param(table.get(name))

    def _handle_param_list(self, _msg: Any) -> None:
        # paced like PX4's parameter streaming, so a receiver's socket buffer keeps up
        queued = set(self._param_queue)
        self._param_queue.extend(i for i in range(len(self._parameters)) if i not in queued)

    def _handle_param_set(self, msg: Any) -> None:
        name = self._param_name(msg.param_id)
        if self._parameters.index_of(name) is None:
            return
        # the echo carries the old value when the set is rejected, as PX4 does
        self._send_param(self._parameters.set(name, msg.param_value))


def wait_for(predicate: Callable[[], bool], timeout_s: float, poll_s: float = 0.01) -> bool:
    """Wall-clock wait (real-time mode helper for tests and the CLI): True once `predicate()`."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(poll_s)
    return predicate()
