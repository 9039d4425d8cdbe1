"""PX4's commander and navigator in miniature: arming, flight modes, failsafes, land detector.

`Px4Vehicle` wraps a `Multirotor` and is pure and synchronous like it: every request takes the
simulated time `now_s` implicitly from the vehicle clock, `step(dt_s)` advances both. The MAVLink
server (`hil.vehicle_server`) only translates messages to these calls, so every PX4 behaviour
here is testable in lockstep without sockets.

Behaviours reproduced (PX4 v1.14): arming checks and "arming denied right after boot";
takeoff to MIS_TAKEOFF_ALT then the navigator's switch to Hold; land with land detection and
auto-disarm (COM_DISARM_LAND) and preflight auto-disarm (COM_DISARM_PRFLT); RTL (climb, return,
land); Offboard entry only with a setpoint younger than 0.5 s; offboard loss (COM_OF_LOSS_T)
and companion loss (COM_OBC_LOSS_T) failsafes to Hold; the end-of-takeoff Hold race.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from enum import Enum, IntEnum

import numpy as np

from hil.multirotor import Multirotor, VehicleState
from hil.params import VehicleSimParams
from hil.px4_controller import TrajectorySetpoint

# PX4 custom main modes and auto sub modes (px4_custom_mode.h)
PX4_MAIN_MODE_MANUAL = 1
PX4_MAIN_MODE_ALTCTL = 2
PX4_MAIN_MODE_POSCTL = 3
PX4_MAIN_MODE_AUTO = 4
PX4_MAIN_MODE_ACRO = 5
PX4_MAIN_MODE_OFFBOARD = 6
PX4_MAIN_MODE_STABILIZED = 7
PX4_AUTO_SUB_MODE_READY = 1
PX4_AUTO_SUB_MODE_TAKEOFF = 2
PX4_AUTO_SUB_MODE_LOITER = 3
PX4_AUTO_SUB_MODE_MISSION = 4
PX4_AUTO_SUB_MODE_RTL = 5
PX4_AUTO_SUB_MODE_LAND = 6


class FlightMode(Enum):
    """The navigation states this vehicle flies, with their PX4 (main, sub) custom mode."""

    HOLD = (PX4_MAIN_MODE_AUTO, PX4_AUTO_SUB_MODE_LOITER)
    TAKEOFF = (PX4_MAIN_MODE_AUTO, PX4_AUTO_SUB_MODE_TAKEOFF)
    LAND = (PX4_MAIN_MODE_AUTO, PX4_AUTO_SUB_MODE_LAND)
    RTL = (PX4_MAIN_MODE_AUTO, PX4_AUTO_SUB_MODE_RTL)
    OFFBOARD = (PX4_MAIN_MODE_OFFBOARD, 0)

    @property
    def custom_mode(self) -> int:
        """HEARTBEAT.custom_mode: main << 16 | sub << 24."""
        main, sub = self.value
        return (main << 16) | (sub << 24)

    @classmethod
    def from_px4(cls, main_mode: int, sub_mode: int) -> FlightMode | None:
        """The mode of a DO_SET_MODE (main, sub) pair; None when this vehicle has no such mode."""
        for mode in cls:
            if mode.value == (main_mode, sub_mode if main_mode == PX4_MAIN_MODE_AUTO else 0):
                return mode
        return None


class CommandResult(IntEnum):
    """MAV_RESULT values."""

    ACCEPTED = 0
    TEMPORARILY_REJECTED = 1
    DENIED = 2
    UNSUPPORTED = 3
    FAILED = 4


class LandedState(IntEnum):
    """MAV_LANDED_STATE values."""

    UNDEFINED = 0
    ON_GROUND = 1
    IN_AIR = 2
    TAKEOFF = 3
    LANDING = 4


@dataclass(frozen=True)
class StatusText:
    """A STATUSTEXT to publish: MAV_SEVERITY and text (<= 50 chars)."""

    severity: int
    text: str


SEVERITY_CRITICAL = 2
SEVERITY_WARNING = 4
SEVERITY_INFO = 6


class RtlPhase(Enum):
    """Phases of Return mode: climb to RTL_RETURN_ALT, fly home, descend and land."""

    CLIMB = "climb"
    RETURN = "return"
    DESCEND = "descend"


class Px4Vehicle:
    """A PX4-like autopilot around a `Multirotor`. Boots at time 0, disarmed, in Hold on the ground.

    Not thread-safe: the MAVLink server holds a lock around every call.
    """

    def __init__(self, params: VehicleSimParams, seed: int | None = None) -> None:
        self.params = params
        self.seed = params.seed if seed is None else seed
        self.body = Multirotor(params, seed=self.seed)
        self.body.motors_enabled = False
        self._quirk_rng = np.random.default_rng([self.seed, 0x7A6E])
        self.armed = False
        self.mode = FlightMode.HOLD
        self.status_texts: deque[StatusText] = deque(maxlen=64)
        self._hold_position = np.zeros(3)
        self._hold_yaw_rad = 0.0
        self._takeoff_target_z_m = 0.0
        self._takeoff_completed_s = -math.inf
        self._has_taken_off_since_arming = False
        self._armed_at_s = -math.inf
        self._ground_since_s: float | None = 0.0
        self._landed = True
        self._land_xy = np.zeros(2)
        self._rtl_phase = RtlPhase.CLIMB
        self._rtl_wait_since_s: float | None = None
        self._offboard_setpoint: TrajectorySetpoint | None = None
        self._offboard_setpoint_s = -math.inf
        self._companion_seen_s: float | None = None
        self._race_hold_at_s: float | None = None
        self._latch_hold()

    # --- read-only status -------------------------------------------------------------------
    @property
    def time_s(self) -> float:
        """Simulated seconds since boot."""
        return self.body.time_s

    @property
    def truth(self) -> VehicleState:
        """Ground truth of the body."""
        return self.body.state

    @property
    def healthy(self) -> bool:
        """Sensors, estimator and pre-arm checks pass (simulated convergence after boot)."""
        return self.time_s >= self.params.health_ok_after_boot_s

    @property
    def landed(self) -> bool:
        """PX4's land detector: on the ground (maybe landed for land_detect_time_s)."""
        return self._landed

    @property
    def landed_state(self) -> LandedState:
        """EXTENDED_SYS_STATE.landed_state."""
        if self._landed:
            return LandedState.ON_GROUND
        if self.mode is FlightMode.TAKEOFF:
            return LandedState.TAKEOFF
        if self.mode is FlightMode.LAND or (
            self.mode is FlightMode.RTL and self._rtl_phase == RtlPhase.DESCEND
        ):
            return LandedState.LANDING
        return LandedState.IN_AIR

    def offboard_setpoint_fresh(self, max_age_s: float) -> bool:
        """An offboard setpoint arrived within `max_age_s`."""
        return self.time_s - self._offboard_setpoint_s <= max_age_s

    def _say(self, severity: int, text: str) -> None:
        self.status_texts.append(StatusText(severity, text[:50]))

    # --- commands ---------------------------------------------------------------------------
    def arm(self, force: bool = False) -> CommandResult:
        """MAV_CMD_COMPONENT_ARM_DISARM(1): PX4's arming checks unless forced (21196)."""
        if self.armed:
            return CommandResult.ACCEPTED
        if not force:
            if not self.healthy:
                self._say(SEVERITY_CRITICAL, "Arming denied: Resolve system health failures first")
                return CommandResult.TEMPORARILY_REJECTED
            if self.time_s < self.params.arm_denied_after_boot_s:
                self._say(SEVERITY_CRITICAL, "Arming denied: system not ready")
                return CommandResult.TEMPORARILY_REJECTED
            if self.mode is FlightMode.RTL:
                self._say(SEVERITY_CRITICAL, "Arming denied: not in an armable mode")
                return CommandResult.TEMPORARILY_REJECTED
            if self.mode is FlightMode.OFFBOARD and not self.offboard_setpoint_fresh(
                self.params.offboard_entry_max_age_s
            ):
                self._say(SEVERITY_CRITICAL, "Arming denied: no offboard signal")
                return CommandResult.TEMPORARILY_REJECTED
        self.armed = True
        self._armed_at_s = self.time_s
        self._has_taken_off_since_arming = False
        self.body.motors_enabled = self.mode in (FlightMode.TAKEOFF, FlightMode.OFFBOARD)
        self._latch_hold()
        self._say(SEVERITY_INFO, "Armed by external command")
        return CommandResult.ACCEPTED

    def disarm(self, force: bool = False) -> CommandResult:
        """MAV_CMD_COMPONENT_ARM_DISARM(0): denied in the air unless forced (kill)."""
        if not self.armed:
            return CommandResult.ACCEPTED
        if not self._landed and not force:
            self._say(SEVERITY_CRITICAL, "Disarming denied: not landed")
            return CommandResult.DENIED
        self._disarm("Disarmed by external command")
        return CommandResult.ACCEPTED

    def _disarm(self, reason: str) -> None:
        self.armed = False
        self.body.motors_enabled = False
        self._say(SEVERITY_INFO, reason)
        if self.mode is not FlightMode.HOLD:
            self._set_mode(FlightMode.HOLD)

    def takeoff(self, altitude_amsl_m: float = math.nan) -> CommandResult:
        """MAV_CMD_NAV_TAKEOFF: climb to param7 (AMSL; NaN: MIS_TAKEOFF_ALT above home)."""
        if math.isfinite(altitude_amsl_m):
            height_m = altitude_amsl_m - self.params.home_alt_amsl_m
        else:
            height_m = self.params.takeoff_alt_m
        if height_m <= 0.0:
            return CommandResult.DENIED
        position = self.truth.position_ned_m
        self._takeoff_target_z_m = min(-height_m, float(position[2]))
        self._land_xy = position[:2].copy()
        self._set_mode(FlightMode.TAKEOFF)
        return CommandResult.ACCEPTED

    def land(self) -> CommandResult:
        """MAV_CMD_NAV_LAND: descend at MPC_LAND_SPEED where we are."""
        self._set_mode(FlightMode.LAND)
        return CommandResult.ACCEPTED

    def return_to_launch(self) -> CommandResult:
        """MAV_CMD_NAV_RETURN_TO_LAUNCH / Return mode."""
        if self._landed and not self.armed:
            return CommandResult.TEMPORARILY_REJECTED
        self._set_mode(FlightMode.RTL)
        return CommandResult.ACCEPTED

    def request_mode(self, mode: FlightMode) -> CommandResult:
        """A mode switch asked over MAVLink (DO_SET_MODE), with PX4's transition checks."""
        if mode is FlightMode.TAKEOFF:
            return self.takeoff()
        if mode is FlightMode.LAND:
            return self.land()
        if mode is FlightMode.RTL:
            return self.return_to_launch()
        if mode is FlightMode.OFFBOARD:
            return self._request_offboard()
        self._set_mode(mode)
        return CommandResult.ACCEPTED

    def _request_offboard(self) -> CommandResult:
        p = self.params
        if not self.offboard_setpoint_fresh(p.offboard_entry_max_age_s):
            self._say(SEVERITY_CRITICAL, "Switching to Offboard is currently not available")
            return CommandResult.TEMPORARILY_REJECTED
        if self.mode is FlightMode.OFFBOARD:
            return CommandResult.ACCEPTED
        if self._exposed_to_takeoff_hold_race() and (
            self._quirk_rng.random() < p.takeoff_hold_race_probability
        ):
            # commander accepts, the navigator's end-of-takeoff Hold lands a moment later
            self._race_hold_at_s = self.time_s + 0.1
        self._set_mode(FlightMode.OFFBOARD)
        return CommandResult.ACCEPTED

    def _exposed_to_takeoff_hold_race(self) -> bool:
        window = self.params.takeoff_hold_race_window_s
        if self.mode is FlightMode.TAKEOFF:
            remaining_m = abs(self.truth.position_ned_m[2] - self._takeoff_target_z_m)
            return remaining_m <= self.params.takeoff_speed_mps * window
        return self.time_s - self._takeoff_completed_s <= window

    def offboard_setpoint(self, setpoint: TrajectorySetpoint) -> None:
        """SET_POSITION_TARGET_LOCAL_NED arrived (any mode: it keeps the offboard signal alive)."""
        self._offboard_setpoint = setpoint
        self._offboard_setpoint_s = self.time_s
        if self.mode is FlightMode.OFFBOARD:
            self.body.set_setpoint(setpoint)

    def companion_heartbeat(self) -> None:
        """A HEARTBEAT from an onboard controller (companion computer) arrived."""
        if self._companion_seen_s is None:
            self._say(SEVERITY_INFO, "Onboard controller connected")
        self._companion_seen_s = self.time_s

    # --- mode machinery -------------------------------------------------------------------
    def _latch_hold(self) -> None:
        state = self.truth
        stop = np.zeros(3)
        speed_xy = float(np.hypot(*state.velocity_ned_mps[:2]))
        if speed_xy > 1e-3:
            stop[:2] = state.velocity_ned_mps[:2] * speed_xy / (2.0 * self.params.acc_hor_mps2)
        self._hold_position = state.position_ned_m + stop
        self._hold_position[2] = min(self._hold_position[2], 0.0)
        self._hold_yaw_rad = state.yaw_rad

    def _set_mode(self, mode: FlightMode) -> None:
        previous = self.mode
        self.mode = mode
        if mode is FlightMode.HOLD:
            self._latch_hold()
        elif mode is FlightMode.LAND:
            self._land_xy = self.truth.position_ned_m[:2].copy()
        elif mode is FlightMode.RTL:
            self._latch_hold()
            self._rtl_phase = RtlPhase.CLIMB
            self._rtl_wait_since_s = None
        elif mode is FlightMode.OFFBOARD and self._offboard_setpoint is not None:
            self.body.set_setpoint(self._offboard_setpoint)
        if mode is not FlightMode.OFFBOARD:
            self._race_hold_at_s = None
        if previous is not mode:
            self._say(SEVERITY_INFO, f"Mode: {mode.name}")

    def _failsafe(self, text: str) -> None:
        self._say(SEVERITY_WARNING, f"Failsafe: {text}, Hold")
        self._set_mode(FlightMode.HOLD)

    def _update_failsafes(self) -> None:
        p = self.params
        now = self.time_s
        if self.mode is not FlightMode.OFFBOARD or not self.armed:
            return
        if self._race_hold_at_s is not None and now >= self._race_hold_at_s:
            self._set_mode(FlightMode.HOLD)
            return
        if now - self._offboard_setpoint_s > p.offboard_loss_timeout_s:
            self._failsafe("offboard control lost")
        elif (
            self._companion_seen_s is not None
            and now - self._companion_seen_s > p.companion_loss_timeout_s
        ):
            self._failsafe("onboard controller lost")

    def _update_land_detector(self) -> None:
        p = self.params
        now = self.time_s
        on_ground = self.truth.on_ground
        if not on_ground:
            self._ground_since_s = None
            if self._landed and self.armed:
                self._landed = False
                self._has_taken_off_since_arming = True
            return
        if self._ground_since_s is None:
            self._ground_since_s = now
        if not self._landed and now - self._ground_since_s >= p.land_detect_time_s:
            self._landed = True
            self._say(SEVERITY_INFO, "Landing detected")
        if not self.armed or not self._landed:
            return
        landed_for_s = now - max(self._ground_since_s + p.land_detect_time_s, self._armed_at_s)
        if self._has_taken_off_since_arming:
            if 0.0 <= p.disarm_land_s <= landed_for_s:
                self._disarm("Disarmed by landing")
        elif (
            self.mode is not FlightMode.TAKEOFF
            and 0.0 <= p.disarm_preflight_s <= now - self._armed_at_s
        ):
            self._disarm("Disarmed by auto preflight disarming")

    def _mode_setpoint(self) -> TrajectorySetpoint | None:
        """The setpoint of the auto mode flying now; None in Offboard."""
        p = self.params
        state = self.truth
        if self.mode is FlightMode.HOLD:
            return TrajectorySetpoint(
                position_ned_m=self._hold_position.copy(),
                yaw_rad=self._hold_yaw_rad,
                speed_max_xy_mps=p.xy_cruise_mps,
            )
        if self.mode is FlightMode.TAKEOFF:
            if state.position_ned_m[2] - self._takeoff_target_z_m <= p.takeoff_acceptance_m:
                self._takeoff_completed_s = self.time_s
                self._say(SEVERITY_INFO, "Takeoff complete")
                self._set_mode(FlightMode.HOLD)
                self._hold_position = np.array([*self._land_xy, self._takeoff_target_z_m])
                return self._mode_setpoint()
            return TrajectorySetpoint(
                position_ned_m=np.array([*self._land_xy, self._takeoff_target_z_m]),
                yaw_rad=self._hold_yaw_rad,
                speed_max_up_mps=p.takeoff_speed_mps,
            )
        if self.mode is FlightMode.LAND:
            return self._descend_setpoint(self._land_xy)
        if self.mode is FlightMode.RTL:
            return self._rtl_setpoint(state)
        return None

    def _descend_setpoint(self, xy: np.ndarray) -> TrajectorySetpoint:
        p = self.params
        height_m = -self.truth.position_ned_m[2]
        speed = p.land_speed_mps if height_m < 3.0 else p.z_vel_max_dn_mps
        return TrajectorySetpoint(
            position_ned_m=np.array([xy[0], xy[1], np.nan]),
            velocity_ned_mps=np.array([np.nan, np.nan, speed]),
            yaw_rad=self._hold_yaw_rad,
        )

    def _rtl_setpoint(self, state: VehicleState) -> TrajectorySetpoint:
        p = self.params
        position = state.position_ned_m
        return_z = min(-p.rtl_return_alt_m, self._hold_position[2])
        if self._rtl_phase == RtlPhase.CLIMB:
            if position[2] <= return_z + p.takeoff_acceptance_m:
                self._rtl_phase = RtlPhase.RETURN
            return TrajectorySetpoint(
                position_ned_m=np.array([*self._hold_position[:2], return_z]),
                yaw_rad=self._hold_yaw_rad,
            )
        if self._rtl_phase == RtlPhase.RETURN:
            home_distance = float(np.hypot(*position[:2]))
            speed = float(np.hypot(*state.velocity_ned_mps[:2]))
            if home_distance < min(p.nav_acc_rad_m, 0.5) and speed < 0.3:
                if self._rtl_wait_since_s is None:
                    self._rtl_wait_since_s = self.time_s
                if self.time_s - self._rtl_wait_since_s >= max(p.rtl_land_delay_s, 0.0):
                    self._rtl_phase = RtlPhase.DESCEND
            return TrajectorySetpoint(
                position_ned_m=np.array([0.0, 0.0, return_z]),
                yaw_rad=self._hold_yaw_rad,
                speed_max_xy_mps=p.xy_cruise_mps,
            )
        return self._descend_setpoint(np.zeros(2))

    # --- simulation ---------------------------------------------------------------------------
    def step(self, dt_s: float) -> VehicleState:
        """Advance `dt_s` in physics steps, running commander and navigator at each step."""
        remaining = float(dt_s)
        h_nominal = 1.0 / self.params.physics_rate_hz
        while remaining > 1e-9:
            h = min(h_nominal, remaining)
            self._update_failsafes()
            self._update_land_detector()
            setpoint = self._mode_setpoint()
            if setpoint is not None:
                self.body.set_setpoint(setpoint)
            self.body.motors_enabled = self.armed and not (
                self._landed and self.mode in (FlightMode.HOLD, FlightMode.LAND)
            )
            self.body.step(h)
            remaining -= h
        return self.truth
