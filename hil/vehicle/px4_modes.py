"""PX4's commander and navigator in miniature: arming, flight modes, failsafes, takeoff and landing.

`Px4Vehicle` wraps a `Multirotor` and is pure and synchronous like it: every request takes the
simulated time implicitly from the vehicle clock, `step(dt_s)` advances both. The MAVLink
server (`hil.mavlink.server`) only translates messages to these calls, so every PX4 behaviour
here is testable in lockstep without sockets.

Behaviours reproduced (PX4-Autopilot main, March 2026):
- arming checks, "arming denied right after boot", auto-disarm after landing (COM_DISARM_LAND)
  and preflight (COM_DISARM_PRFLT);
- takeoff: spool-up (COM_SPOOLUP_TIME), the climb-speed ramp (MPC_TKO_RAMP_T, MPC_TKO_SPEED),
  the tilt limit MPC_TILTMAX_LND until flying, done within NAV_MC_ALT_RAD of the target, then
  the navigator's Hold at the takeoff point;
- Hold, RTL and Land fly PX4's jerk-limited auto trajectories (`px4_auto`); RTL climbs to
  RTL_RETURN_ALT (within RTL_MIN_DIST of home only to its RTL_CONE_ANG cone, and not at all next
  to home), returns at MPC_XY_CRUISE, descends to RTL_DESCEND_ALT and lands; Land descends at
  MPC_Z_V_AUTO_DN above MPC_LAND_ALT1, MPC_LAND_SPEED below MPC_LAND_ALT2, MPC_LAND_CRWL below
  MPC_LAND_ALT3, with PX4's land detector (`land_detector`) and idle thrust on ground contact;
- Offboard entry only with a setpoint younger than 0.5 s; offboard loss (COM_OF_LOSS_T) takes the
  action of COM_OBL_RC_ACT: without RC (never simulated) Position/Altitude/Stabilized fall back to
  Return, as PX4 does; losing the onboard computer's heartbeat (COM_OBC_LOSS_T) is only a warning
  on PX4 (the offboard loss that follows is what acts);
- after a disarm the mode is the last one the user chose that outlives a landing (Hold or
  Offboard): PX4 reports the mode it had before Land, not Land;
- PX4's events (`events`, names of PX4's event definitions) and STATUSTEXTs; the
  end-of-takeoff Hold race.
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from dataclasses import dataclass
from enum import Enum, IntEnum

import numpy as np

from hil.vehicle.land_detector import LandDetector, LandDetectorInput
from hil.vehicle.multirotor import Multirotor
from hil.vehicle.params import VehicleSimParams
from hil.vehicle.px4_auto import AutoTrajectory, max_speed_from_distance_mps
from hil.vehicle.px4_controller import TakeoffRamp, TakeoffState, TrajectorySetpoint
from hil.vehicle.state import RigidBodyState

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

_TILT_LIMIT_SLEW_RADPS = 0.2  # PX4 mc_pos_control: the tilt limit changes at most this fast
_TAKEOFF_WANTED_ABOVE_M = 0.2  # a setpoint this far above the vehicle asks for takeoff


class Px4Mode(Enum):
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
    def from_px4(cls, main_mode: int, sub_mode: int) -> Px4Mode | None:
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


class MavLandedState(IntEnum):
    """MAV_LANDED_STATE values."""

    UNDEFINED = 0
    ON_GROUND = 1
    IN_AIR = 2
    TAKEOFF = 3
    LANDING = 4


class FailsafeAction(IntEnum):
    """PX4's failsafe_action_t (the argument of its failsafe events)."""

    NONE = 0
    WARN = 1
    HOLD = 5
    RTL = 6
    LAND = 7
    DISARM = 9
    TERMINATE = 10


def offboard_loss_action(com_obl_rc_act: int, rc_available: bool = False) -> FailsafeAction:
    """PX4's action for COM_OBL_RC_ACT: 0 Position, 1 Altitude, 2 Manual (RC modes: Return
    without RC), 3 Return, 4 Land, 5 Hold, 6 Terminate, 7 Disarm."""
    if com_obl_rc_act in (0, 1, 2):
        return FailsafeAction.HOLD if rc_available else FailsafeAction.RTL
    return {
        3: FailsafeAction.RTL,
        4: FailsafeAction.LAND,
        5: FailsafeAction.HOLD,
        6: FailsafeAction.TERMINATE,
        7: FailsafeAction.DISARM,
    }.get(com_obl_rc_act, FailsafeAction.RTL)


