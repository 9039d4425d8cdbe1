"""Fault injection in a simulated flight and the judgement of the process' reaction.

`FaultAddon` plugs the injectors of `hil.faults` into `fly_world` (the camera wrapper, the
MAVLink relay, the CPU hog, the broker restart) and wraps the flight process' stage callables
for the stalls (the wire CNN, the planner): nothing inside the process knows. For mqtt_restart
it runs the ground link's broker itself (`hil.broker.Mosquitto` on a free loopback port; a
broker configured with `--mqtt` or `ground.broker_url` is not the simulation's to restart, and
the fault is then not injected) and watches the link's health and, as a ground station would,
the vehicle's status topic. It watches the bus, and when the flight is over `fault_rows`
judges each fault on simulated time (the lockstep clock):

- `detectable_s`: when the fault became detectable by the limits the process declares: the
  last good frame's exposure + `flight.perception_max_age_s` (camera freeze, drop and delay,
  stalled CNN), the last plan + `flight.planner_max_age_s` (stalled planner), the first
  affected input (reordered frames, pose jump, link loss, CPU hog, the broker stopping).
- `detected_after_s`: fault start -> the process' first reaction (a failsafe, a refused frame,
  the link reporting loss, the watchdog; for mqtt_restart the ground link going down).
- `stopped_after_s`: detectable -> the vehicle braking to a hold: the first brake the process
  hands the link (the library's stop trajectory, an invalid setpoint the watchdog turns into a
  brake), or for a lost link the autopilot leaving offboard for its own failsafe.
- `halted_after_s`: detectable -> the true speed below `link.brake_speed_mps` (physics:
  from 2 m/s at 2 m/s^2 that alone takes a second).
- `collisions`: contact episodes on the true geometry while the fault and its aftermath last;
  `recovered`: once the fault cleared, the mission flew again and the vehicle moved on by
  more than 0.5 m (or it landed, as configured); `state_after` is its state at the end.

mqtt_restart needs no hold: a lost ground link is a failsafe only as `mission.ground_lost_action`
says (default continue), after `mission.ground_lost_s`. Its row adds `broker_down_s` (the
broker's outage), `reconnected_after_s` (the broker back -> the ground link connected again),
`status_resumed_after_s` (the broker back -> the first status a ground station received that
the vehicle published after it), `interrupted` (the mission left flying for a hold, failsafe or
landing before its goals were done), `ground_lost_action` and `reaction_expected` (the outage
outlasted `ground_lost_s` with an action other than continue). It is recovered when the link
reconnected, the status flowed again and the mission flew on; ok also needs `interrupted` to
be what the configuration asks for (`reaction_expected`).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import tempfile
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import aiomqtt
import numpy as np
from pydantic import ValidationError

from companion.cli.sim_addons import FlightAddon
from companion.clock import Clock
from companion.flight.process import FlightProcess
from companion.ground.client import connect_client, first_version
from companion.ground.link import GroundLink
from companion.ground.params import GroundParams
from companion.ground.protocol import Status, vehicle_topics
from companion.ingest.frames import CameraSource
from companion.topics import Stamped
from hil.broker import Mosquitto
from hil.faults import (
    CAMERA_FAULTS,
    RELAY_FAULTS,
    BrokerRestart,
    CpuHog,
    FaultLog,
    FaultSchedule,
    FaultSpec,
    FaultyCamera,
    MavlinkRelay,
)
from hil.judge import clearance_m, contact_episodes, ground_clearance_m
from hil.lockstep import LockstepClock
from planning.types import SetpointKind

if TYPE_CHECKING:
    from companion.cli.settings import SimSettings
    from companion.cli.sim_flight import FlightRecord

HOLD_FAULTS = frozenset(
    {"camera_freeze", "camera_drop", "camera_delay", "cnn_stall", "planner_stall", "pose_jump"}
)
STOP_WITHIN_S = 0.5  # the requirement: braking to a hold within this of detectable
_FLYING = {"navigate", "avoid", "recovery"}
_ENDED = {"landing", "landed"}
_POLL_S = 0.05
_RELEASE_M = 0.05


@dataclass
class _Observed:
    """What the bus showed, in simulated seconds."""

    perceptions: list[tuple[float, float]] = field(default_factory=list)  # (published, stamp)
    plans: list[float] = field(default_factory=list)  # publication times
    brakes: list[float] = field(default_factory=list)  # brake or invalid setpoints
    events: list[tuple[float, str, str, bool]] = field(default_factory=list)

    def on_message(self, stamped: Stamped) -> None:
        m = stamped.message
        if stamped.topic == "perception":
            self.perceptions.append((stamped.stamp_s, m.stamp_s))
        elif stamped.topic == "plan":
            self.plans.append(stamped.stamp_s)
        elif stamped.topic == "setpoint":
            if m.kind is SetpointKind.BRAKE or not m.valid:
                self.brakes.append(stamped.stamp_s)
        elif stamped.topic == "mission":
            self.events.append((m.stamp_s, m.state.value, m.text, m.warning))


@dataclass
class _GroundObserved:
    """The ground link as the process and a ground station saw it, in simulated seconds."""

    changes: list[tuple[float, bool]] = field(default_factory=list)  # (since_s, connected)
    statuses: list[tuple[float, float]] = field(default_factory=list)  # (received, stamp_s)

    def on_health(self, link: GroundLink) -> None:
        health = link.health()
        if not self.changes or self.changes[-1][1] != health.connected:
            self.changes.append((health.since_s, health.connected))

    def first_change(self, connected: bool, after_s: float) -> float:
        """When the link first went up (`connected`) or down at or after `after_s`."""
        return next((t for t, up in self.changes if up is connected and t >= after_s), math.nan)


async def _watch_status(params: GroundParams, clock: Clock, seen: _GroundObserved) -> None:
    """A ground station on the vehicle's status topic: each status it receives (with the
    vehicle's stamp) into `seen`; it reconnects at once when the broker goes away."""
    topic = vehicle_topics(params.vehicle_id).status
    identifier = f"wireavoid-faults-{uuid.uuid4().hex[:8]}"
    while True:
        try:
            client, _ = await connect_client(
                params, identifier=identifier, version=first_version(params)
            )
            try:
                await client.subscribe(topic, qos=0)
                async for message in client.messages:
                    payload = message.payload
                    if not isinstance(payload, (bytes, bytearray)):
                        continue
                    with contextlib.suppress(ValidationError):
                        status = Status.model_validate_json(payload)
                        if status.online and status.stamp_s is not None:
                            seen.statuses.append((clock.now_s(), status.stamp_s))
            finally:
                with contextlib.suppress(aiomqtt.MqttError):
                    await client.__aexit__(None, None, None)
        except aiomqtt.MqttError:
            pass
        await clock.sleep(_POLL_S)


