"""The parts of the flight process on their own: the bus, the clocks, the stage timings, the map
builder's registration of frames, and the pilot's hold and final approach."""

from __future__ import annotations

import asyncio
import math
import threading
import time

import numpy as np
import pytest

from companion.clock import WallClock, wait_or_timeout
from companion.flight.map_builder import MapBuilder
from companion.flight.perceive import Perception
from companion.flight.pilot import Pilot
from companion.flight.timing import StageTimes
from companion.topics import TOPICS, Bus
from geometry.pose import Pose
from hil.lockstep import LockstepClock
from hil.mavlink.server import VehicleServer
from hil.vehicle.params import VehicleSimParams
from mapping.catenary.params import CatenaryParams
from mapping.droan.params import MappingParams
from mapping.droan.pose_graph import InsertResult
from planning.params import PlanningParams
from planning.synthetic_occupancy import SyntheticOccupancyMap
from planning.types import PlannerState, SetpointKind, VehicleState


async def test_the_bus_hands_out_the_newest_message_and_counts_what_was_skipped() -> None:
    now = [0.0]
    bus = Bus(lambda: now[0])
    seen = []
    bus.subscribe(lambda stamped: seen.append((stamped.topic, stamped.seq)))
    for i in range(3):
        now[0] = float(i)
        bus.publish("camera", f"frame {i}")
    latest = await bus.newer("camera", 0)
    assert (latest.seq, latest.message, latest.stamp_s) == (3, "frame 2", 2.0)
    assert seen == [("camera", 1), ("camera", 2), ("camera", 3)]
    waiter = asyncio.ensure_future(bus.newer("camera", 3))
    await asyncio.sleep(0)
    assert not waiter.done()
    bus.publish("camera", "frame 3")
    assert (await waiter).message == "frame 3"
    now[0] = 5.5
    assert bus.age_s("camera") == pytest.approx(3.5) and bus.age_s("plan") == math.inf
    with pytest.raises(KeyError, match="unknown topic"):
        bus.publish("cmaera", None)
    assert {"camera", "perception", "map", "plan", "setpoint", "mission"} <= set(TOPICS)


def test_stage_times_report_percentiles_and_drops() -> None:
    times = StageTimes(window=100)
    for ms in range(1, 101):
        times.add("cnn", ms / 1e3)
    times.dropped_frames = 4
    summary = times.summary("cnn")
    assert summary.count == 100 and summary.p50_ms == pytest.approx(50.5)
    assert summary.p99_ms == pytest.approx(99.01) and summary.max_ms == 100.0
    report = times.to_dict()
    assert report["dropped_frames"] == 4 and report["map"]["p50_ms"] is None
    assert "cnn=50/99ms" in times.line()


async def test_the_wall_clock_runs_each_worker_on_one_thread_of_its_own() -> None:
    clock = WallClock()
    names = await asyncio.gather(
        *(clock.compute(w, lambda: threading.current_thread().name) for w in ("a", "b", "a"))
    )
    assert names[0] == names[2] and names[0] != names[1]
    assert not await wait_or_timeout(clock, asyncio.sleep(1.0), 0.01)
    assert await wait_or_timeout(clock, asyncio.sleep(0.0), 1.0)
    clock.close()


def test_the_lockstep_clock_stands_still_while_computing_then_charges_the_time() -> None:
    async def scenario() -> None:
        params = VehicleSimParams()
        with VehicleServer(params, _free_port(), lockstep=True) as server:
            clock = LockstepClock(server, max_speed=50.0)
            driver = asyncio.create_task(clock.run())
            order = []

            async def sleeper(name: str, seconds: float) -> None:
                await clock.sleep(seconds)
                order.append((name, clock.now_s()))

            t0 = clock.now_s()
            await asyncio.gather(sleeper("late", 0.2), sleeper("early", 0.1))
            assert [name for name, _ in order] == ["early", "late"]
            assert order[0][1] - t0 == pytest.approx(0.1, abs=0.005)
            during = []

            def work() -> str:
                during.append(clock.now_s())
                time.sleep(0.08)
                during.append(clock.now_s())
                return "done"

            start = clock.now_s()
            assert await clock.compute("cnn", work) == "done"
            assert during[0] == during[1] == start  # time stood still while computing
            assert clock.now_s() - start == pytest.approx(0.08, abs=0.03)  # then was charged
            assert server.time_s == pytest.approx(clock.now_s())
            driver.cancel()
            clock.close()

    asyncio.run(scenario())


