"""The fault matrix: each injector does what it says (camera, MAVLink relay, world file), and
a flight with every fault in turn never collides, brakes to a hold within 0.5 s of a stale
input or a stalled stage being detectable, and flies on once the fault clears."""

from __future__ import annotations

import json
import math
import socket
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink
from typer.testing import CliRunner

from companion.cli import app
from companion.cli.faults import FaultFlight, fence_around, fly_faults, matrix_summary
from companion.flight.pose_jump import pose_jump_m
from companion.ground.params import GeofenceParams
from companion.link.telemetry import LocalPosition
from hil.faults import FAULT_KINDS, FaultSchedule, FaultSpec, FaultyCamera, MavlinkRelay
from hil.world.file import WorldFileError, load_faults, load_world, world_from_toml

DATA = Path(__file__).parent / "data"
FIELD = Path(__file__).parents[1] / "hil" / "world" / "examples" / "fault-field.toml"


@dataclass(frozen=True)
class _Frame:
    stamp_s: float
    sequence: int
    pixels: str


def _camera(*specs: FaultSpec) -> tuple[FaultyCamera, FaultSchedule]:
    schedule = FaultSchedule(list(specs), lambda: 0.0)
    schedule.start(0.0)
    return FaultyCamera(None, None, schedule), schedule


def _delivered(camera: FaultyCamera) -> list[tuple[float, int, str]]:
    return sorted((due, item.sequence, item.pixels) for due, _, item in camera._due)


def _feed(camera: FaultyCamera, n: int) -> None:
    for i in range(n):  # frames delivered every 0.1 s from t = 0.05
        camera._route(_Frame(0.1 * i, i, f"p{i}"), 0.1 * i + 0.05)


def test_the_camera_faults_drop_freeze_delay_and_swap_frames() -> None:
    drop, log = _camera(FaultSpec(kind="camera_drop", start_s=0.3, duration_s=0.3))
    _feed(drop, 10)
    assert [s for _, s, _ in _delivered(drop)] == [0, 1, 2, 6, 7, 8, 9]
    assert log.logs[0].affected == 3 and log.logs[0].last_good_stamp_s == pytest.approx(0.2)

    freeze, _ = _camera(FaultSpec(kind="camera_freeze", start_s=0.3, duration_s=0.3))
    _feed(freeze, 8)
    # frames 3-5 carry frame 2's pixels under their own stamps and sequence numbers
    assert [(s, p) for _, s, p in _delivered(freeze)][2:7] == [
        (2, "p2"), (3, "p2"), (4, "p2"), (5, "p2"), (6, "p6"),
    ]  # fmt: skip

    delay, _ = _camera(FaultSpec(kind="camera_delay", start_s=0.3, duration_s=0.3, delay_s=0.8))
    _feed(delay, 10)
    due = {s: d for d, s, _ in _delivered(delay)}
    assert due[4] == pytest.approx(0.45 + 0.8) and due[7] == pytest.approx(0.75)

    swap, _ = _camera(FaultSpec(kind="camera_reorder", start_s=0.3, duration_s=0.4))
    _feed(swap, 9)
    order = [seq for _, _, seq in sorted((d, i, it.sequence) for d, i, it in swap._due)]
    assert order == [0, 1, 2, 4, 3, 6, 5, 7, 8]


def _mavlink_bytes(message: object, system: int, component: int) -> bytes:
    return message.pack(mavlink.MAVLink(None, system, component))


