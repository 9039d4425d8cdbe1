"""The flight process: the thesis' loop, camera to setpoints, as one set of asyncio tasks.

```
camera source -> [ingest] -> camera -> [perceive: wire CNN, worker "perceive"] -> perception
telemetry -> [vehicle] -> PoseHistory, vehicle                                       |
perception + pose at the frame's stamp -> [map: DROAN insert, worker "map"] -> map   v
map update or 1/planning.rate_hz -> [plan: planner, worker "map"] -> plan
map update -> [fit wires: catenary refit, worker "catenary"] (catenary.use_in_collision_check)
plan, planning.setpoint_rate_hz or a new plan -> [track: tracker] -> setpoint -> link
mission.rate_hz -> [mission: state machine] -> arm / takeoff / offboard / land on the link
```

Each stage takes the newest message of its input topic (`companion.topics.Bus`): a busy
stage skips frames rather than queue them, and the skipped ones are counted. With
`flight.wires_during_takeoff_and_landing` off, frames taken while the mission is not airborne
(on the ground, the takeoff climb, landing) give the map their stereo alone: a vertical
sweep turns each wire's prior into a fan. The CNN runs on
a worker thread of its own; map inserts and planner queries share one, so the map never
changes under a query. Every message carries the stamp of the exposure it derives from: a
plan built on a map whose newest frame is older than `flight.perception_max_age_s` is not
flown (the mission brakes and holds, thesis 4.4 needs fresh frames), and setpoints from a
plan older than `flight.planner_max_age_s` go out invalid, which the link turns into a brake
and PX4's Hold: the vehicle is never left flying blind. Latencies of every stage (p50/p99)
and dropped frames are in `times` and logged every `flight.status_period_s`.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field

import numpy as np

from companion.clock import Clock, cancel_and_wait, wait_or_timeout
from companion.config import Settings
from companion.flight.ground import GroundConnection
from companion.flight.map_builder import MapBuilder, MapUpdate
from companion.flight.perceive import Perception, WireDetector
from companion.flight.pilot import Pilot
from companion.flight.pose_jump import pose_jump_m
from companion.flight.timing import StageTimes
from companion.flight.vehicle_check import VehicleCheck
from companion.ingest.frames import CameraError, CameraFrame, CameraSource
from companion.link.telemetry import LandedState, TelemetrySnapshot
from companion.link.vehicle_link import LinkError, LinkState, VehicleLink
from companion.mission import (
    AIRBORNE,
    Decision,
    Mission,
    MissionEvent,
    MissionState,
    Operation,
    OperationResult,
    StageHealth,
    VehicleStatus,
)
from companion.topics import Bus
from perception.segmenter import WireSegmenter
from planning.types import PlannerOutput, PlannerState, Setpoint, VehicleState

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class PlanUpdate:
    """One planning cycle: its output and every input it had (so a replay can run it again):
    the vehicle state, the exposure stamp of the newest frame in the map it queried (-inf before
    any; read on the map's worker, so it is exactly the map the planner saw), the mission's
    goal (local NED, m; None: none), hold and cruise speed (None: `planning.max_speed_mps`),
    and the velocity the library started from, (3,) NED m/s."""

    output: PlannerOutput
    vehicle: VehicleState
    frame_stamp_s: float
    goal_index: int
    goal_ned_m: np.ndarray | None = None
    hold: bool = False
    speed_mps: float | None = None
    commanded_velocity_ned_mps: np.ndarray = field(default_factory=lambda: np.zeros(3))


@dataclass
class FlightReport:
    """How the process ran: the mission's end, its events, and the stage statistics."""

    state: MissionState = MissionState.IDLE
    events: list[MissionEvent] = field(default_factory=list)
    frames: int = 0
    perceptions: int = 0
    fused: int = 0
    unregistered: int = 0  # frames not fused: no pose near their stamp
    refused: int = 0  # frames not newer than the last one, or repeating its pixels (frozen)
    plans: int = 0
    setpoints: int = 0
    timings: dict[str, object] = field(default_factory=dict)


class FlightProcess:
    """The closed loop on a connected `VehicleLink` and a `CameraSource`.

    Construct with the parts (the wire segmenter is loaded from `settings.perception` when
    not given; a `detector` replaces the CNN stage's, as a simulator's diagnostics do), then
    `await run()`. A simulator plugs in its own camera source and clock;
    the process cannot tell.
    """

    def __init__(
        self,
        settings: Settings,
        link: VehicleLink,
        camera: CameraSource,
        clock: Clock,
        segmenter: WireSegmenter | None = None,
        detector: Callable[[CameraFrame], Perception] | None = None,
    ) -> None:
        self.settings = settings
        self.link = link
        self.camera = camera
        self.clock = clock
        self.bus = Bus(clock.now_s)
        self.times = StageTimes(settings.flight.timing_window)
        self.mission = Mission(settings.mission)
        self.detector = detector or WireDetector(
            segmenter or WireSegmenter.load(params=settings.perception)
        )
        self.builder = MapBuilder(settings.mapping, settings.catenary)
        self.pilot = Pilot(settings.planning)
        self._rebuilt_s = -math.inf  # when the map was last rebuilt after a pose jump
        self.report = FlightReport()
        self.ground = GroundConnection(self)
        self.decision: Decision | None = None
        self._operation: asyncio.Task[OperationResult] | None = None
        self._flown = False
        self._refusal = ""  # why the vehicle check forbids flying ("" when it may)
        self._refused_warned_s = -math.inf  # refused frames are reported once a status period
        self.mission_tick_s = clock.now_s()  # the mission loop's last tick (the watchdog's)

    # ------------------------------------------------------------------ running

    async def run(
        self, stop: asyncio.Event | None = None, until_done: bool = False
    ) -> FlightReport:
        """Run every stage until `stop` is set, or (with `until_done`) the mission ended.

        The mission ends once it flew and then landed, or holds after its last goal. A
        stage that raises ends the process with that exception (after the others stopped).
        """
        stop = stop or asyncio.Event()
        stages: list[Callable[[], Awaitable[None]]] = [
            self._ingest,
            self._vehicle,
            self._perceive,
            self._map,
            self._plan,
            self._track,
            self._status,
            self.ground.run,
        ]
        if self.settings.catenary.use_in_collision_check:
            stages.append(self._fit_wires)
        try:
            async with asyncio.TaskGroup() as group:
                tasks = [group.create_task(stage(), name=stage.__name__) for stage in stages]
                mission = group.create_task(self._mission(stop, until_done), name="mission")
                await mission
                await cancel_and_wait(tasks)  # re-cancels one that swallowed a cancel
        finally:
            if self._operation is not None and not self._operation.done():
                self._operation.cancel()
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await self._operation
            with contextlib.suppress(Exception):
                await self.camera.close()
            self.report.state = self.mission.state
            self.report.timings = self.times.to_dict()
        return self.report

    # ------------------------------------------------------------------ stages

    async def _ingest(self) -> None:
        """Frames from the camera source onto the bus; reopen a source that failed."""
        p = self.settings.flight
        await self.camera.open()
        previous: CameraFrame | None = None
        while True:
            try:
                frame = await self._next_frame(p.camera_timeout_s)
            except CameraError as e:
                self._warn(f"camera failed: {e}; reopening in {p.camera_retry_s:.1f} s")
                with contextlib.suppress(Exception):
                    await self.camera.close()
                await self.clock.sleep(p.camera_retry_s)
                with contextlib.suppress(CameraError):
                    await self.camera.open()
                continue
            if frame is None:
                self._warn(f"no camera frame for {p.camera_timeout_s:.1f} s")
                continue
            self.report.frames += 1
            if previous is not None and (
                frame.stamp_s <= previous.stamp_s or _same_pixels(frame, previous)
            ):
                # a frame from the past (reordered, repeated) or a frozen camera's copy: never
                # fused, so a camera that stops seeing makes perception stale
                self.report.refused += 1
                now_s = self.clock.now_s()
                if now_s - self._refused_warned_s >= p.status_period_s:
                    self._refused_warned_s = now_s
                    self._warn(
                        f"camera: frame {frame.sequence} refused (older than, or the same "
                        f"pixels as, frame {previous.sequence}); {self.report.refused} so far"
                    )
                continue
            previous = frame
            self.times.add("ingest", self.clock.now_s() - frame.stamp_s)
            self.bus.publish("camera", frame)

    async def _next_frame(self, timeout_s: float) -> CameraFrame | None:
        box: list[CameraFrame] = []

        async def take() -> None:
            box.append(await self.camera.next_frame())

        await wait_or_timeout(self.clock, take(), timeout_s)
        return box[0] if box else None

    async def _vehicle(self) -> None:
        """Each new local position from telemetry: into the pose history and onto the bus."""
        p = self.settings.flight
        last_s, previous = -math.inf, None
        while True:
            try:
                snap = await self.link.wait_until(_pose_newer_than(last_s), 1.0, "telemetry")
            except LinkError:
                continue  # silence is the link supervisor's to report
            last_s = snap.pose.stamp_s
            world_from_body = snap.world_from_body()
            if world_from_body is not None:
                jump_m = pose_jump_m(previous, snap.pose, p.pose_jump_max_gap_s)
                previous = snap.pose
                if jump_m > p.pose_jump_m:
                    self.reset_map()
                    self._warn(f"local position jumped {jump_m:.1f} m: map rebuilt, holding")
                self.builder.add_pose(last_s, world_from_body)
                self.bus.publish("vehicle", snap)

    def reset_map(self) -> None:
        """A new, empty map and a fresh planner (after the local frame jumped): perception is
        stale until new frames are fused and `flight.pose_jump_hold_s` has passed, so the
        mission brakes and holds meanwhile."""
        self.builder = MapBuilder(self.settings.mapping, self.settings.catenary)
        self.pilot.reset()
        self._rebuilt_s = self.clock.now_s()

    async def _perceive(self) -> None:
        """The newest frame through the wire CNN (on its own worker)."""
        seen = 0
        while True:
            stamped = await self.bus.newer("camera", seen)
            self.times.dropped_frames += stamped.seq - seen - 1
            seen = stamped.seq
            start_s = self.clock.now_s()
            perception = await self.clock.compute("perceive", self.detector, stamped.message)
            self.times.add("cnn", self.clock.now_s() - start_s)
            self.report.perceptions += 1
            self.bus.publish("perception", perception)

    async def _map(self) -> None:
        """The newest perception into the map at its camera pose (on the map's worker)."""
        seen = 0
        while True:
            stamped = await self.bus.newer("perception", seen)
            self.times.dropped_frames += stamped.seq - seen - 1
            seen = stamped.seq
            perception: Perception = stamped.message
            pose = self.builder.camera_pose_at(perception.stamp_s)
            wires = self.settings.flight.wires_during_takeoff_and_landing
            wires |= self.mission.state in AIRBORNE
            start_s = self.clock.now_s()
            update: MapUpdate = await self.clock.compute(
                "map", self.builder.insert, perception, pose, wires
            )
            self.times.add("map", self.clock.now_s() - start_s)
            if update.result is None:
                self.report.unregistered += 1
            else:
                self.report.fused += 1
            self.bus.publish("map", update)

    async def _fit_wires(self) -> None:
        """After each map update, the catenary refit it owes (ch. 3) on a worker of its own:
        a refit takes up to 2 s, which on the map's worker would stall mapping and planning
        (`catenary.use_in_collision_check`)."""
        seen = 0
        while True:
            stamped = await self.bus.newer("map", seen)
            seen = stamped.seq
            builder = self.builder
            refit = builder.take_catenary_refit()
            if refit is None:
                continue
            start_s = self.clock.now_s()
            fits = await self.clock.compute("catenary", refit)
            self.times.add("catenary", self.clock.now_s() - start_s)
            if builder is self.builder:  # not rebuilt meanwhile (a pose jump)
                builder.use_catenary_fits(fits)

    async def _plan(self) -> None:
        """A planning cycle on every map update, and at least at `planning.rate_hz`."""
        period_s = 1.0 / self.settings.planning.rate_hz
        seen = 0
        while True:
            await wait_or_timeout(self.clock, self.bus.newer("map", seen), period_s)
            latest = self.bus.latest("map")
            seen = 0 if latest is None else latest.seq
            vehicle = self._vehicle_state()
            decision = self.decision
            if vehicle is None or decision is None:
                continue
            fresh = self._perception_fresh()
            hold = decision.hold or not fresh or not self.link.offboard_engaged
            self.pilot.set_speed(decision.speed_mps, vehicle.stamp_s)
            commanded = self.pilot.commanded_velocity(vehicle)
            start_s = self.clock.now_s()
            output, frame_s = await self.clock.compute(
                "map", self._plan_on_map, start_s, vehicle, decision.goal_ned_m, hold, commanded
            )
            took_s = self.clock.now_s() - start_s
            self.times.add("plan", took_s)
            if took_s > period_s:
                self.times.overruns["plan"] += 1
            self.report.plans += 1
            update = PlanUpdate(
                output, vehicle, frame_s, decision.goal_index, decision.goal_ned_m, hold,
                decision.speed_mps, commanded,
            )  # fmt: skip
            self.bus.publish("plan", update)

    def _plan_on_map(
        self,
        now_s: float,
        vehicle: VehicleState,
        goal_ned_m: np.ndarray | None,
        hold: bool,
        commanded_velocity_ned_mps: np.ndarray,
    ) -> tuple[PlannerOutput, float]:
        """One planning cycle on the map's worker, and the newest frame of the map it saw."""
        frame_s = self.builder.newest_frame_s
        output = self.pilot.plan(
            now_s, vehicle, self.builder.occupancy_map(), goal_ned_m, hold,
            commanded_velocity_ned_mps,
        )  # fmt: skip
        return output, frame_s

    async def _track(self) -> None:
        """Setpoints from the newest plan at the setpoint rate, and at once for a new plan."""
        period_s = 1.0 / self.settings.planning.setpoint_rate_hz
        max_age_s = self.settings.flight.planner_max_age_s
        seen, counted_frame_s = 0, -math.inf
        while True:
            await wait_or_timeout(self.clock, self.bus.newer("plan", seen), period_s)
            plan = self.bus.latest("plan")
            vehicle = self._vehicle_state()
            if plan is None or vehicle is None:
                continue
            now_s = self.clock.now_s()
            fresh = now_s - plan.stamp_s <= max_age_s
            setpoint = self.pilot.setpoint(now_s, vehicle, plan.message.output if fresh else None)
            self._publish_setpoint(setpoint)
            if plan.seq != seen:
                seen = plan.seq
                self.times.add("stream", now_s - plan.stamp_s)
                frame_s = plan.message.frame_stamp_s
                if frame_s > counted_frame_s and math.isfinite(frame_s):
                    counted_frame_s = frame_s
                    self.times.add("frame_to_setpoint", now_s - frame_s)

    def _publish_setpoint(self, setpoint: Setpoint) -> None:
        decision = self.decision
        flying = decision is not None and decision.state in AIRBORNE
        if flying or (self._operation is not None and not self._operation.done()):
            self.link.setpoints.publish(setpoint)
        self.report.setpoints += 1
        self.bus.publish("setpoint", setpoint)

    async def _mission(self, stop: asyncio.Event, until_done: bool) -> None:
        """Step the mission manager and carry out its vehicle operations."""
        period_s = 1.0 / self.settings.flight.mission_rate_hz
        while not stop.is_set():
            self.mission_tick_s = self.clock.now_s()
            result = self._finished_operation()
            decision = self.mission.step(
                self.clock.now_s(),
                self._vehicle_status(),
                self._health(),
                self._planner_state(),
                result,
            )
            self.decision = decision
            for event in decision.events:
                self.report.events.append(event)
                self.bus.publish("mission", event)
                log.log(
                    logging.WARNING if event.warning else logging.INFO,
                    "mission %s: %s",
                    event.state.value,
                    event.text,
                )
            if decision.operation is not None:
                self._operation = asyncio.create_task(
                    self._operate(decision.operation), name=f"op-{decision.operation.value}"
                )
            if decision.state in AIRBORNE:
                self._flown = True
            if until_done and self._done(decision):
                return
            await wait_or_timeout(self.clock, stop.wait(), period_s)

    async def _status(self) -> None:
        """Log the stage timings every `flight.status_period_s`."""
        while True:
            await self.clock.sleep(self.settings.flight.status_period_s)
            log.info("stages: %s", self.times.line())

    # ------------------------------------------------------------------ mission plumbing

    def _done(self, decision: Decision) -> bool:
        if not self._flown or (self._operation is not None and not self._operation.done()):
            return False
        ended = decision.goal_index >= len(self.mission.goals_ned_m)
        return decision.state is MissionState.LANDED or (
            decision.state is MissionState.HOLD and ended
        )

    def _finished_operation(self) -> OperationResult | None:
        task = self._operation
        if task is None or not task.done():
            return None
        self._operation = None
        return task.result()

    def adopt(self, check: VehicleCheck) -> None:
        """Fly with what the vehicle check found (before `run`): the vehicle's limits in the
        planner and tracker, its refusal (the mission then never arms) and its warnings."""
        self.settings = check.settings
        self.pilot.adopt(check.settings.planning)
        self._refusal = check.refusal
        for warning in check.warnings:
            self._warn(f"pre-flight: {warning}")

    async def _operate(self, operation: Operation) -> OperationResult:
        """Carry out one vehicle operation on the link; its outcome for the mission."""
        link = self.link
        if operation is Operation.ARM and self._refusal:
            return OperationResult(operation, False, self._refusal)
        try:
            if operation is Operation.ARM:
                await link.arm()
            elif operation is Operation.TAKEOFF:
                await link.takeoff(self.mission.takeoff_altitude_m)
            elif operation is Operation.OFFBOARD:
                await link.start_offboard(self._hold_setpoint())
            elif operation is Operation.HOLD:
                await link.hold()
            elif operation is Operation.LAND:
                await link.land()
            elif operation is Operation.RTL:
                await link.return_to_launch()
        except LinkError as e:
            return OperationResult(operation, False, str(e))
        except Exception as e:  # a failed operation is the mission's to handle, not a crash
            log.exception("operation %s", operation.value)
            return OperationResult(operation, False, repr(e))
        return OperationResult(operation, True)

    def _hold_setpoint(self) -> Setpoint:
        """Hold where the vehicle is: the first setpoint offboard is entered with."""
        snap = self.link.telemetry()
        now_s = self.clock.now_s()
        if snap.pose is None:
            return Setpoint.brake(math.nan, now_s)
        yaw = snap.attitude.yaw_rad if snap.attitude is not None else math.nan
        return Setpoint.position(snap.pose.position_ned_m, yaw, now_s)

    def _vehicle_state(self) -> VehicleState | None:
        snap = self.link.telemetry()
        if snap.age_s() > self.settings.link.link_loss_timeout_s:
            return None
        return snap.vehicle_state()

    def _vehicle_status(self) -> VehicleStatus:
        snap: TelemetrySnapshot = self.link.telemetry()
        battery = None if snap.battery is None else snap.battery.remaining_frac
        return VehicleStatus(
            link_ok=self.link.state is LinkState.CONNECTED,
            armed=snap.armed,
            in_air=None
            if snap.landed_state is LandedState.UNKNOWN
            else snap.landed_state is LandedState.IN_AIR,
            offboard=self.link.offboard_engaged,
            position_ned_m=None if snap.pose is None else snap.pose.position_ned_m,
            battery_frac=None if battery is None or not np.isfinite(battery) else battery,
        )

    def _perception_fresh(self) -> bool:
        p, now_s = self.settings.flight, self.clock.now_s()
        if now_s - self._rebuilt_s < p.pose_jump_hold_s:
            return False
        return now_s - self.builder.newest_frame_s <= p.perception_max_age_s

    def _health(self) -> StageHealth:
        return StageHealth(
            perception_fresh=self._perception_fresh(),
            planner_fresh=self.bus.age_s("plan") <= self.settings.flight.planner_max_age_s,
            ground_link_ok=self.ground.ground_link_ok(self.clock.now_s()),
            inside_geofence=self.ground.inside_geofence(),
        )

    def _planner_state(self) -> PlannerState | None:
        """The newest plan's state, if it was planned for the mission's active goal."""
        plan = self.bus.latest("plan")
        if plan is None or plan.message.goal_index != self.mission.goal_index:
            return None
        return plan.message.output.state

    def _warn(self, text: str) -> None:
        state = self.mission.state
        event = MissionEvent(self.clock.now_s(), state, text, warning=True)
        self.report.events.append(event)
        self.bus.publish("mission", event)
        log.warning("%s", text)


def _same_pixels(a: CameraFrame, b: CameraFrame) -> bool:
    """Whether two frames carry identical images: a real sensor's noise never repeats."""
    if a.image_bgr is not None and b.image_bgr is not None:
        return a.image_bgr.shape == b.image_bgr.shape and np.array_equal(a.image_bgr, b.image_bgr)
    if a.disparity_px is not None and b.disparity_px is not None:
        return np.array_equal(a.disparity_px, b.disparity_px, equal_nan=True)
    return False


def _pose_newer_than(stamp_s: float) -> Callable[[TelemetrySnapshot], bool]:
    """Predicate: the snapshot holds a local position that arrived after `stamp_s`."""
    return lambda s: s.pose is not None and s.pose.stamp_s > stamp_s
