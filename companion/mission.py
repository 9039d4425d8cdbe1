"""The mission manager: a pure state machine that decides what the vehicle does next.

No I/O and no clock inside: each `step` gets the time, what the vehicle reports, the health of
the stages, the planner's state and the outcome of the last vehicle operation, and returns a
`Decision`: the state, at most one vehicle operation to start (arm, take off, enter offboard,
land, return, hold), the goal the planner flies to, whether the planner must brake and hold,
and the events of the transitions. The flight process (`companion.flight.process`) carries the
operations out on the link and feeds their outcome back.

States: IDLE -> ARMING -> TAKEOFF -> NAVIGATE (the goal queue; AVOID and RECOVERY while the
planner avoids or recovers, thesis 4.5) -> HOLD or LANDING at the end -> LANDED. FAILSAFE:
stale perception or map (brake and hold in offboard, thesis 4.4 needs fresh frames), a stalled
planner (the link's watchdog brakes and holds), a lost vehicle link, a lost ground link, low
battery or a geofence breach; it resumes, holds, lands or returns as configured.

Operator commands (`takeoff`, `goto`, `hold`, `resume`, `land`, `rtl`, `abort`, `set_speed`)
return a `Verdict` that says why a command is refused; a refused command changes nothing.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from planning.types import PlannerState


class MissionParams(BaseModel):
    """The mission manager (`companion.mission`): goals, end of mission, failsafe actions."""

    model_config = ConfigDict(extra="forbid")

    auto_start: bool = Field(
        False,
        description="arm, take off and fly the configured goals as soon as the vehicle is ready "
        "(the simulator and scripted flights); False waits for an operator's command",
    )
    takeoff_altitude_m: float = Field(
        3.0, ge=1.0, le=100.0, description="takeoff altitude above home, m"
    )
    goals_ned_m: list[tuple[float, float, float]] = Field(
        default_factory=list,
        description="goals flown in order after takeoff, local NED from home, m "
        "(the ground station may replace them)",
    )
    end_action: Literal["hold", "land"] = Field(
        "land", description="what the vehicle does after the last goal: hold there, or land"
    )
    offboard_attempts: int = Field(
        3, ge=1, le=10, description="offboard entries tried before holding in PX4's Hold"
    )
    stale_resume_s: float = Field(
        1.0,
        ge=0.0,
        le=60.0,
        description="perception and map must be fresh this long again before a failsafe "
        "hold resumes the goal, s",
    )
    stale_land_s: float = Field(
        30.0,
        gt=0.0,
        le=3600.0,
        description="a failsafe hold for stale perception that lasts this long ends in a "
        "landing, s",
    )
    battery_low_frac: float = Field(
        0.2, ge=0.0, le=1.0, description="remaining charge that ends the mission, 0..1"
    )
    battery_action: Literal["land", "rtl"] = Field(
        "land", description="what low battery does: land where it is, or return to launch"
    )
    ground_lost_s: float = Field(
        10.0, gt=0.0, le=3600.0, description="ground link silent this long is a failsafe, s"
    )
    ground_lost_action: Literal["continue", "hold", "land", "rtl"] = Field(
        "continue",
        description="what a lost ground link does: continue the mission, hold, land, or return",
    )
    vehicle_link_back_action: Literal["hold", "resume", "land"] = Field(
        "hold",
        description="once a lost vehicle link is back (the autopilot's own failsafe flew "
        "meanwhile): hold for the operator, resume the active goal, or land",
    )


class MissionState(StrEnum):
    """Where the mission stands."""

    IDLE = "idle"  # on the ground, no mission running
    ARMING = "arming"
    TAKEOFF = "takeoff"
    NAVIGATE = "navigate"  # flying the goal queue on a free library trajectory
    AVOID = "avoid"  # the planner brakes, or holds short of a goal seen blocked
    RECOVERY = "recovery"  # the planner rotates in place or rewinds (4.5)
    HOLD = "hold"  # holding position: end of mission, operator hold, unreachable goal
    FAILSAFE = "failsafe"  # a fault stopped the mission (see `Decision.cause`)
    LANDING = "landing"
    LANDED = "landed"  # on the ground after a flight


AIRBORNE = frozenset(
    {
        MissionState.NAVIGATE,
        MissionState.AVOID,
        MissionState.RECOVERY,
        MissionState.HOLD,
        MissionState.FAILSAFE,
    }
)  # the states the mission flies in (in the air, offboard or PX4's Hold)


class Operation(StrEnum):
    """A vehicle operation the flight process carries out on the link."""

    ARM = "arm"
    TAKEOFF = "takeoff"
    OFFBOARD = "offboard"  # enter offboard (the tracker streams the planner's setpoints)
    HOLD = "hold"  # leave offboard for PX4's Hold
    LAND = "land"
    RTL = "rtl"


class FailsafeCause(StrEnum):
    """Why the mission is in FAILSAFE."""

    PERCEPTION_STALE = "perception_stale"
    PLANNER_STALE = "planner_stale"
    VEHICLE_LINK_LOST = "vehicle_link_lost"
    GROUND_LINK_LOST = "ground_link_lost"
    BATTERY_LOW = "battery_low"
    GEOFENCE = "geofence"


@dataclass(frozen=True, slots=True)
class VehicleStatus:
    """What the mission reads of the vehicle; None where the link never reported it."""

    link_ok: bool
    armed: bool | None
    in_air: bool | None
    offboard: bool  # our streamer is in control and the vehicle reports OFFBOARD
    position_ned_m: np.ndarray | None  # (3,) local NED, m
    battery_frac: float | None = None


@dataclass(frozen=True, slots=True)
class StageHealth:
    """Freshness of the stages the mission depends on (max ages of `companion.topics`)."""

    perception_fresh: bool  # frames are arriving and being fused into the map
    planner_fresh: bool  # the planner produced an output recently
    ground_link_ok: bool | None = None  # None: no ground link configured
    inside_geofence: bool = True


@dataclass(frozen=True, slots=True)
class OperationResult:
    """The outcome of the last vehicle operation the mission started."""

    operation: Operation
    ok: bool
    detail: str = ""


@dataclass(frozen=True, slots=True)
class MissionEvent:
    """A transition or a warning, at `stamp_s`."""

    stamp_s: float
    state: MissionState
    text: str
    warning: bool = False


@dataclass(frozen=True, slots=True)
class Verdict:
    """An operator command's answer: accepted, or refused with a reason a person can act on."""

    accepted: bool
    reason: str = ""