def test_the_relay_loses_the_link_and_shifts_the_local_frame() -> None:
    now = [0.0]
    schedule = FaultSchedule(
        [
            FaultSpec(kind="link_loss", start_s=1.0, duration_s=1.0),
            FaultSpec(kind="pose_jump", start_s=3.0, jump_ned_m=(2.0, -1.0, 0.5)),
        ],
        lambda: now[0],
    )
    schedule.start(0.0)
    companion = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    companion.bind(("127.0.0.1", 0))
    companion.settimeout(0.5)
    relay = MavlinkRelay(companion.getsockname()[1], schedule).start()
    vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    vehicle.bind(("127.0.0.1", 0))
    vehicle.settimeout(0.5)
    position = mavlink.MAVLink_local_position_ned_message(1000, 5.0, 1.0, -3.0, 1.0, 0.0, 0.0)
    target = mavlink.MAVLink_set_position_target_local_ned_message(
        0, 1, 1, 1, 0b110111111000, 5.0, 1.0, -3.0, 0, 0, 0, 0, 0, 0, 0, 0
    )

    def up_and_down() -> tuple[object | None, object | None]:
        vehicle.sendto(_mavlink_bytes(position, 1, 1), ("127.0.0.1", relay.port))
        try:
            data, address = companion.recvfrom(4096)
        except TimeoutError:
            return None, None
        up = mavlink.MAVLink(None).parse_buffer(data)[0]
        companion.sendto(_mavlink_bytes(target, 255, 191), address)
        try:
            down = mavlink.MAVLink(None).parse_buffer(vehicle.recvfrom(4096)[0])[0]
        except TimeoutError:
            down = None
        return up, down

    try:
        up, down = up_and_down()
        assert (up.x, up.y, up.z) == pytest.approx((5.0, 1.0, -3.0)) and down.x == 5.0
        now[0] = 1.5  # the link is lost: nothing passes
        assert up_and_down() == (None, None) and relay.dropped >= 1
        now[0] = 3.5  # after the jump: the vehicle's frame moved by (2, -1, 0.5)
        up, down = up_and_down()
        assert (up.x, up.y, up.z) == pytest.approx((7.0, 0.0, -2.5))
        assert (down.x, down.y, down.z) == pytest.approx((3.0, 2.0, -3.5))
    finally:
        relay.stop()
        companion.close()
        vehicle.close()
    assert schedule.logs[0].affected >= 1 and schedule.logs[1].affected >= 1


def test_a_pose_jump_is_told_from_flying_fast() -> None:
    previous = LocalPosition(np.array([0.0, 0.0, -3.0]), np.array([2.0, 0.0, 0.0]), 10.0)
    flown = LocalPosition(np.array([0.066, 0.0, -3.0]), np.array([2.0, 0.0, 0.0]), 10.033)
    assert pose_jump_m(previous, flown, 0.5) < 0.01  # 2 m/s is no jump
    jumped = LocalPosition(np.array([3.066, 0.0, -3.0]), np.array([2.0, 0.0, 0.0]), 10.033)
    assert pose_jump_m(previous, jumped, 0.5) == pytest.approx(3.0)
    late = LocalPosition(np.array([9.0, 0.0, -3.0]), np.zeros(3), 12.0)
    assert pose_jump_m(previous, late, 0.5) == 0.0 and pose_jump_m(None, late, 0.5) == 0.0


def test_world_files_carry_faults(tmp_path: Path) -> None:
    world = tmp_path / "w.toml"
    world.write_text(
        "[[goal]]\nposition_ned_m = [10.0, 0.0, -3.0]\n\n"
        '[[fault]]\nkind = "camera_drop"\nstart_s = 2.0\nduration_s = 1.5\n\n'
        '[[fault]]\nkind = "pose_jump"\njump_ned_m = [0.0, 2.0, 0.0]\n'
    )
    faults = load_faults(world)
    assert [(f.kind, f.start_s, f.duration_s) for f in faults] == [
        ("camera_drop", 2.0, 1.5), ("pose_jump", 3.0, 2.0),
    ]  # fmt: skip
    assert faults[1].jump_ned_m == (0.0, 2.0, 0.0)
    with pytest.raises(WorldFileError, match=r"w\.toml:2: fault\[0\]\.kind"):
        world_from_toml('[[fault]]\nkind = "camera_dorp"\n', str(world))
    assert load_faults(FIELD) == []


def test_the_faults_command_lists_every_fault_and_refuses_unknown_ones() -> None:
    listed = CliRunner().invoke(app, ["faults", "--list"])
    assert listed.exit_code == 0
    assert [line.split()[0] for line in listed.output.splitlines()] == list(FAULT_KINDS)
    assert CliRunner().invoke(app, ["faults", "--only", "camera_dorp"]).exit_code != 0
    assert CliRunner().invoke(app, ["sim", "--fault", "camera_dorp"]).exit_code != 0


def test_the_matrix_widens_a_cylinder_fence_to_take_in_the_world_s_goals() -> None:
    field = load_world(FIELD)  # its goal 220 m north: past the default 100 m cylinder
    assert fence_around(GeofenceParams(), field).radius_m == pytest.approx(220.0 + 20.0)
    wide = GeofenceParams(radius_m=500.0)
    assert fence_around(wide, field) is wide
    polygon = GeofenceParams(shape="polygon", polygon_ned_m=[(0, -5), (50, -5), (50, 5)])
    assert fence_around(polygon, field) is polygon


