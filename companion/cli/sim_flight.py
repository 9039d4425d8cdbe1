"""One simulated flight of the whole stack: the composition `wireavoid sim` and `sweep` run.

The parts are the product's own (`companion.flight.process.FlightProcess` on a `VehicleLink`
through the real MAVSDK), plugged into the hil harness: the PX4-like vehicle over real MAVLink
on a free UDP port, the simulated cameras behind the `CameraSource` protocol, and the
lockstep clock (or the wall clock with `sim.time = "realtime"`). With `connect_url` the
vehicle is an external autopilot (PX4 SITL) and the flight runs in real time: the cameras
render from the ground truth PX4 SITL's SIH streams (`sim.px4_ground_truth`; the stack flies
on PX4's estimate, as on a real drone), else from its telemetry pose.

Frames: the world file's NED frame is the judge's; the vehicle's local NED frame starts at the
world's take-off point (PX4's home), so `local = world - start` for goals and poses.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import socket
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from companion.cli.settings import SimSettings
from companion.cli.sim_addons import FlightAddon
from companion.cli.sim_camera import SimulatedCameraSource, settings_camera
from companion.cli.sim_masks import TruthWireDetector
from companion.clock import Clock, WallClock, wait_or_timeout
from companion.flight.perceive import WireDetector
from companion.flight.process import FlightProcess, FlightReport
from companion.flight.vehicle_check import check_vehicle
from companion.link.vehicle_link import LinkError, LinkEvent, VehicleLink
from companion.mission import AIRBORNE
from geometry.pose import Pose
from hil.lockstep import LockstepClock
from hil.mavlink.server import VehicleServer
from hil.px4_truth import Px4TruthTap, sih_truth_port
from hil.world.model import World
from perception.segmenter import WireSegmenter

log = logging.getLogger(__name__)

TRUTH_RATE_HZ = 50.0  # how often the judge samples the vehicle's true position
TRUTH_WAIT_S = 3.0  # how long PX4 SITL's ground truth may take to arrive


@dataclass
class FlightRecord:
    """What a simulated flight produced, before it is judged."""

    world: World
    times_s: np.ndarray  # (N,) simulated (or wall) seconds since the vehicle booted
    path_ned_m: np.ndarray  # (N, 3) true positions in the world frame, m
    on_ground: np.ndarray  # (N,) bool, the vehicle touching the ground
    report: FlightReport
    link_events: list[LinkEvent]
    completed: bool  # the mission ended (landed or holding after its last goal) in time
    failure: str = ""  # why the flight could not be flown, empty when it was
    wall_s: float = 0.0
    compute_s: float = 0.0  # simulated seconds charged for the stack's computation
    truth_source: str = "simulator"
    extra: dict[str, object] = field(default_factory=dict)


def free_udp_port() -> int:
    """A UDP port nobody listens on now."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def mission_settings(settings: SimSettings, world: World) -> SimSettings:
    """The settings with the world's mission: auto-start, its take-off altitude and goals in
    the vehicle's local frame (world minus take-off point)."""
    goals = np.asarray(world.goals_ned_m, dtype=np.float64).reshape(-1, 3) - world.start_ned_m
    mission = settings.mission.model_copy(
        update={
            "auto_start": True,
            "takeoff_altitude_m": float(world.takeoff_altitude_m),
            "goals_ned_m": [tuple(float(x) for x in g) for g in goals],
        }
    )
    return settings.model_copy(update={"mission": mission})