@dataclass(frozen=True, slots=True)
class Decision:
    """What the mission wants now."""

    state: MissionState
    operation: Operation | None  # an operation to start now (the previous one has finished)
    goal_ned_m: np.ndarray | None  # the planner's goal, local NED, m (None: no goal)
    hold: bool  # the planner must brake and hold position (offboard keeps streaming)
    speed_mps: float | None  # the operator's cruise speed; None: planning.max_speed_mps
    cause: FailsafeCause | None
    goal_index: int  # index of the active goal in the queue (== len when done)
    events: tuple[MissionEvent, ...]


_FLYING = frozenset(
    {MissionState.NAVIGATE, MissionState.AVOID, MissionState.RECOVERY, MissionState.HOLD}
)
_BLIND = frozenset({FailsafeCause.PERCEPTION_STALE, FailsafeCause.PLANNER_STALE})
_PLANNER_TO_STATE = {
    PlannerState.TRACKING: MissionState.NAVIGATE,
    PlannerState.IDLE: MissionState.NAVIGATE,
    PlannerState.ALIGNING: MissionState.NAVIGATE,
    PlannerState.BRAKING: MissionState.AVOID,
    PlannerState.GOAL_BLOCKED: MissionState.AVOID,
    PlannerState.RECOVERING: MissionState.RECOVERY,
    PlannerState.REWINDING: MissionState.RECOVERY,
}


@dataclass
class _Memory:
    """The mission's mutable state between steps."""

    state: MissionState = MissionState.IDLE
    goals: list[np.ndarray] = field(default_factory=list)
    index: int = 0
    speed_mps: float | None = None  # None: planning.max_speed_mps
    pending: Operation | None = None  # an operation in flight
    want: Operation | None = None  # an operation to start at the next step
    offboard_tries: int = 0
    hold: bool = False  # planner hold requested (operator hold, abort, stale inputs)
    cause: FailsafeCause | None = None
    resume_state: MissionState | None = None
    stale_since_s: float = math.nan
    fresh_since_s: float = math.nan
    takeoff_altitude_m: float = 3.0
    started: bool = False