MATRIX = list(FAULT_KINDS)  # mqtt_restart: the flight runs the ground link's broker itself
FLYING_AGAIN = {"navigate", "avoid", "recovery", "landing", "landed"}  # mission states


@pytest.mark.slow
def test_every_fault_in_turn_is_survived_and_handled_in_time() -> None:
    """One flight of the fault field with the small camera: each fault 2 s long, 10 s apart
    (8 s to fly on: a recovery the fault left the planner in, a rotation or a rewind, takes
    up to 6 s before the vehicle moves on)."""
    started = time.monotonic()
    faults = tuple(
        {"kind": kind, "start_s": 3.0 + 10.0 * i, "duration_s": 2.0}
        for i, kind in enumerate(MATRIX)
    )
    rows = fly_faults(FaultFlight(faults, str(FIELD), str(DATA / "tiny-camera.toml"), 5.0))
    print(json.dumps(rows, indent=1))  # the matrix, for the log of a failure
    summary = matrix_summary(rows, time.monotonic() - started, [])
    by_name = {r["name"]: r for r in summary["faults"]}
    assert list(by_name) == MATRIX
    for name, row in by_name.items():
        assert row["injected"] and row["affected_inputs"] > 0, row
        # no fault leaves the mission held, failed safe or lost: it flies again once it clears
        assert row["collisions"] == 0 and row["state_after"] in FLYING_AGAIN, row
        if name != "cpu_hog":  # a hog the stages keep up with needs no reaction
            assert row["detected_after_s"] is not None, row  # the process noticed the fault ...
        if row["hold_required"]:  # ... and braked to a hold in time where inputs went stale
            assert row["stopped_after_s"] is not None and row["stopped_after_s"] <= 0.5, row
    assert by_name["camera_freeze"]["detected_after_s"] < 0.2  # the repeated pixels at once
    assert by_name["pose_jump"]["detected_after_s"] < 0.1
    broker = by_name["mqtt_restart"]  # the ground link back at its backoff's next attempt
    assert not broker["interrupted"] and broker["reconnected_after_s"] < 2.5, broker
    assert broker["status_resumed_after_s"] < broker["reconnected_after_s"] + 0.6, broker
    # ... and moves on (> 0.5 m before the next fault) after at least 9 of the 10: all 10 in
    # each of 7 local flights of the hazy field, 2 of them with computation charged twice
    # over (`sim.compute_scale = 2`), 0.55-15 m moved (on the clear field, whose tree line the
    # small camera reads as a wire, CI saw 8; without the takeoff climb's wire masks 10 in 2 of
    # 2, but 0.6-1.3 m in some windows)
    moved_on = [r["name"] for r in summary["faults"] if r["recovered"]]
    assert len(moved_on) >= len(MATRIX) - 1, summary["faults"]
    assert summary["collisions"] == 0
    assert not math.isnan(summary["wall_s"])


@pytest.mark.parametrize(
    ("action", "state"),
    [("hold", "hold"), ("resume", "navigate"), ("land", "landing")],
)
def test_a_vehicle_link_that_comes_back_holds_resumes_or_lands(action: str, state: str) -> None:
    from companion.mission import (
        Mission,
        MissionParams,
        MissionState,
        Operation,
        OperationResult,
        StageHealth,
        VehicleStatus,
    )
    from planning.types import PlannerState

    mission = Mission(
        MissionParams(auto_start=True, goals_ned_m=[(20.0, 0.0, -3.0)],
                      vehicle_link_back_action=action)
    )  # fmt: skip
    fresh = StageHealth(perception_fresh=True, planner_fresh=True)

    def step(link_ok: bool = True, offboard: bool = True, result: OperationResult | None = None):
        vehicle = VehicleStatus(link_ok, True, True, offboard, np.zeros(3))
        return mission.step(0.0, vehicle, fresh, PlannerState.TRACKING, result)

    decision = step(offboard=False)
    for operation in (Operation.ARM, Operation.TAKEOFF, Operation.OFFBOARD):
        assert decision.operation is operation
        decision = step(
            offboard=operation is Operation.OFFBOARD, result=OperationResult(operation, True)
        )
    assert decision.state is MissionState.NAVIGATE
    assert step(link_ok=False).state is MissionState.FAILSAFE
    decision = step()
    assert decision.state.value == state and decision.hold is (action == "hold")