class _Stalled:
    """A stage callable that does not return while a stall fault is active: it blocks its
    worker until the fault ends (the lockstep clock charges the blocked time)."""

    def __init__(self, fn: Callable[..., Any], schedule: FaultSchedule, kind: str, scale: float):
        self._fn, self._schedule, self._kind, self._scale = fn, schedule, kind, scale

    def __call__(self, *args: Any) -> Any:
        now_s = self._schedule.now_s()
        for log in self._schedule.active({self._kind}, now_s):
            log.effect(now_s)
            time.sleep(max(log.end_s - now_s, 0.0) / max(self._scale, 1e-6))
        return self._fn(*args)


class FaultAddon(FlightAddon):
    """Injects `specs` into a simulated flight; ends it `judge_s` after the last fault ended
    (None: the flight goes on to its mission's end)."""

    def __init__(self, specs: list[FaultSpec], judge_s: float | None = 6.0) -> None:
        self.specs = specs
        self.judge_s = judge_s
        self._clock: Clock | None = None
        self.schedule = FaultSchedule(specs, self._now_s)
        self.observed = _Observed()
        self._relay: MavlinkRelay | None = None
        self._hog = CpuHog(self.schedule)
        self._process: FlightProcess | None = None
        self._stop: asyncio.Event | None = None
        self.ground = _GroundObserved()
        self._broker: Mosquitto | None = None
        self._broker_folder: tempfile.TemporaryDirectory[str] | None = None
        self._restart: BrokerRestart | None = None
        self.broker_note = "the simulation has no broker of its own to restart"

    def _now_s(self) -> float:
        return -math.inf if self._clock is None else self._clock.now_s()

    def _kinds(self) -> set[str]:
        return {s.kind for s in self.specs}

    def settings(self, settings: SimSettings) -> SimSettings:
        if "mqtt_restart" not in self._kinds() or self._broker is not None:
            return settings
        if settings.ground.enabled:
            self.broker_note = (
                f"the ground link's broker {settings.ground.broker_url} is not the simulation's "
                "to restart (--mqtt / ground.broker_url): mqtt_restart runs a broker of its own "
                "when none is configured"
            )
            return settings
        self._broker_folder = tempfile.TemporaryDirectory(prefix="wireavoid-broker-")
        self._broker = Mosquitto.open(Path(self._broker_folder.name))
        self._broker.start()
        self._restart = BrokerRestart(self.schedule, self._broker)
        ground = settings.ground.model_copy(update={"broker_url": self._broker.url})
        return settings.model_copy(update={"ground": ground})

    @property
    def restarts_broker(self) -> bool:
        """mqtt_restart has a broker of the simulation's own to restart."""
        return self._restart is not None

    def vehicle_port(self, port: int) -> int:
        if not self._kinds() & RELAY_FAULTS:
            return port
        self._relay = MavlinkRelay(port, self.schedule).start()
        return self._relay.port

    def camera(self, source: CameraSource, clock: Clock) -> CameraSource:
        self._clock = clock
        if not self._kinds() & CAMERA_FAULTS:
            return source
        return FaultyCamera(source, clock, self.schedule)

    def attach(self, process: FlightProcess, clock: Clock, stop: asyncio.Event) -> None:
        self._clock, self._process, self._stop = clock, process, stop
        scale = clock.compute_scale if isinstance(clock, LockstepClock) else 1.0
        if "cnn_stall" in self._kinds():
            process.detector = _Stalled(process.detector, self.schedule, "cnn_stall", scale)
        if "planner_stall" in self._kinds():
            process.pilot.plan = _Stalled(process.pilot.plan, self.schedule, "planner_stall", scale)
        process.bus.subscribe(self.observed.on_message)

    async def run(self) -> None:
        assert self._clock is not None and self._process is not None
        link = self._process.ground.link
        watcher = None
        if self._restart is not None and link is not None:
            watcher = asyncio.create_task(
                _watch_status(link.params, self._clock, self.ground), name="fault-ground-station"
            )
        end_s = math.inf
        try:
            while True:
                now_s = self._clock.now_s()
                if math.isnan(self.schedule.origin_s) and self._process.link.offboard_engaged:
                    self.schedule.start(now_s)
                    if self.judge_s is not None:
                        end_s = max(log.end_s for log in self.schedule.logs) + self.judge_s
                self._hog.tick()
                if self._restart is not None:
                    await self._restart.tick()
                if link is not None:
                    self.ground.on_health(link)
                if now_s >= end_s and self._stop is not None:
                    self._stop.set()
                    return
                await self._clock.sleep(_POLL_S)
        finally:
            if watcher is not None:
                watcher.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await watcher

    def close(self, record: FlightRecord) -> dict[str, Any]:
        self.release()
        assert self._process is not None
        rows = fault_rows(self, record, self._process)
        return {"faults": rows}

    def release(self) -> None:
        """End what the injectors started (hog processes, the relay, the broker); idempotent,
        for a flight that ended before `close`."""
        self._hog.stop()
        if self._relay is not None:
            self._relay.stop()
        if self._broker is not None:
            self._broker.stop()
        if self._broker_folder is not None:
            self._broker_folder.cleanup()
            self._broker_folder = None


