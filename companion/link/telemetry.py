"""Typed, timestamped telemetry snapshots of the vehicle, independent of MAVSDK's types.

`TelemetryCache` collects updates as they arrive (each group stamped with the monotonic time of
its arrival, since MAVSDK's streams carry no sample time) and hands out immutable
`TelemetrySnapshot`s. A group never received is None: unknown, not zero. Frames: positions and
velocities NED relative to the autopilot's local origin (m, m/s); attitude as roll, pitch,
yaw of the FRD body in NED (rad).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from enum import Enum

import numpy as np

from geometry.pose import Pose
from planning.types import VehicleState


class FlightMode(Enum):
    """PX4 flight modes as MAVSDK names them (the names match `mavsdk...FlightMode`)."""

    UNKNOWN = "UNKNOWN"
    READY = "READY"
    TAKEOFF = "TAKEOFF"
    HOLD = "HOLD"
    MISSION = "MISSION"
    RETURN_TO_LAUNCH = "RETURN_TO_LAUNCH"
    LAND = "LAND"
    OFFBOARD = "OFFBOARD"
    FOLLOW_ME = "FOLLOW_ME"
    MANUAL = "MANUAL"
    ALTCTL = "ALTCTL"
    POSCTL = "POSCTL"
    ACRO = "ACRO"
    STABILIZED = "STABILIZED"
    RATTITUDE = "RATTITUDE"

    @classmethod
    def from_name(cls, name: str) -> FlightMode:
        """The mode called `name`; UNKNOWN for a name this enum does not know."""
        return cls.__members__.get(name, cls.UNKNOWN)


class LandedState(Enum):
    """EXTENDED_SYS_STATE landed state."""

    UNKNOWN = "UNKNOWN"
    ON_GROUND = "ON_GROUND"
    IN_AIR = "IN_AIR"
    TAKING_OFF = "TAKING_OFF"
    LANDING = "LANDING"

    @classmethod
    def from_name(cls, name: str) -> LandedState:
        """The state called `name`; UNKNOWN for a name this enum does not know."""
        return cls.__members__.get(name, cls.UNKNOWN)


@dataclass(frozen=True)
class LocalPosition:
    """Local position and velocity, NED from the autopilot's origin, at `stamp_s` (monotonic)."""

    position_ned_m: np.ndarray  # (3,) float64, NED, m
    velocity_ned_mps: np.ndarray  # (3,) float64, NED, m/s
    stamp_s: float

    @property
    def altitude_m(self) -> float:
        """Height above the local origin (-down), m."""
        return float(-self.position_ned_m[2])

    @property
    def speed_mps(self) -> float:
        """Norm of the NED velocity, m/s."""
        return float(np.linalg.norm(self.velocity_ned_mps))


@dataclass(frozen=True)
class Attitude:
    """Euler angles of the FRD body in NED (rad), at `stamp_s` (monotonic)."""

    roll_rad: float
    pitch_rad: float
    yaw_rad: float
    stamp_s: float


@dataclass(frozen=True)
class Battery:
    """Battery state; NaN fields are not reported by the vehicle."""

    voltage_v: float
    remaining_frac: float  # 0..1
    stamp_s: float


@dataclass(frozen=True)
class Home:
    """PX4's home (set at arming): WGS84 latitude and longitude (deg), altitude above mean sea
    level (m), and where it lies in the local NED frame (3,), m; NaN where not reported."""

    lat_deg: float
    lon_deg: float
    alt_amsl_m: float
    position_ned_m: np.ndarray
    stamp_s: float


@dataclass(frozen=True)
class Health:
    """Pre-flight health flags as reported in SYS_STATUS / HOME_POSITION."""

    local_position_ok: bool
    global_position_ok: bool
    home_position_ok: bool
    armable: bool
    sensors_calibrated: bool
    stamp_s: float

    @property
    def ready_to_fly(self) -> bool:
        """Whether the vehicle can arm and hold position."""
        return self.local_position_ok and self.home_position_ok and self.armable