@dataclass(frozen=True)
class StatusText:
    """A STATUSTEXT to publish: MAV_SEVERITY and text (<= 50 chars)."""

    severity: int
    text: str


@dataclass(frozen=True)
class Px4Event:
    """An event of PX4's events protocol: the name of its PX4 definition and its arguments."""

    name: str
    arguments: tuple[float | int, ...] = ()


SEVERITY_CRITICAL = 2
SEVERITY_WARNING = 4
SEVERITY_INFO = 6

# PX4 arm_disarm_reason_t
REASON_COMMAND_EXTERNAL = 4
REASON_LANDING = 6
REASON_PREFLIGHT_INACTION = 7
REASON_FAILSAFE = 14


class RtlPhase(Enum):
    """Phases of Return mode (RTL_TYPE 0)."""

    CLIMB = "climb"
    RETURN = "return"
    DESCEND = "descend"
    LOITER = "loiter"
    LAND = "land"


_MODES_OUTLIVING_LANDING = (Px4Mode.HOLD, Px4Mode.OFFBOARD)


class Px4Vehicle:
    """A PX4 autopilot around a `Multirotor`. Boots at time 0, disarmed, in Hold on the ground.

    Not thread-safe: the MAVLink server holds a lock around every call.
    """

    def __init__(self, params: VehicleSimParams, seed: int | None = None) -> None:
        self.params = params
        self.seed = params.seed if seed is None else seed
        self.body = Multirotor(params, seed=self.seed)
        self.body.motors_enabled = False
        self._quirk_rng = np.random.default_rng([self.seed, 0x7A6E])
        self._land_detector = LandDetector(params)
        self._takeoff_ramp = TakeoffRamp(params)
        self._auto = AutoTrajectory(params)
        self.armed = False
        self.mode = Px4Mode.HOLD
        self.status_texts: deque[StatusText] = deque(maxlen=64)
        self.events: deque[Px4Event] = deque(maxlen=64)
        self.failsafe_active = False
        self._mode_after_disarm = Px4Mode.HOLD
        self._intended_mode = Px4Mode.HOLD
        self._target_ned_m = np.zeros(3)
        self._hold_yaw_rad = 0.0
        self._takeoff_target_z_m = 0.0
        self._takeoff_completed_s = -math.inf
        self._has_taken_off_since_arming = False
        self._armed_at_s = -math.inf
        self._landed_at_s = 0.0
        self._land_xy = np.zeros(2)
        self._rtl_phase = RtlPhase.CLIMB
        self._rtl_return_z_m = 0.0
        self._rtl_loiter_since_s: float | None = None
        self._offboard_setpoint: TrajectorySetpoint | None = None
        self._offboard_setpoint_s = -math.inf
        self._companion_seen_s: float | None = None
        self._companion_lost = False
        self._race_hold_at_s: float | None = None
        self._tilt_limit_rad = math.radians(params.tilt_max_land_deg)
        self._enter_hold()

    # --- read-only status -------------------------------------------------------------------
    @property
    def time_s(self) -> float:
        """Simulated seconds since boot."""
        return self.body.time_s

    @property
    def truth(self) -> RigidBodyState:
        """Ground truth of the body."""
        return self.body.state

    @property
    def estimate(self) -> RigidBodyState:
        """The state as PX4's estimator reports it."""
        return self.body.estimate

    @property
    def intended_mode(self) -> Px4Mode:
        """The mode the user chose last (a failsafe changes `mode`, not this)."""
        return self._intended_mode

    @property
    def healthy(self) -> bool:
        """Sensors, estimator and pre-arm checks pass (simulated convergence after boot)."""
        return self.time_s >= self.params.health_ok_after_boot_s

    @property
    def landed(self) -> bool:
        """PX4's land detector: landed."""
        return self._land_detector.landed

    @property
    def landed_state(self) -> MavLandedState:
        """EXTENDED_SYS_STATE.landed_state."""
        if self.landed:
            return MavLandedState.ON_GROUND
        if self.mode is Px4Mode.TAKEOFF:
            return MavLandedState.TAKEOFF
        if self.mode is Px4Mode.LAND or (
            self.mode is Px4Mode.RTL and self._rtl_phase is RtlPhase.LAND
        ):
            return MavLandedState.LANDING
        return MavLandedState.IN_AIR

    @property
    def companion_lost(self) -> bool:
        """A companion's heartbeat was seen, then none for COM_OBC_LOSS_T (PX4 warns)."""
        return self._companion_lost

    def offboard_setpoint_fresh(self, max_age_s: float) -> bool:
        """An offboard setpoint arrived within `max_age_s`."""
        return self.time_s - self._offboard_setpoint_s <= max_age_s

    def _say(self, severity: int, text: str, event: Px4Event | None = None) -> None:
        self.status_texts.append(StatusText(severity, text[:50]))
        if event is not None:
            self.events.append(event)

    # --- commands ---------------------------------------------------------------------------
    def arm(self, force: bool = False) -> CommandResult:
        """MAV_CMD_COMPONENT_ARM_DISARM(1): PX4's arming checks unless forced (21196)."""
        if self.armed:
            return CommandResult.ACCEPTED
        if not force:
            if not self.healthy:
                self._say(
                    SEVERITY_CRITICAL,
                    "Arming denied: Resolve system health failures first",
                    Px4Event("commander_arm_denied_resolve_failures"),
                )
                return CommandResult.TEMPORARILY_REJECTED
            if self.time_s < self.params.arm_denied_after_boot_s:
                self._say(
                    SEVERITY_CRITICAL,
                    "Arming denied: system not ready",
                    Px4Event("commander_arm_denied_resolve_failures"),
                )
                return CommandResult.TEMPORARILY_REJECTED
            if self.mode is Px4Mode.RTL:
                self._say(
                    SEVERITY_CRITICAL,
                    "Arming denied: not in an armable mode",
                    Px4Event("commander_modeswitch_not_avail", (0, 0)),
                )
                return CommandResult.TEMPORARILY_REJECTED
            if self.mode is Px4Mode.OFFBOARD and not self.offboard_setpoint_fresh(
                self.params.offboard_entry_max_age_s
            ):
                self._say(
                    SEVERITY_CRITICAL,
                    "Arming denied: no offboard signal",
                    Px4Event("commander_arm_denied_resolve_failures"),
                )
                return CommandResult.TEMPORARILY_REJECTED
        self.armed = True
        self._armed_at_s = self.time_s
        self._has_taken_off_since_arming = False
        self.body.motors_enabled = True
        self._tilt_limit_rad = math.radians(self.params.tilt_max_land_deg)
        self._say(
            SEVERITY_INFO,
            "Armed by external command",
            Px4Event("commander_armed_by", (REASON_COMMAND_EXTERNAL,)),
        )
        return CommandResult.ACCEPTED

    def disarm(self, force: bool = False) -> CommandResult:
        """MAV_CMD_COMPONENT_ARM_DISARM(0): denied in the air unless forced (kill)."""
        if not self.armed:
            return CommandResult.ACCEPTED
        if not self.landed and not force:
            self._say(
                SEVERITY_CRITICAL,
                "Disarming denied: not landed",
                Px4Event("commander_disarm_denied_not_landed"),
            )
            return CommandResult.DENIED
        self._disarm("external command", REASON_COMMAND_EXTERNAL)
        return CommandResult.ACCEPTED

    def _disarm(self, reason: str, reason_code: int) -> None:
        self.armed = False
        self.body.motors_enabled = False
        self.failsafe_active = False
        self._say(
            SEVERITY_INFO,
            f"Disarmed by {reason}",
            Px4Event("commander_disarmed_by", (reason_code,)),
        )
        self._intended_mode = self._mode_after_disarm
        if self.mode is not self._mode_after_disarm:
            self._set_mode(self._mode_after_disarm)

    def takeoff(self, altitude_amsl_m: float = math.nan) -> CommandResult:
        """MAV_CMD_NAV_TAKEOFF: climb to param7 (AMSL; NaN: MIS_TAKEOFF_ALT above home)."""
        if math.isfinite(altitude_amsl_m):
            height_m = altitude_amsl_m - self.params.home_alt_amsl_m
        else:
            height_m = self.params.takeoff_alt_m
            self.events.append(Px4Event("navigator_takeoff_default_alt", (height_m,)))
        if height_m <= 0.0:
            return CommandResult.DENIED
        position = self.estimate.position_ned_m
        self._takeoff_target_z_m = min(-height_m, float(position[2]))
        self._land_xy = position[:2].copy()
        self._user_mode(Px4Mode.TAKEOFF)
        return CommandResult.ACCEPTED

    def land(self) -> CommandResult:
        """MAV_CMD_NAV_LAND: descend where it is (after braking)."""
        self._say(
            SEVERITY_INFO, "Landing at current position", Px4Event("commander_landing_current_pos")
        )
        self._user_mode(Px4Mode.LAND)
        return CommandResult.ACCEPTED

    def return_to_launch(self) -> CommandResult:
        """MAV_CMD_NAV_RETURN_TO_LAUNCH / Return mode."""
        if self.landed and not self.armed:
            return CommandResult.TEMPORARILY_REJECTED
        self._user_mode(Px4Mode.RTL)
        return CommandResult.ACCEPTED

    def request_mode(self, mode: Px4Mode) -> CommandResult:
        """A mode switch asked over MAVLink (DO_SET_MODE), with PX4's transition checks."""
        if mode is Px4Mode.TAKEOFF:
            return self.takeoff()
        if mode is Px4Mode.LAND:
            return self.land()
        if mode is Px4Mode.RTL:
            return self.return_to_launch()
        if mode is Px4Mode.OFFBOARD:
            return self._request_offboard()
        self._user_mode(mode)
        return CommandResult.ACCEPTED

    def _request_offboard(self) -> CommandResult:
        p = self.params
        if not self.offboard_setpoint_fresh(p.offboard_entry_max_age_s):
            self._say(
                SEVERITY_CRITICAL,
                "Switching to Offboard is currently not available",
                Px4Event("commander_modeswitch_not_avail", (0, 14)),
            )
            return CommandResult.TEMPORARILY_REJECTED
        if self.mode is Px4Mode.OFFBOARD:
            self._user_mode(Px4Mode.OFFBOARD)
            return CommandResult.ACCEPTED
        if self._exposed_to_takeoff_hold_race() and (
            self._quirk_rng.random() < p.takeoff_hold_race_probability
        ):
            # commander accepts, the navigator's end-of-takeoff Hold lands a moment later
            self._race_hold_at_s = self.time_s + 0.1
        self._user_mode(Px4Mode.OFFBOARD)
        return CommandResult.ACCEPTED

    def _exposed_to_takeoff_hold_race(self) -> bool:
        window = self.params.takeoff_hold_race_window_s
        if self.mode is Px4Mode.TAKEOFF:
            remaining_m = abs(self.estimate.position_ned_m[2] - self._takeoff_target_z_m)
            return (
                remaining_m <= self.params.takeoff_speed_mps * window + self.params.nav_mc_alt_rad_m
            )
        return self.time_s - self._takeoff_completed_s <= window

    def offboard_setpoint(self, setpoint: TrajectorySetpoint) -> None:
        """SET_POSITION_TARGET_LOCAL_NED arrived (any mode: it keeps the offboard signal alive)."""
        self._offboard_setpoint = setpoint
        self._offboard_setpoint_s = self.time_s

    def companion_heartbeat(self) -> None:
        """A HEARTBEAT from an onboard controller (companion computer) arrived."""
        if self._companion_seen_s is None or self._companion_lost:
            self._companion_lost = False
            self._say(SEVERITY_INFO, "Onboard controller connected")
        self._companion_seen_s = self.time_s

    # --- mode machinery -------------------------------------------------------------------
    def _user_mode(self, mode: Px4Mode) -> None:
        """A mode the user chose: it ends a failsafe (user takeover) and may outlive landing."""
        self.failsafe_active = False
        self._intended_mode = mode
        if mode in _MODES_OUTLIVING_LANDING:
            self._mode_after_disarm = mode
        self._set_mode(mode)

    def _enter_hold(self) -> None:
        est = self.estimate
        self._auto.reset(est.position_ned_m, est.velocity_ned_mps)
        self._target_ned_m = (
            self._auto.stopping_point() if not self.landed else est.position_ned_m.copy()
        )
        self._target_ned_m[2] = min(self._target_ned_m[2], 0.0)
        self._hold_yaw_rad = est.yaw_rad

    def _set_mode(self, mode: Px4Mode) -> None:
        previous = self.mode
        self.mode = mode
        est = self.estimate
        if mode is Px4Mode.HOLD:
            self._enter_hold()
        elif mode is Px4Mode.TAKEOFF:
            self._auto.reset(est.position_ned_m, est.velocity_ned_mps)
            self._hold_yaw_rad = est.yaw_rad
        elif mode is Px4Mode.LAND:
            self._enter_hold()
            self._land_xy = self._target_ned_m[:2].copy()
        elif mode is Px4Mode.RTL:
            self._enter_rtl()
        if mode is not Px4Mode.OFFBOARD:
            self._race_hold_at_s = None
        if previous is not mode:
            self._say(SEVERITY_INFO, f"Mode: {mode.name}")

    def _enter_rtl(self) -> None:
        """PX4 RTL (RTL_TYPE 0): the return altitude from RTL_RETURN_ALT and the cone."""
        p = self.params
        self._enter_hold()
        est = self.estimate
        home_distance = float(np.hypot(*est.position_ned_m[:2]))
        return_alt = p.rtl_return_alt_m
        if home_distance <= p.nav_acc_rad_m:
            return_alt = 2.0 * home_distance
        else:
            if home_distance <= p.rtl_min_dist_m and p.rtl_cone_ang_deg > 0:
                cone = math.radians(min(max(p.rtl_cone_ang_deg, 1.0), 89.0))
                return_alt = min(return_alt, home_distance / math.tan(cone))
            return_alt = max(return_alt, 2.0 * p.nav_acc_rad_m)
        current_alt = -float(est.position_ned_m[2])
        return_alt = max(return_alt, current_alt)
        self._rtl_return_z_m = -return_alt
        self._rtl_phase = RtlPhase.CLIMB
        self._rtl_loiter_since_s = None
        self.events.append(
            Px4Event("vrtl_return_at", (round(p.home_alt_amsl_m + return_alt), round(return_alt)))
        )

    def _failsafe(self, cause: str) -> None:
        action = offboard_loss_action(self.params.offboard_loss_action)
        self._say(
            SEVERITY_WARNING,
            f"Failsafe activated: {cause}, {action.name}",
            Px4Event("commander_failsafe_enter_generic", (0, int(action))),
        )
        self.failsafe_active = True
        if action is FailsafeAction.RTL:
            self._set_mode(Px4Mode.RTL)
        elif action is FailsafeAction.LAND:
            self._set_mode(Px4Mode.LAND)
        elif action is FailsafeAction.HOLD:
            self._set_mode(Px4Mode.HOLD)
        else:  # disarm, terminate: the motors stop wherever the vehicle is
            self._disarm("failsafe", REASON_FAILSAFE)

    def _update_failsafes(self) -> None:
        p = self.params
        now = self.time_s
        if self.mode is not Px4Mode.OFFBOARD or not self.armed:
            return
        if self._race_hold_at_s is not None and now >= self._race_hold_at_s:
            self._set_mode(Px4Mode.HOLD)
            return
        if now - self._offboard_setpoint_s > p.offboard_loss_timeout_s:
            self._failsafe("no offboard signal")
        if (
            self._companion_seen_s is not None
            and now - self._companion_seen_s > p.companion_loss_timeout_s
            and not self._companion_lost
        ):
            self._companion_lost = True
            self._say(SEVERITY_WARNING, "Connection to onboard computer lost")

    def _update_land_detector(self) -> None:
        p = self.params
        now = self.time_s
        was_landed = self.landed
        control = self.body.last_control
        collective = 0.0 if control is None else float(np.linalg.norm(control.thrust_ned))
        vel_sp_z = math.nan if control is None else float(control.velocity_setpoint_ned_mps[2])
        est = self.estimate
        landed = self._land_detector.update(
            LandDetectorInput(
                now_s=now,
                velocity_ned_mps=est.velocity_ned_mps,
                angular_velocity_frd_radps=est.angular_velocity_frd_radps,
                collective_thrust=collective,
                velocity_setpoint_z_mps=vel_sp_z,
                armed=self.armed,
            )
        )
        if was_landed and not landed and self.armed:
            self._has_taken_off_since_arming = True
            self.events.append(Px4Event("commander_takeoff_detected"))
        if landed and not was_landed:
            self._landed_at_s = now
            if self.armed:
                self._say(SEVERITY_INFO, "Landing detected", Px4Event("commander_landing_detected"))
        if not self.armed or not landed:
            return
        if self._has_taken_off_since_arming:
            if 0.0 <= p.disarm_land_s <= now - self._landed_at_s:
                self._disarm("landing", REASON_LANDING)
        elif (
            self.mode is not Px4Mode.TAKEOFF
            and 0.0 <= p.disarm_preflight_s <= now - self._armed_at_s
        ):
            self._disarm("auto preflight disarming", REASON_PREFLIGHT_INACTION)

    def _mode_setpoint(self, h: float) -> TrajectorySetpoint:
        """The setpoint of the mode flying now."""
        p = self.params
        if self.mode is Px4Mode.OFFBOARD and self._offboard_setpoint is not None:
            return self._offboard_setpoint
        if self.mode is Px4Mode.TAKEOFF:
            est_z = float(self.estimate.position_ned_m[2])
            if abs(est_z - self._takeoff_target_z_m) < p.nav_mc_alt_rad_m:
                self._takeoff_completed_s = self.time_s
                self._say(SEVERITY_INFO, "Takeoff complete")
                self._set_mode(Px4Mode.HOLD)
                self._target_ned_m = np.array([*self._land_xy, self._takeoff_target_z_m])
            else:
                return self._takeoff_setpoint(h, est_z)
        if self.mode is Px4Mode.LAND:
            return self._land_setpoint(h, self._land_xy)
        if self.mode is Px4Mode.RTL:
            return self._rtl_setpoint(h)
        # Hold, and Offboard before any setpoint
        return self._auto.update(h, self._target_ned_m, self._hold_yaw_rad)

    def _takeoff_setpoint(self, h: float, est_z_m: float) -> TrajectorySetpoint:
        """PX4's takeoff: a climb rate reaching MPC_TKO_SPEED over MPC_TKO_RAMP_T, slowing to
        stop at the target altitude; the altitude is not a position setpoint (it follows the
        vehicle)."""
        p = self.params
        accel = p.takeoff_speed_mps / max(p.takeoff_ramp_s, 0.1)
        distance = est_z_m - self._takeoff_target_z_m
        speed = min(
            p.takeoff_speed_mps, max_speed_from_distance_mps(p.jerk_auto_mps3, accel, distance)
        )
        target = np.array([*self._land_xy, math.nan])
        return self._auto.update(
            h,
            target,
            self._hold_yaw_rad,
            speed_up_mps=p.takeoff_speed_mps,
            climb_rate_mps=-speed,
            accel_z_mps2=accel,
        )

    def _land_setpoint(self, h: float, xy: np.ndarray) -> TrajectorySetpoint:
        """PX4 FlightTaskAuto land: descend at the speed of the height above ground."""
        p = self.params
        height_m = -float(self.truth.position_ned_m[2])  # SIH's distance sensor
        speed = float(
            np.interp(
                height_m,
                [p.land_alt2_m, max(p.land_alt1_m, p.land_alt2_m + 1e-3)],
                [p.land_speed_mps, p.z_vel_auto_dn_mps],
            )
        )
        if height_m <= p.land_alt3_m:
            speed = p.land_crawl_mps
        target = np.array([xy[0], xy[1], math.nan])
        return self._auto.update(h, target, self._hold_yaw_rad, climb_rate_mps=speed)

    def _rtl_setpoint(self, h: float) -> TrajectorySetpoint:
        p = self.params
        est = self.estimate
        position = est.position_ned_m
        if self._rtl_phase is RtlPhase.CLIMB:
            if position[2] <= self._rtl_return_z_m + p.nav_mc_alt_rad_m:
                self._rtl_phase = RtlPhase.RETURN
            target = np.array([*self._target_ned_m[:2], self._rtl_return_z_m])
            return self._auto.update(h, target, self._hold_yaw_rad)
        if self._rtl_phase is RtlPhase.RETURN:
            target = np.array([0.0, 0.0, self._rtl_return_z_m])
            if (
                float(np.hypot(*position[:2])) < p.nav_acc_rad_m
                and float(np.linalg.norm(est.velocity_ned_mps)) < 0.5
            ):
                self._rtl_phase = RtlPhase.DESCEND
            return self._auto.update(h, target, self._hold_yaw_rad)
        if self._rtl_phase is RtlPhase.DESCEND:
            descend_z = max(-p.rtl_descend_alt_m, self._rtl_return_z_m)
            if position[2] >= descend_z - p.nav_mc_alt_rad_m:
                self._rtl_phase = RtlPhase.LOITER
                self._rtl_loiter_since_s = self.time_s
            return self._auto.update(h, np.array([0.0, 0.0, descend_z]), self._hold_yaw_rad)
        if self._rtl_phase is RtlPhase.LOITER:
            assert self._rtl_loiter_since_s is not None
            delay = p.rtl_land_delay_s
            if delay >= 0.0 and self.time_s - self._rtl_loiter_since_s >= delay:
                self._rtl_phase = RtlPhase.LAND
                self.events.append(Px4Event("rtl_land_at_destination"))
            descend_z = max(-p.rtl_descend_alt_m, self._rtl_return_z_m)
            return self._auto.update(h, np.array([0.0, 0.0, descend_z]), self._hold_yaw_rad)
        return self._land_setpoint(h, np.zeros(2))

    def _want_takeoff(self, setpoint: TrajectorySetpoint) -> bool:
        """PX4: a takeoff is wanted when the setpoint climbs away from the vehicle."""
        if self.mode is Px4Mode.TAKEOFF:
            return True
        z = float(self.estimate.position_ned_m[2])
        return bool(
            (
                math.isfinite(setpoint.position_ned_m[2])
                and setpoint.position_ned_m[2] < z - _TAKEOFF_WANTED_ABOVE_M
            )
            or (math.isfinite(setpoint.velocity_ned_mps[2]) and setpoint.velocity_ned_mps[2] < 0.0)
        )

    def _controlled_setpoint(self, h: float, setpoint: TrajectorySetpoint) -> TrajectorySetpoint:
        """MulticopterPositionControl's takeoff handling around the mode's setpoint."""
        p = self.params
        state = self._takeoff_ramp.update(
            self.time_s, self.armed, self.landed, self._want_takeoff(setpoint)
        )
        speed_up = self._takeoff_ramp.upward_speed_limit(h, p.z_vel_max_up_mps)
        tilt_target = math.radians(
            p.tilt_max_land_deg if state < TakeoffState.FLIGHT else p.tilt_max_air_deg
        )
        step = _TILT_LIMIT_SLEW_RADPS * h
        self._tilt_limit_rad += min(max(tilt_target - self._tilt_limit_rad, -step), step)
        self.body.set_tilt_limit_deg(math.degrees(self._tilt_limit_rad))
        self.body.set_thrust_min(None if state is TakeoffState.FLIGHT else 0.0)
        ground_contact = self._land_detector.ground_contact
        if state < TakeoffState.RAMPUP or (state is TakeoffState.FLIGHT and ground_contact):
            # not flying, or flying but touching the ground: idle thrust, no integrator windup
            self.body.reset_velocity_integral()
            if state < TakeoffState.RAMPUP:
                self._auto.reset(self.estimate.position_ned_m, np.zeros(3))
            return TrajectorySetpoint(
                acceleration_ned_mps2=np.array([0.0, 0.0, 100.0]), yaw_rad=self._hold_yaw_rad
            )
        if state is TakeoffState.RAMPUP:
            if speed_up <= 0.0:
                # the trajectory starts once the ramp allows a climb (thrust near hover)
                self._auto.reset(self.estimate.position_ned_m, np.zeros(3))
            limit = (
                speed_up
                if not math.isfinite(setpoint.speed_max_up_mps)
                else min(speed_up, setpoint.speed_max_up_mps)
            )
            return dataclasses.replace(setpoint, speed_max_up_mps=limit)
        return setpoint

    # --- simulation ---------------------------------------------------------------------------
    def step(self, dt_s: float) -> RigidBodyState:
        """Advance `dt_s` in physics steps, running commander, navigator and controllers."""
        remaining = float(dt_s)
        h_nominal = 1.0 / self.params.physics_rate_hz
        while remaining > 1e-9:
            h = min(h_nominal, remaining)
            self._update_failsafes()
            setpoint = self._controlled_setpoint(h, self._mode_setpoint(h))
            self.body.set_setpoint(setpoint)
            self.body.motors_enabled = self.armed
            self.body.landed = self.landed
            self.body.step(h)
            self._update_land_detector()
            remaining -= h
        return self.truth
