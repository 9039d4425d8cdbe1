"""The setpoint staleness guard (STYLE.md practice 6): brake, then Hold, when the plan is stale.

MAVSDK re-sends the last setpoint every 50 ms by itself, so PX4's own offboard-loss failsafe
(COM_OF_LOSS_T) never fires while our process is alive but the planner is stuck. This pure
state machine decides, tick by tick, what the streamer sends: the planner's setpoint while it is
fresh and valid; zero velocity once it is older than `max_age_s` or marked invalid; and a
switch to Hold once the vehicle has slowed below `brake_speed_mps` or `brake_timeout_s` has
passed. Once tripped it stays tripped until `rearm()` (a new offboard entry).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum


class WatchdogAction(Enum):
    """What the streamer does this tick."""

    STREAM = "stream"  # send the planner's setpoint
    BRAKE = "brake"  # send zero velocity
    HOLD = "hold"  # leave offboard for Hold (once), then send nothing of ours
    TRIPPED = "tripped"  # Hold already requested; waiting for rearm()


@dataclass(frozen=True)
class WatchdogEvent:
    """A transition of the watchdog at `stamp_s` (monotonic, s)."""

    stamp_s: float
    action: WatchdogAction
    setpoint_age_s: float
    speed_mps: float
    reason: str


class SetpointWatchdog:
    """Brake-then-hold guard on the age of the planner output; pure, time passed in."""

    def __init__(self, max_age_s: float, brake_timeout_s: float, brake_speed_mps: float) -> None:
        self.max_age_s = max_age_s
        self.brake_timeout_s = brake_timeout_s
        self.brake_speed_mps = brake_speed_mps
        self._action = WatchdogAction.STREAM
        self._brake_start_s: float | None = None
        self._armed_at_s = -math.inf
        self.events: list[WatchdogEvent] = []

    @property
    def action(self) -> WatchdogAction:
        """The action decided at the last update."""
        return self._action

    def rearm(self, now_s: float) -> None:
        """Back to STREAM when offboard is (re-)entered at `now_s`.

        Setpoints are judged from `now_s` on: the one offboard was entered with may be older
        than `max_age_s` (entry takes seconds), and the planner gets `max_age_s` to follow it.
        """
        self._action = WatchdogAction.STREAM
        self._brake_start_s = None
        self._armed_at_s = now_s

    def update(
        self,
        now_s: float,
        setpoint_stamp_s: float | None,
        speed_mps: float,
        valid: bool = True,
    ) -> WatchdogAction:
        """The action for this tick.

        `setpoint_stamp_s` is the production time of the latest planner output (None: none yet,
        which counts as stale from the last `rearm`); `speed_mps` the measured speed (NaN or
        inf when unknown: then braking lasts the full `brake_timeout_s`); `valid` False when
        the planner marked its output invalid (no plan, stale inputs): that brakes at once.
        """
        stamp_s = -math.inf if setpoint_stamp_s is None else setpoint_stamp_s
        age_s = now_s - max(stamp_s, self._armed_at_s)
        previous = self._action
        if previous is WatchdogAction.STREAM:
            if age_s > self.max_age_s or not valid:
                self._action = WatchdogAction.BRAKE
                self._brake_start_s = now_s
                reason = f"planner output {age_s:.2f} s old" if valid else "planner output invalid"
                self._record(now_s, age_s, speed_mps, reason)
        elif previous is WatchdogAction.BRAKE:
            assert self._brake_start_s is not None
            braked_s = now_s - self._brake_start_s
            if speed_mps < self.brake_speed_mps or braked_s >= self.brake_timeout_s:
                self._action = WatchdogAction.HOLD
                self._record(
                    now_s, age_s, speed_mps, f"braked {braked_s:.2f} s to {speed_mps:.2f} m/s"
                )
        elif previous is WatchdogAction.HOLD:
            self._action = WatchdogAction.TRIPPED
        return self._action

    def _record(self, now_s: float, age_s: float, speed_mps: float, reason: str) -> None:
        self.events.append(WatchdogEvent(now_s, self._action, age_s, speed_mps, reason))