def _first_at_or_after(times: list[float], t: float) -> float:
    return next((x for x in times if x >= t), math.nan)


def _last_before(times: list[float], t: float) -> float:
    before = [x for x in times if x < t]
    return before[-1] if before else math.nan


def _round(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(x) else round(float(x), 3)


def _detectable_s(log: FaultLog, addon: FaultAddon, process: FlightProcess) -> float:
    p = process.settings.flight
    kind = log.spec.kind
    if kind in ("camera_freeze", "camera_drop", "camera_delay"):
        return log.last_good_stamp_s + p.perception_max_age_s
    if kind == "cnn_stall":
        stamps = [s for pub, s in addon.observed.perceptions if pub < log.start_s]
        return (stamps[-1] if stamps else log.start_s) + p.perception_max_age_s
    if kind == "planner_stall":
        last = _last_before(addon.observed.plans, log.start_s)
        return (last if math.isfinite(last) else log.start_s) + p.planner_max_age_s
    return log.first_effect_s if math.isfinite(log.first_effect_s) else log.start_s


def _reaction_s(log: FaultLog, addon: FaultAddon, process: FlightProcess, until_s: float) -> float:
    """The process' first reaction after the fault began: a warning or failsafe of the
    mission, or the link reporting loss or braking (the ground link going down for a broker
    restart)."""
    if log.spec.kind == "mqtt_restart":
        lost = addon.ground.first_change(False, log.start_s)
        return lost if lost < until_s else math.nan
    times = [t for t, _, _, warning in addon.observed.events if warning]
    times += [
        e.stamp_s
        for e in process.link.events
        if e.kind.value in ("link_lost", "watchdog_brake", "watchdog_hold", "offboard_lost")
    ]
    after = sorted(t for t in times if log.start_s <= t < until_s)
    return after[0] if after else math.nan


def _state_at(events: list[tuple[float, str, str, bool]], t: float) -> str | None:
    state = None
    for stamp, s, _, _ in events:
        if stamp > t:
            break
        state = s
    return state


def fault_rows(addon: FaultAddon, record: FlightRecord, process: FlightProcess) -> list[dict]:
    """One row per injected fault: the keys of `wireavoid faults --json` (module docstring)."""
    settings = process.settings
    radius = getattr(getattr(settings, "sim", None), "vehicle_radius_m", 0.3)
    times = np.asarray(record.times_s, dtype=np.float64)
    path = np.asarray(record.path_ned_m, dtype=np.float64).reshape(-1, 3)
    speeds = np.zeros(len(times))
    if len(times) > 1:
        steps = np.linalg.norm(np.diff(path, axis=0), axis=1) / np.maximum(np.diff(times), 1e-9)
        speeds[1:] = steps
    logs = sorted(addon.schedule.logs, key=lambda log: log.start_s)
    flight_end_s = float(times[-1]) if len(times) else math.nan
    rows = []
    for i, log in enumerate(logs):
        kind = log.spec.kind
        note = _not_injected(log, addon)
        if note:
            rows.append({"name": kind, "injected": False, "ok": False,
                         "detected_after_s": None, "stopped_after_s": None,
                         "collisions": 0, "recovered": False, "note": note})  # fmt: skip
            continue
        until_s = logs[i + 1].start_s if i + 1 < len(logs) else flight_end_s
        detectable = _detectable_s(log, addon, process)
        reaction = _reaction_s(log, addon, process, until_s)
        hold_needed = kind in HOLD_FAULTS
        if kind == "link_loss" and addon._relay is not None:
            left = [t for t, offboard in addon._relay.offboard_changes if not offboard]
            braked = _first_at_or_after(left, log.start_s)
        else:
            braked = _first_at_or_after(addon.observed.brakes, log.start_s)
        stopped = max(braked - detectable, 0.0) if math.isfinite(braked) else math.nan
        if math.isfinite(braked) and braked >= until_s:
            stopped = math.nan
        window = (times >= log.start_s) & (times < until_s)
        slow = (times >= detectable) & window & (speeds < settings.link.brake_speed_mps)
        halted = float(times[slow][0]) - detectable if slow.any() else math.nan
        grounded = np.asarray(record.on_ground, dtype=bool)[window]
        collisions, min_clearance = _contacts(record, path[window], grounded, radius)
        after = log.end_s if kind != "pose_jump" else log.start_s + log.spec.duration_s
        state_end = _state_at(addon.observed.events, until_s)
        moved = _moved_after(times, path, after, until_s)
        # flew again once the fault cleared (a later, unrelated stale frame does not undo it)
        flew_again = _state_at(addon.observed.events, after) in _FLYING or any(
            after <= t < until_s and state in _FLYING for t, state, _, _ in addon.observed.events
        )
        recovered = bool(
            (flew_again and moved > 0.5) or state_end in _ENDED
            or (state_end == "hold" and _mission_done(addon))
        )  # fmt: skip
        stop_ok = not hold_needed or (math.isfinite(stopped) and stopped <= STOP_WITHIN_S)
        row: dict[str, Any] = {}
        if kind == "mqtt_restart":
            row = _broker_row(log, addon, process, until_s)
            recovered = bool(recovered and row.pop("link_back"))
            stop_ok = row["interrupted"] == row["reaction_expected"]
        rows.append(
            {
                "name": kind,
                "injected": True,
                "start_s": _round(log.start_s),
                "duration_s": log.spec.duration_s,
                "detectable_after_s": _round(detectable - log.start_s),
                "detected_after_s": _round(reaction - log.start_s),
                "stopped_after_s": _round(stopped),
                "halted_after_s": _round(halted),
                "hold_required": hold_needed,
                "collisions": collisions,
                "min_clearance_m": _round(min_clearance),
                "recovered": recovered,
                "state_after": state_end,
                "moved_after_m": _round(moved),
                "affected_inputs": log.affected,
                **row,
                "ok": bool(collisions == 0 and recovered and stop_ok),
            }
        )
    return rows


def _not_injected(log: FaultLog, addon: FaultAddon) -> str:
    """Why the fault was not injected ("" when it was)."""
    if math.isnan(log.start_s):
        return "offboard never engaged: the fault was not injected"
    if log.spec.kind == "mqtt_restart" and not addon.restarts_broker:
        return addon.broker_note
    return ""


def _broker_row(
    log: FaultLog, addon: FaultAddon, process: FlightProcess, until_s: float
) -> dict[str, Any]:
    """The mqtt_restart columns (module docstring), and `link_back`: reconnected and the
    status flowing again (taken into `recovered`)."""
    mission = process.settings.mission
    back_s = log.cleared_s
    lost_s = addon.ground.first_change(False, log.start_s)
    reconnected_s = addon.ground.first_change(True, back_s) if math.isfinite(back_s) else math.nan
    resumed_s = next((stamp for _, stamp in addon.ground.statuses if stamp >= back_s), math.nan)
    outage_s = (reconnected_s if math.isfinite(reconnected_s) else until_s) - lost_s
    expected = mission.ground_lost_action != "continue" and outage_s > mission.ground_lost_s
    done = [t for t, _, text, _ in addon.observed.events if "mission complete" in text]
    done_s = done[0] if done else math.inf
    interrupted = any(
        log.start_s <= t < min(until_s, done_s) and state not in _FLYING
        for t, state, _, _ in addon.observed.events
    )
    return {
        "broker_down_s": _round(back_s - log.first_effect_s),
        "reconnected_after_s": _round(reconnected_s - back_s),
        "status_resumed_after_s": _round(resumed_s - back_s),
        "statuses_received": len(addon.ground.statuses),
        "interrupted": interrupted,
        "ground_lost_action": mission.ground_lost_action,
        "reaction_expected": bool(expected),
        "link_back": bool(math.isfinite(reconnected_s) and math.isfinite(resumed_s)),
    }


def _mission_done(addon: FaultAddon) -> bool:
    return any("mission complete" in text for _, _, text, _ in addon.observed.events)


def _moved_after(times: np.ndarray, path: np.ndarray, start_s: float, end_s: float) -> float:
    """Distance flown between `start_s` and `end_s`, m."""
    inside = (times >= start_s) & (times <= end_s)
    if inside.sum() < 2:
        return 0.0
    return float(np.linalg.norm(np.diff(path[inside], axis=0), axis=1).sum())


def _contacts(
    record: FlightRecord, points: np.ndarray, grounded: np.ndarray, radius_m: float
) -> tuple[int, float]:
    """Contact episodes (solids, wires, the ground while airborne) and the least clearance to
    solids and wires, m."""
    if len(points) == 0:
        return 0, math.inf
    obstacle, wire = clearance_m(record.world, points)
    ground = np.where(grounded, np.inf, ground_clearance_m(record.world, points))
    nearest = np.minimum(np.minimum(obstacle, wire), ground)
    episodes = contact_episodes(nearest < radius_m, nearest >= radius_m + _RELEASE_M)
    return int(episodes), float(np.minimum(obstacle, wire).min())