@dataclass(frozen=True)
class TelemetrySnapshot:
    """Everything known about the vehicle at `stamp_s` (monotonic, s). None: never received."""

    stamp_s: float
    last_update_s: float | None
    pose: LocalPosition | None = None
    attitude: Attitude | None = None
    flight_mode: FlightMode = FlightMode.UNKNOWN
    flight_mode_stamp_s: float | None = None
    armed: bool | None = None
    landed_state: LandedState = LandedState.UNKNOWN
    battery: Battery | None = None
    health: Health | None = None
    home: Home | None = None

    def age_s(self) -> float:
        """Time since the last update of any kind, s (inf when nothing ever arrived)."""
        return math.inf if self.last_update_s is None else self.stamp_s - self.last_update_s

    def vehicle_state(self) -> VehicleState | None:
        """The planner's `VehicleState` (stamped with the local position's arrival), or None
        before both a local position and an attitude arrived."""
        if self.pose is None or self.attitude is None:
            return None
        return VehicleState(
            self.pose.stamp_s,
            self.pose.position_ned_m,
            self.pose.velocity_ned_mps,
            self.attitude.yaw_rad,
        )

    def world_from_body(self) -> Pose | None:
        """The vehicle's pose, body FRD in local NED (attitude and position), or None."""
        if self.pose is None or self.attitude is None:
            return None
        a = self.attitude
        return Pose.from_yaw_pitch_roll(
            a.yaw_rad, a.pitch_rad, a.roll_rad, self.pose.position_ned_m
        )


class TelemetryCache:
    """Latest value of each telemetry group, each stamped with its arrival time (monotonic, s).

    Pure: the caller passes `now_s` in. `clear()` forgets everything (after the link is
    rebuilt, old values must not pass for the vehicle's current state).
    """

    def __init__(self) -> None:
        self._snapshot = TelemetrySnapshot(stamp_s=0.0, last_update_s=None)

    def clear(self) -> None:
        """Forget every value: all groups become unknown."""
        self._snapshot = TelemetrySnapshot(stamp_s=0.0, last_update_s=None)

    def _update(self, now_s: float, **fields: object) -> None:
        self._snapshot = replace(self._snapshot, last_update_s=now_s, **fields)

    def update_pose(
        self, position_ned_m: np.ndarray, velocity_ned_mps: np.ndarray, now_s: float
    ) -> None:
        """Record a local position (3,) NED m and velocity (3,) NED m/s."""
        pose = LocalPosition(
            np.asarray(position_ned_m, dtype=np.float64).reshape(3).copy(),
            np.asarray(velocity_ned_mps, dtype=np.float64).reshape(3).copy(),
            now_s,
        )
        self._update(now_s, pose=pose)

    def update_attitude(
        self, roll_rad: float, pitch_rad: float, yaw_rad: float, now_s: float
    ) -> None:
        """Record the attitude, rad."""
        self._update(now_s, attitude=Attitude(roll_rad, pitch_rad, yaw_rad, now_s))

    def update_flight_mode(self, mode: FlightMode, now_s: float) -> None:
        """Record the flight mode (arrives with each HEARTBEAT)."""
        self._update(now_s, flight_mode=mode, flight_mode_stamp_s=now_s)

    def update_armed(self, armed: bool, now_s: float) -> None:
        """Record whether the motors are armed."""
        self._update(now_s, armed=bool(armed))

    def update_landed_state(self, state: LandedState, now_s: float) -> None:
        """Record the landed state."""
        self._update(now_s, landed_state=state)

    def update_battery(self, voltage_v: float, remaining_frac: float, now_s: float) -> None:
        """Record the battery voltage (V) and remaining charge (0..1)."""
        self._update(now_s, battery=Battery(float(voltage_v), float(remaining_frac), now_s))

    def update_home(
        self,
        lat_deg: float,
        lon_deg: float,
        alt_amsl_m: float,
        position_ned_m: np.ndarray,
        now_s: float,
    ) -> None:
        """Record the home position (WGS84 deg, AMSL m, local NED m)."""
        local = np.asarray(position_ned_m, dtype=np.float64).reshape(3).copy()
        self._update(now_s, home=Home(lat_deg, lon_deg, alt_amsl_m, local, now_s))

    def update_health(self, health: Health, now_s: float) -> None:
        """Record the health flags."""
        self._update(now_s, health=health)

    def snapshot(self, now_s: float) -> TelemetrySnapshot:
        """The immutable state as of `now_s`."""
        return replace(self._snapshot, stamp_s=now_s)