def _free_port() -> int:
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_the_map_builder_registers_a_frame_at_its_interpolated_camera_pose() -> None:
    mapping = MappingParams(camera_width_px=320, camera_height_px=240, max_nodes=4)
    builder = MapBuilder(mapping, CatenaryParams())
    wire = np.zeros((120, 160), bool)  # the colour camera at half the stereo camera's size
    wire[40, 20:140] = True
    frame = Perception(1.05, 7, wire, None)
    assert builder.camera_pose_at(frame.stamp_s) is None  # no pose yet: not fused
    update = builder.insert(frame, None)
    assert update.result is None and len(builder.droan) == 0
    builder.add_pose(1.0, Pose.identity())
    builder.add_pose(1.1, Pose(np.eye(3), np.array([1.0, 0.0, -2.0])))
    pose = builder.camera_pose_at(frame.stamp_s)
    # half-way between the two vehicle poses, shifted by the camera mount (0.1 m forward)
    np.testing.assert_allclose(pose.translation_m, [0.6, 0.0, -1.0], atol=1e-9)
    update = builder.insert(frame, pose)
    assert update.result is InsertResult.KEYFRAME and update.nodes == 1
    assert builder.newest_frame_s == 1.05
    # the wire seen straight ahead, 4-20 m away (4.4.3), is in the map; the ground below is not
    ahead = pose.apply(np.array([[0.0, -0.55, 8.0]]))  # camera frame: x right, y down, z fwd
    assert builder.occupancy_map().query(ahead).occupancy[0] > 0
    # taken in the takeoff climb, a frame is fused without its wire evidence: stereo alone
    climb = MapBuilder(mapping, CatenaryParams())
    update = climb.insert(frame, pose, wire_evidence=False)  # nothing left to fuse
    assert update.result is None and not update.wire_evidence and len(climb.droan) == 0
    far = np.full((240, 320), 0.5, np.float32)  # the stereo sees everything 80+ m off
    update = climb.insert(Perception(1.05, 7, wire, far), pose, wire_evidence=False)
    assert update.result is InsertResult.KEYFRAME and not update.wire_evidence
    assert climb.newest_frame_s == 1.05  # fused: perception stays fresh
    assert climb.occupancy_map().query(ahead).occupancy[0] == 0
    climb.insert(Perception(1.15, 8, wire, far), pose)  # the same once airborne: the wire
    assert climb.occupancy_map().query(ahead).occupancy[0] > 0


def _state(position, velocity=(0.0, 0.0, 0.0), stamp_s=0.0) -> VehicleState:
    return VehicleState(stamp_s, np.asarray(position, float), np.asarray(velocity, float), 0.0)


def test_the_pilot_brakes_and_holds_when_told_and_approaches_a_near_goal_directly() -> None:
    pilot = Pilot(PlanningParams())
    world = SyntheticOccupancyMap(omniscient=True)
    goal = np.array([10.0, 0.0, -3.0])
    moving = _state([0.0, 0.0, -3.0], [2.0, 0.0, 0.0])
    held = pilot.plan(0.0, moving, world, goal, hold=True)
    assert held.state is PlannerState.BRAKING and held.reference.brake
    assert pilot.planner.goal_ned_m is not None  # the goal is kept through the hold
    flying = pilot.plan(0.1, moving, world, goal, hold=False)
    assert flying.state is PlannerState.TRACKING and flying.label != "approach"
    near = pilot.plan(0.2, _state([8.5, 0.0, -4.0], [1.0, 0.0, 0.0], 0.2), world, goal, False)
    assert near.state is PlannerState.TRACKING and near.label == "approach"
    np.testing.assert_allclose(near.reference.positions_ned_m[-1], goal)
    assert np.linalg.norm(near.reference.velocities_ned_mps[-1]) == 0.0
    again = pilot.plan(0.3, _state([8.6, 0.0, -4.0], [1.0, 0.0, 0.0], 0.3), world, goal, False)
    assert again.reference.plan_id == near.reference.plan_id  # the approach is kept, not redone
    setpoint = pilot.setpoint(0.3, _state([8.6, 0.0, -4.0], [1.0, 0.0, 0.0], 0.3), again)
    assert setpoint.kind is SetpointKind.TRAJECTORY and setpoint.valid
    invalid = pilot.setpoint(0.35, _state([8.6, 0.0, -4.0]), None)
    assert invalid.kind is SetpointKind.BRAKE and not invalid.valid