async def fly_world(
    settings: SimSettings,
    world: World,
    *,
    segmenter: WireSegmenter | None = None,
    connect_url: str | None = None,
    progress: bool = False,
    addons: Sequence[FlightAddon] = (),
) -> FlightRecord:
    """Fly `world`'s mission with the whole stack; never raises for a failed flight.

    progress: print a line on stderr every simulated second (state, position, goal).
    addons: recorders, live views, fault injectors (`companion.cli.sim_addons`); what each
    reports when the flight ends goes into `FlightRecord.extra`.
    """
    started = time.monotonic()
    settings = mission_settings(settings, world)
    for addon in addons:
        settings = addon.settings(settings)
    sim = settings.sim
    lockstep = connect_url is None and sim.time == "lockstep"
    # the slow set-up (CNN runtime, numba kernels) before any clock runs
    segmenter = segmenter or WireSegmenter.load(params=settings.perception)
    server: VehicleServer | None = None
    clock: Clock
    if connect_url is None:
        vehicle = settings.vehicle_sim
        if lockstep:
            vehicle = vehicle.model_copy(update={"heartbeat_rate_hz": sim.vehicle_heartbeat_hz})
        port = free_udp_port()
        vehicle_port = port
        for addon in addons:
            vehicle_port = addon.vehicle_port(vehicle_port)
        server = VehicleServer(vehicle, vehicle_port, lockstep=lockstep, speed=1.0)
        server.start()
        connect_url = f"udpin://127.0.0.1:{port}"
        clock = (
            LockstepClock(server, max_speed=sim.max_speed, compute_scale=sim.compute_scale)
            if lockstep
            else WallClock()
        )
    else:
        clock = WallClock()
    link = VehicleLink(
        settings.link.model_copy(update={"connection_url": connect_url}), clock=clock
    )
    tap = await _px4_truth_tap(connect_url) if server is None and sim.px4_ground_truth else None
    truth = _TruthSampler(server, link, world, clock, tap)
    camera = SimulatedCameraSource(
        settings_camera(settings, world),
        truth.world_from_body,
        clock,
        settings.camera.frame_rate_hz,
        sim.camera_latency_s,
    )
    detector = (
        None
        if sim.wire_masks == "cnn"
        else TruthWireDetector(WireDetector(segmenter), camera, sim.wire_masks)
    )
    for addon in addons:
        camera = addon.camera(camera, clock)
    process = FlightProcess(settings, link, camera, clock, segmenter, detector)
    stop = asyncio.Event()  # an addon may end the flight early
    truth.ground_allowed = lambda: process.mission.state not in AIRBORNE
    driver = asyncio.create_task(clock.run(), name="lockstep") if lockstep else None
    failure, completed = "", False
    try:
        await link.connect()
        await link.wait_healthy()
        process.adopt(await check_vehicle(process.settings, link))
        for addon in addons:  # after the vehicle check: a recording carries the adopted limits
            addon.attach(process, clock, stop)
        watchers = [asyncio.create_task(truth.run(), name="truth")]
        watchers += [asyncio.create_task(addon.run()) for addon in addons]
        if progress:
            watchers.append(asyncio.create_task(_report_progress(process, truth, clock)))
        try:
            flight = process.run(stop, until_done=True)
            completed = await wait_or_timeout(clock, flight, sim.timeout_s)
        finally:
            for watcher in watchers:
                watcher.cancel()
        if not completed:
            state = process.mission.state.value
            failure = f"mission not done after {sim.timeout_s:.0f} s (state {state})"
    except LinkError as e:
        failure = f"link: {e}"
    finally:
        with contextlib.suppress(Exception):
            await link.close()
        if driver is not None:
            driver.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await driver
        if tap is not None:
            tap.close()
        if server is not None:
            server.stop()
            if server.error is not None:
                failure = f"the simulated vehicle crashed: {server.error!r}"
    record = FlightRecord(
        world=world,
        times_s=np.array(truth.times_s),
        path_ned_m=np.array(truth.positions_ned_m).reshape(-1, 3),
        on_ground=np.array(truth.on_ground, dtype=bool),
        report=process.report,
        link_events=list(link.events),
        completed=completed,
        failure=failure,
        wall_s=time.monotonic() - started,
        compute_s=clock.compute_s if isinstance(clock, LockstepClock) else math.nan,
        truth_source=(
            "simulator"
            if server is not None
            else "autopilot estimate"
            if tap is None
            else "PX4 ground truth (live)"
        ),
    )
    for addon in addons:
        record.extra.update(addon.close(record))
    return record


