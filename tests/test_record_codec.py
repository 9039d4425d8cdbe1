"""The recording's messages: every bus message survives JSON exactly, disparity bit for bit,
and each channel carries a JSON Schema under the name Foxglove knows."""

from __future__ import annotations

import json
import math

import numpy as np

from companion.flight.map_builder import MapUpdate
from companion.flight.perceive import Perception
from companion.flight.process import PlanUpdate
from companion.ingest.frames import CameraFrame
from companion.link.telemetry import (
    Attitude,
    Battery,
    FlightMode,
    LandedState,
    LocalPosition,
    TelemetrySnapshot,
)
from companion.mission import MissionEvent, MissionState
from companion.record import codec
from geometry.pose import Pose
from mapping.droan.pose_graph import InsertResult
from planning.types import (
    PlannerOutput,
    PlannerState,
    Reference,
    Setpoint,
    SetpointKind,
    VehicleState,
)


def _roundtrip(encoded: list[codec.Encoded]) -> list[dict]:
    return [json.loads(e.data()) for e in encoded]


def test_disparity_is_stored_bit_for_bit_with_nan_and_zero() -> None:
    rng = np.random.default_rng(1)
    d = (rng.normal(20.0, 5.0, (48, 64))).astype(np.float32)
    d[:5] = np.nan
    d[10:12] = 0.0
    back = codec.disparity_from_bytes(codec.disparity_bytes(d), 48, 64)
    assert back.dtype == np.float32
    np.testing.assert_array_equal(back.view(np.uint32), d.view(np.uint32))


def test_a_camera_frame_and_its_mask_come_back_exactly() -> None:
    rng = np.random.default_rng(2)
    image = rng.integers(0, 256, (24, 32, 3), dtype=np.uint8)
    disparity = rng.uniform(0, 30, (48, 64)).astype(np.float32)
    frame = CameraFrame(12.345678901234, 77, image, disparity)
    image_msg, disparity_msg, preview = _roundtrip(codec.encode_camera(frame, 12.4, 32.0))
    assert preview["format"] == "jpeg" and codec.image_from_json(preview).shape == (24, 32, 3)
    back = codec.decode_camera(image_msg, disparity_msg)
    assert (back.stamp_s, back.sequence) == (frame.stamp_s, 77)
    np.testing.assert_array_equal(back.image_bgr, image)
    np.testing.assert_array_equal(back.disparity_px, disparity)
    mask = rng.random((24, 32)) > 0.8
    (mask_msg,) = _roundtrip(codec.encode_perception(Perception(1.5, 77, mask, disparity), 1.6))
    assert mask_msg["wire_pixels"] == int(mask.sum())
    decoded = codec.decode_perception(mask_msg, None)
    np.testing.assert_array_equal(decoded.wire_mask, mask)
    np.testing.assert_array_equal(decoded.possible_mask, mask)  # none given: the wire mask
    possible = mask | (rng.random((24, 32)) > 0.5)
    (both,) = _roundtrip(codec.encode_perception(Perception(1.5, 77, mask, None, possible), 1.6))
    decoded = codec.decode_perception(both, None)
    np.testing.assert_array_equal(decoded.wire_mask, mask)
    np.testing.assert_array_equal(decoded.possible_mask, possible)
    (empty,) = _roundtrip(codec.encode_perception(Perception(1.5, 78, None, disparity), 1.6))
    assert codec.decode_perception(empty, None).wire_mask is None