class Mission:
    """The mission state machine; see the module docstring."""

    def __init__(self, params: MissionParams) -> None:
        self.params = params
        self._m = _Memory(takeoff_altitude_m=params.takeoff_altitude_m)
        self._m.goals = [np.asarray(g, dtype=np.float64) for g in params.goals_ned_m]
        self._m.started = params.auto_start and bool(self._m.goals)
        self._events: deque[MissionEvent] = deque()
        self._now_s = 0.0

    # ------------------------------------------------------------------ reading

    @property
    def state(self) -> MissionState:
        """The current state."""
        return self._m.state

    @property
    def goals_ned_m(self) -> list[np.ndarray]:
        """The goal queue, local NED, m (the active one is `goal_index`)."""
        return list(self._m.goals)

    @property
    def takeoff_altitude_m(self) -> float:
        """The altitude the next takeoff climbs to, m above home."""
        return self._m.takeoff_altitude_m

    @property
    def goal_index(self) -> int:
        """Index of the active goal (== number of goals once all are reached)."""
        return self._m.index

    # ------------------------------------------------------------------ operator commands

    def takeoff(self, altitude_m: float | None = None) -> Verdict:
        """Arm and take off to `altitude_m` (default `takeoff_altitude_m`), then hold."""
        if self._m.state not in (MissionState.IDLE, MissionState.LANDED):
            return Verdict(False, f"cannot take off while {self._m.state.value}")
        if altitude_m is not None:
            self._m.takeoff_altitude_m = float(altitude_m)
        self._m.goals, self._m.index, self._m.started = [], 0, True
        self._event("takeoff requested")
        return Verdict(True)

    def goto(self, goals_ned_m: list[np.ndarray], speed_mps: float | None = None) -> Verdict:
        """Fly to these goals in order (replacing the queue); from the ground, take off first."""
        if not goals_ned_m:
            return Verdict(False, "no goal given")
        if speed_mps is not None and not _valid_speed(speed_mps):
            return Verdict(False, f"speed {speed_mps} m/s outside (0, 15]")
        if self._m.state in (MissionState.LANDING, MissionState.ARMING, MissionState.TAKEOFF):
            return Verdict(False, f"cannot accept goals while {self._m.state.value}; retry after")
        if self._m.state is MissionState.FAILSAFE and self._m.cause in _BLIND:
            return Verdict(False, f"in failsafe ({self._m.cause}): cannot fly blind; land or wait")
        if self._m.state is MissionState.FAILSAFE:
            self._m.cause = self._m.resume_state = None
        self._m.goals = [np.asarray(g, dtype=np.float64).reshape(3) for g in goals_ned_m]
        self._m.index = 0
        if speed_mps is not None:
            self._m.speed_mps = float(speed_mps)
        if self._m.state in (MissionState.IDLE, MissionState.LANDED):
            self._m.started = True
        elif self._m.state in (*_FLYING, MissionState.FAILSAFE):
            self._m.hold = False
            self._transition(MissionState.NAVIGATE, f"new goals: {len(goals_ned_m)}")
        return Verdict(True)

    def hold(self) -> Verdict:
        """Brake and hold where the vehicle is (offboard keeps it there)."""
        if self._m.state not in _FLYING:
            return Verdict(False, f"cannot hold while {self._m.state.value}")
        self._m.hold = True
        self._transition(MissionState.HOLD, "operator hold")
        return Verdict(True)

    def abort(self) -> Verdict:
        """Brake and hold at once, whatever the vehicle is doing in the air."""
        if self._m.state not in (*_FLYING, MissionState.FAILSAFE, MissionState.TAKEOFF):
            return Verdict(False, f"nothing to abort while {self._m.state.value}")
        self._m.hold = True
        self._m.goals, self._m.index = self._m.goals[: self._m.index], self._m.index
        self._transition(MissionState.HOLD, "abort: brake and hold")
        return Verdict(True)

    def resume(self) -> Verdict:
        """Continue to the active goal after a hold."""
        if self._m.state is not MissionState.HOLD:
            return Verdict(False, f"nothing to resume while {self._m.state.value}")
        if self._m.index >= len(self._m.goals):
            return Verdict(False, "no goal left to resume; send goals first")
        self._m.hold = False
        self._transition(MissionState.NAVIGATE, f"resume to goal {self._m.index}")
        return Verdict(True)

    def land(self) -> Verdict:
        """Land where the vehicle is."""
        if self._m.state in (MissionState.IDLE, MissionState.LANDED, MissionState.LANDING):
            return Verdict(False, f"cannot land while {self._m.state.value}")
        self._start_landing("operator land")
        return Verdict(True)

    def rtl(self) -> Verdict:
        """Return to launch (PX4's RTL: it climbs to RTL_RETURN_ALT first)."""
        if self._m.state in (MissionState.IDLE, MissionState.LANDED, MissionState.LANDING):
            return Verdict(False, f"cannot return while {self._m.state.value}")
        self._m.want = Operation.RTL
        self._transition(MissionState.LANDING, "operator return to launch")
        return Verdict(True)

    def set_speed(self, speed_mps: float) -> Verdict:
        """Change the cruise speed."""
        if not _valid_speed(speed_mps):
            return Verdict(False, f"speed {speed_mps} m/s outside (0, 15]")
        self._m.speed_mps = float(speed_mps)
        self._event(f"speed {speed_mps:.1f} m/s")
        return Verdict(True)

    # ------------------------------------------------------------------ the step

    def step(
        self,
        now_s: float,
        vehicle: VehicleStatus,
        health: StageHealth,
        planner: PlannerState | None,
        result: OperationResult | None = None,
    ) -> Decision:
        """Advance the state machine at `now_s` and say what to do."""
        self._now_s = now_s
        m = self._m
        if result is not None and result.operation is m.pending:
            m.pending = None
            self._on_result(result, vehicle)
        self._check_failsafes(now_s, vehicle, health)
        if m.state is MissionState.IDLE or m.state is MissionState.LANDED:
            if m.started and vehicle.link_ok:
                m.started = False
                self._transition(MissionState.ARMING, "arming")
                m.want = Operation.ARM
        elif m.state in (MissionState.NAVIGATE, MissionState.AVOID, MissionState.RECOVERY):
            self._navigate(vehicle, planner)
        elif (
            m.state is MissionState.LANDING and vehicle.armed is False and not (m.pending or m.want)
        ):
            self._transition(MissionState.LANDED, "landed and disarmed")
        operation = None
        if m.want is not None and m.pending is None:
            operation, m.pending, m.want = m.want, m.want, None
        goal = m.goals[m.index] if m.index < len(m.goals) and m.state in _FLYING else None
        return Decision(
            state=m.state,
            operation=operation,
            goal_ned_m=None if goal is None else goal.copy(),
            hold=m.hold or m.state in (MissionState.HOLD, MissionState.FAILSAFE),
            speed_mps=m.speed_mps,
            cause=m.cause,
            goal_index=m.index,
            events=self._drain(),
        )

    def _on_result(self, result: OperationResult, vehicle: VehicleStatus) -> None:
        m = self._m
        op, ok = result.operation, result.ok
        if op is Operation.ARM:
            if ok:
                self._transition(MissionState.TAKEOFF, f"taking off to {m.takeoff_altitude_m} m")
                m.want = Operation.TAKEOFF
            else:
                self._transition(MissionState.IDLE, f"arming failed: {result.detail}", True)
        elif op is Operation.TAKEOFF:
            if ok:
                m.offboard_tries = 0
                if m.index < len(m.goals):
                    self._transition(MissionState.NAVIGATE, f"to goal {m.index}")
                    m.want = Operation.OFFBOARD
                else:
                    self._transition(MissionState.HOLD, "airborne; waiting for goals")
            else:
                self._start_landing(f"takeoff failed: {result.detail}")
        elif op is Operation.OFFBOARD:
            m.offboard_tries = 0 if ok else m.offboard_tries + 1
            if ok:
                self._event("offboard engaged")
            elif m.offboard_tries < self.params.offboard_attempts:
                m.want = Operation.OFFBOARD
                self._event(f"offboard refused: {result.detail}; retrying", True)
            else:
                m.want = Operation.HOLD
                self._transition(MissionState.HOLD, f"offboard failed: {result.detail}", True)
        elif op in (Operation.LAND, Operation.RTL) and not ok:
            m.want = op
            self._event(f"{op.value} failed: {result.detail}; retrying", True)

    def _navigate(self, vehicle: VehicleStatus, planner: PlannerState | None) -> None:
        m = self._m
        if not vehicle.offboard:
            if m.pending is None and m.want is None:
                if m.offboard_tries >= self.params.offboard_attempts:
                    m.want = Operation.HOLD
                    self._transition(MissionState.HOLD, "vehicle not in offboard", True)
                else:
                    m.want = Operation.OFFBOARD
            return
        if planner is PlannerState.ARRIVED:
            self._event(f"goal {m.index} reached")
            m.index += 1
            if m.index < len(m.goals):
                self._transition(MissionState.NAVIGATE, f"to goal {m.index}")
            elif self.params.end_action == "land":
                self._start_landing("mission complete")
            else:
                m.hold = True
                self._transition(MissionState.HOLD, "mission complete: holding")
            return
        if planner is PlannerState.UNREACHABLE:
            m.hold = True
            self._transition(MissionState.HOLD, f"goal {m.index} unreachable: holding", True)
            return
        target = _PLANNER_TO_STATE.get(planner) if planner is not None else None
        if target is not None and target is not m.state:
            self._transition(target, f"planner {planner.value}")

    def _check_failsafes(self, now_s: float, vehicle: VehicleStatus, health: StageHealth) -> None:
        m, p = self._m, self.params
        airborne = m.state in (*_FLYING, MissionState.FAILSAFE)
        if not airborne:
            return
        if not vehicle.link_ok:
            self._failsafe(FailsafeCause.VEHICLE_LINK_LOST, "vehicle link lost")
            return
        if m.cause is FailsafeCause.VEHICLE_LINK_LOST:
            if p.vehicle_link_back_action == "land":
                m.cause = None
                self._start_landing("vehicle link back: landing")
                return
            if p.vehicle_link_back_action == "resume" and m.index < len(m.goals):
                self._leave_failsafe(MissionState.NAVIGATE, f"vehicle link back: to goal {m.index}")
            else:
                self._leave_failsafe(
                    MissionState.HOLD, "vehicle link back: holding for the operator"
                )
                m.hold = True
        if vehicle.battery_frac is not None and vehicle.battery_frac < p.battery_low_frac:
            if p.battery_action == "rtl":
                m.want = Operation.RTL
                self._transition(MissionState.LANDING, "battery low: returning", True)
            else:
                self._start_landing("battery low: landing")
            m.cause = FailsafeCause.BATTERY_LOW
            return
        if not health.inside_geofence and m.cause is not FailsafeCause.GEOFENCE:
            self._failsafe(FailsafeCause.GEOFENCE, "outside the geofence: holding")
        if health.ground_link_ok is False and p.ground_lost_action != "continue":
            if p.ground_lost_action == "hold":
                self._failsafe(FailsafeCause.GROUND_LINK_LOST, "ground link lost: holding")
            elif p.ground_lost_action == "land":
                self._start_landing("ground link lost: landing")
            else:
                m.want = Operation.RTL
                self._transition(MissionState.LANDING, "ground link lost: returning", True)
            return
        stale = not health.perception_fresh
        if stale:
            m.fresh_since_s = math.nan
            if math.isnan(m.stale_since_s):
                m.stale_since_s = now_s
            if m.state in (MissionState.NAVIGATE, MissionState.AVOID, MissionState.RECOVERY):
                self._failsafe(FailsafeCause.PERCEPTION_STALE, "perception stale: brake and hold")
            elif (
                m.cause is FailsafeCause.PERCEPTION_STALE
                and now_s - m.stale_since_s > p.stale_land_s
            ):
                self._start_landing(f"perception stale for {p.stale_land_s:.0f} s: landing")
        else:
            m.stale_since_s = math.nan
            if math.isnan(m.fresh_since_s):
                m.fresh_since_s = now_s
        if not health.planner_fresh and m.state in (
            MissionState.NAVIGATE,
            MissionState.AVOID,
            MissionState.RECOVERY,
        ):
            self._failsafe(FailsafeCause.PLANNER_STALE, "planner stalled: brake and hold")
        if (
            m.state is MissionState.FAILSAFE
            and m.cause in (FailsafeCause.PERCEPTION_STALE, FailsafeCause.PLANNER_STALE)
            and health.perception_fresh
            and health.planner_fresh
            and now_s - m.fresh_since_s >= p.stale_resume_s
        ):
            self._leave_failsafe(m.resume_state or MissionState.NAVIGATE, "inputs fresh again")

    def _failsafe(self, cause: FailsafeCause, text: str) -> None:
        m = self._m
        if m.state is MissionState.FAILSAFE and m.cause is cause:
            return
        if m.state is not MissionState.FAILSAFE:
            m.resume_state = MissionState.NAVIGATE if m.state is not MissionState.HOLD else m.state
        m.cause = cause
        self._transition(MissionState.FAILSAFE, text, True)

    def _leave_failsafe(self, state: MissionState, text: str) -> None:
        m = self._m
        m.cause, m.resume_state = None, None
        self._transition(state, text)

    def _start_landing(self, text: str) -> None:
        self._m.want = Operation.LAND
        self._m.hold = False
        self._transition(MissionState.LANDING, text, warning="fail" in text or "low" in text)

    def _transition(self, state: MissionState, text: str, warning: bool = False) -> None:
        self._m.state = state
        self._event(text, warning)

    def _event(self, text: str, warning: bool = False) -> None:
        self._events.append(MissionEvent(self._now_s, self._m.state, text, warning))

    def _drain(self) -> tuple[MissionEvent, ...]:
        events = tuple(self._events)
        self._events.clear()
        return events


def _valid_speed(speed_mps: float) -> bool:
    return math.isfinite(speed_mps) and 0.0 < speed_mps <= 15.0