def test_the_approach_is_not_flown_through_an_obstacle_or_unseen_space() -> None:
    from geometry.shapes import Box

    goal = np.array([10.0, 0.0, -3.0])
    start = _state([8.0, 0.0, -3.0], [1.0, 0.0, 0.0])
    blocked = SyntheticOccupancyMap(
        boxes=[Box([8.9, -0.2, -3.2], [9.1, 0.2, -2.8])], inflation_m=0.1, omniscient=True
    )
    assert Pilot(PlanningParams()).plan(0.0, start, blocked, goal, False).label != "approach"
    unseen = SyntheticOccupancyMap()  # nothing observed
    assert Pilot(PlanningParams()).plan(0.0, start, unseen, goal, False).label != "approach"
    # a goal 0.57 m straight above, where the forward camera cannot look: the segment to the
    # arrival sphere (0.5 m) lies in the vehicle's own volume, so it is flown, not circled
    below = _state([10.0, 0.0, -2.43])
    up = Pilot(PlanningParams()).plan(0.0, below, unseen, goal, False)
    assert up.label == "approach"
    np.testing.assert_allclose(up.reference.positions_ned_m[-1], goal)
    far_below = _state([10.0, 0.0, -2.0])  # 1 m under: the checked 0.5 m leaves its own volume
    assert Pilot(PlanningParams()).plan(0.0, far_below, unseen, goal, False).label != "approach"


async def test_a_loop_of_timeouts_can_always_be_cancelled() -> None:
    clock = WallClock()

    async def poll() -> None:
        while True:  # like the stages: wait for news or time out, forever
            await wait_or_timeout(clock, asyncio.Event().wait(), 0.0)

    for trial in range(60):  # each cancel lands at another point of the wait or its cleanup
        task = asyncio.ensure_future(poll())
        for _ in range(trial % 7):
            await asyncio.sleep(0)
        task.cancel()
        done, _ = await asyncio.wait([task], timeout=1.0)
        assert done, "a cancellation was swallowed"


def test_the_map_builder_hands_out_each_catenary_refit_once_and_uses_the_finished_one() -> None:
    mapping = MappingParams(camera_width_px=320, camera_height_px=240, max_nodes=4)
    builder = MapBuilder(mapping, CatenaryParams(use_in_collision_check=True))
    wire = np.zeros((120, 160), bool)
    wire[40, 20:140] = True
    builder.add_pose(0.0, Pose.identity())
    builder.add_pose(1.0, Pose(np.eye(3), np.array([0.0, 0.0, -2.0])))
    for seq, stamp_s in enumerate((0.0, 1.0)):  # 2 m apart: both keyframes
        builder.insert(Perception(stamp_s, seq, wire, None), builder.camera_pose_at(stamp_s))
    refit = builder.take_catenary_refit()
    assert refit is not None and builder.take_catenary_refit() is None  # once
    assert builder.catenary is not None and builder.catenary.obstacles() == []  # not yet used
    fits = refit()  # where the flight process runs it: its "catenary" worker
    assert fits and all(f.stamp_s == 1.0 for f in fits)  # of the keyframes handed out
    builder.use_catenary_fits(fits)
    assert builder.catenary.fits() is fits  # used as it is: nothing owed, no refit here