def test_telemetry_map_plan_setpoint_and_mission_messages_come_back_exactly() -> None:
    snap = TelemetrySnapshot(
        stamp_s=3.25,
        last_update_s=3.2,
        pose=LocalPosition(np.array([1.0, -2.0, -3.3]), np.array([0.1, 0.2, -0.05]), 3.1),
        attitude=Attitude(0.01, -0.02, 1.2345, 3.15),
        flight_mode=FlightMode.OFFBOARD,
        armed=True,
        landed_state=LandedState.IN_AIR,
        battery=Battery(15.9, math.nan, 3.0),
    )
    back = codec.decode_vehicle(_roundtrip(codec.encode_vehicle(snap, 3.3))[0])
    world_from_body = snap.world_from_body()
    assert world_from_body is not None and back.world_from_body() is not None
    np.testing.assert_array_equal(back.world_from_body().rotation, world_from_body.rotation)
    assert back.pose.stamp_s == 3.1 and back.flight_mode is FlightMode.OFFBOARD
    assert back.armed is True and math.isnan(back.battery.remaining_frac)

    pose = Pose.from_yaw_pitch_roll(0.3, -0.1, 0.05, np.array([4.0, 1.0, -2.0]))
    update = MapUpdate(5.5, 9, pose, InsertResult.KEYFRAME, 3, 1)
    back_map = codec.decode_map(_roundtrip(codec.encode_map(update, 5.6))[0])
    np.testing.assert_array_equal(back_map.world_from_camera.rotation, pose.rotation)
    assert (back_map.result, back_map.nodes, back_map.wires) == (InsertResult.KEYFRAME, 3, 1)
    assert back_map.wire_evidence
    climb = MapUpdate(5.5, 9, pose, InsertResult.KEYFRAME, 3, 0, wire_evidence=False)
    assert not codec.decode_map(_roundtrip(codec.encode_map(climb, 5.6))[0]).wire_evidence
    unregistered = codec.decode_map(
        _roundtrip(codec.encode_map(MapUpdate(5.7, 10, None, None, 3, 0), 5.8))[0]
    )
    assert unregistered.world_from_camera is None and unregistered.result is None

    reference = Reference(
        6.0, np.array([0.0, 0.5]), np.array([[1, 2, 3], [1.5, 2, 3]], float),
        np.array([[1, 0, 0], [1, 0, 0]], float), 42, None, 0.7, True,
    )  # fmt: skip
    output = PlannerOutput(6.0, PlannerState.BRAKING, reference, "stop", math.nan, 7.5, 3, 2, 90)
    vehicle = VehicleState(5.99, np.array([1.0, 2.0, 3.0]), np.zeros(3), 0.25)
    plan = PlanUpdate(output, vehicle, -math.inf, 0, np.array([20.0, 0, -3]), True, None,
                      np.array([0.5, 0.0, 0.0]))  # fmt: skip
    plan_msg, path_msg = _roundtrip(codec.encode_plan(plan, 6.05))
    assert len(path_msg["poses"]) == 2
    back_plan = codec.decode_plan(plan_msg)
    assert back_plan.frame_stamp_s == -math.inf and back_plan.hold and back_plan.speed_mps is None
    assert math.isnan(back_plan.output.cost) and back_plan.output.reference.yaw_target_rad == 0.7
    assert back_plan.output.reference.yaw_rate_radps is None
    np.testing.assert_array_equal(
        back_plan.output.reference.positions_ned_m, [[1, 2, 3], [1.5, 2, 3]]
    )

    setpoint = Setpoint(6.1, SetpointKind.BRAKE, np.zeros(3), None, math.nan, 0.0, False)
    back_sp = codec.decode_setpoint(_roundtrip(codec.encode_setpoint(setpoint, 6.1))[0])
    assert back_sp.kind is SetpointKind.BRAKE and not back_sp.valid and math.isnan(back_sp.yaw_rad)
    event = MissionEvent(7.0, MissionState.FAILSAFE, "perception stale: brake and hold", True)
    (log_msg,) = _roundtrip(codec.encode_mission(event, 7.0))
    assert log_msg["level"] == 3 and codec.decode_mission(log_msg) == event


def test_every_channel_has_a_json_schema_named_like_its_messages() -> None:
    for topic, channel in codec.CHANNELS.items():
        assert topic.startswith("/") and channel.schema["title"] == channel.schema_name
        assert channel.schema["type"] == "object" and channel.schema["properties"]
    images = [c for c in codec.CHANNELS.values() if c.schema_name == "foxglove.CompressedImage"]
    assert {c.topic for c in images} >= {"/camera/image", "/perception/wire_mask"}
    assert codec.CHANNELS["/camera/image"].schema["properties"]["data"]["contentEncoding"] == (
        "base64"
    )