async def _px4_truth_tap(connect_url: str) -> Px4TruthTap | None:
    """PX4 SITL's live ground truth for the autopilot at `connect_url`, or None (with a
    warning) when none streams: then the cameras render from, and the judge samples, its
    estimate."""
    port = sih_truth_port(connect_url)
    if port is None:
        return None
    tap = Px4TruthTap(port)
    if await asyncio.to_thread(tap.wait, TRUTH_WAIT_S):
        return tap
    tap.close()
    log.warning(
        "no ground truth from PX4 SITL on UDP %d in %.0f s: the cameras render from its estimate",
        port,
        TRUTH_WAIT_S,
    )
    return None


async def _report_progress(process: FlightProcess, truth: _TruthSampler, clock: Clock) -> None:
    """One line on stderr per simulated second: time, mission state, position, goal."""
    while True:
        await clock.sleep(1.0)
        if not truth.positions_ned_m:
            continue
        n, e, d = truth.positions_ned_m[-1]
        mission = process.mission
        goal = f"goal {mission.goal_index + 1}/{len(mission.goals_ned_m)}"
        print(
            f"t={clock.now_s():6.1f}s {mission.state.value:<9} {goal}  ned=({n:6.1f},{e:6.1f},"
            f"{d:6.1f}) m  frames {process.report.frames}",
            file=sys.stderr,
            flush=True,
        )


class _TruthSampler:
    """The vehicle's pose in the world frame: the simulator's truth, or (external autopilot)
    PX4 SITL's live ground truth (`tap`), else its telemetry estimate; sampled at
    `TRUTH_RATE_HZ` for the judge."""

    def __init__(
        self,
        server: VehicleServer | None,
        link: VehicleLink,
        world: World,
        clock: Clock,
        tap: Px4TruthTap | None = None,
    ) -> None:
        self._server, self._link, self._clock, self._tap = server, link, clock, tap
        self._offset = np.asarray(world.start_ned_m, dtype=np.float64)
        self.times_s: list[float] = []
        self.positions_ned_m: list[np.ndarray] = []
        self.on_ground: list[bool] = []  # touching the ground is no collision (take-off, landing)
        self.ground_allowed: Callable[[], bool] = lambda: True

    def world_from_body(self) -> Pose | None:
        """The vehicle's body pose in the world frame now, or None when unknown."""
        if self._server is not None:
            state = self._server.truth()
            return Pose.from_quaternion(state.attitude_wxyz, state.position_ned_m + self._offset)
        if self._tap is not None:
            truth = self._tap.state()
            if truth is None:
                return None
            return Pose.from_quaternion(truth[0], truth[1] + self._offset)
        local = self._link.telemetry().world_from_body()
        if local is None:
            return None
        return Pose(local.rotation, local.translation_m + self._offset)

    async def run(self) -> None:
        while True:
            if self._server is not None:
                state = self._server.truth()
                self.times_s.append(state.time_s)
                self.positions_ned_m.append(state.position_ned_m + self._offset)
                self.on_ground.append(bool(state.on_ground) or self.ground_allowed())
            elif self._tap is not None:
                truth = self._tap.state()
                if truth is not None:
                    landed = self._link.telemetry().armed is False
                    self.times_s.append(self._clock.now_s())
                    self.positions_ned_m.append(truth[1] + self._offset)
                    self.on_ground.append(landed or self.ground_allowed())
            else:
                snap = self._link.telemetry()
                if snap.pose is not None:
                    self.times_s.append(snap.pose.stamp_s)
                    self.positions_ned_m.append(snap.pose.position_ned_m + self._offset)
                    self.on_ground.append(snap.armed is False or self.ground_allowed())
            await self._clock.sleep(1.0 / TRUTH_RATE_HZ)
