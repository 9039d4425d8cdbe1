"""The recording's messages: each bus topic as MCAP channels of JSON with a JSON Schema each.

Every message of the flight process' bus (`companion.topics`) becomes one or more JSON
messages on named channels, each with its own JSON Schema, so Foxglove opens a recording as it
is: the colour image, the wire mask and a disparity preview show in its image panel
(`foxglove.CompressedImage`), the vehicle and camera poses and the planned path in its 3D
panel (`foxglove.PoseInFrame`, `foxglove.PosesInFrame`, frame `local_ned` under a z-up
`world`), mission events in its log panel (`foxglove.Log`). Foxglove's schemas are extended
with the fields the replay needs; binary data is base64 (Foxglove's JSON rule).

Lossless where the replay re-runs a stage: colour images and masks are PNG, the disparity is
float32 byte-shuffled and zstd-compressed (`wireavoid.Disparity`), floats are written with
Python's shortest round-trip repr. Non-finite floats are null (JSON has none): NaN when read
back, except the stamps that mean "never" (-inf). `decode` turns the JSON back into the
product's own types (`CameraFrame`'s parts, `Perception`, `TelemetrySnapshot`, `MapUpdate`,
`PlanUpdate`, `Setpoint`, `MissionEvent`).
"""

from __future__ import annotations

import base64
import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
import zstandard

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
from geometry.pose import Pose
from geometry.rotation import quaternion_from_rotation
from mapping.droan.pose_graph import InsertResult
from planning.types import (
    PlannerOutput,
    PlannerState,
    Reference,
    Setpoint,
    SetpointKind,
    VehicleState,
)

FRAME_ID = "local_ned"  # the vehicle's local NED frame, m
WORLD_FRAME_ID = "world"  # z-up parent for Foxglove's 3D panel: x north, y west, z up
CAMERA_FRAME_ID = "camera"
DISPARITY_ENCODING = "32FC1-shuffle-zstd"


@dataclass(frozen=True, slots=True)
class Channel:
    """An MCAP channel: its topic, the bus topic it records, its schema's name and JSON Schema."""

    topic: str
    bus_topic: str
    schema_name: str
    schema: dict[str, Any]


@dataclass(frozen=True, slots=True)
class Encoded:
    """One JSON message for `channel` at `stamp_s` (the bus' publication time, s)."""

    channel: str
    stamp_s: float
    payload: dict[str, Any]

    def data(self) -> bytes:
        """The UTF-8 JSON (NaN and inf already replaced by null)."""
        return json.dumps(self.payload, separators=(",", ":"), allow_nan=False).encode()


# ---------------------------------------------------------------------------- JSON Schemas


def _schema(title: str, properties: dict[str, Any], description: str) -> dict[str, Any]:
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": title,
        "description": description,
        "type": "object",
        "properties": properties,
    }


_NUM = {"type": ["number", "null"], "description": "null: not finite"}
_INT = {"type": "integer"}
_STR = {"type": "string"}
_BOOL = {"type": "boolean"}
_BYTES = {"type": "string", "contentEncoding": "base64"}
_VEC3 = {"type": "array", "items": _NUM, "minItems": 3, "maxItems": 3}
_NUMS = {"type": "array", "items": _NUM}
_TIME = {
    "type": "object",
    "properties": {"sec": _INT, "nsec": _INT},
    "description": "the sample time (exposure, arrival): seconds of the process clock",
}
_VECTOR3 = {"type": "object", "properties": {"x": _NUM, "y": _NUM, "z": _NUM}}
_QUATERNION = {"type": "object", "properties": {"x": _NUM, "y": _NUM, "z": _NUM, "w": _NUM}}
_POSE = {"type": "object", "properties": {"position": _VECTOR3, "orientation": _QUATERNION}}
_MATRIX = {
    "type": ["array", "null"],
    "items": _NUM,
    "minItems": 12,
    "maxItems": 12,
    "description": "row-major 3x3 rotation then translation (m) of the pose, exact",
}
_IMAGE = {
    "timestamp": _TIME,
    "frame_id": _STR,
    "data": _BYTES,
    "format": {"type": "string", "description": "png or jpeg"},
    "stamp_s": _NUM,
    "sequence": _INT,
}
_REFERENCE = {
    "type": "object",
    "properties": {
        "start_s": _NUM,
        "times_s": _NUMS,
        "positions_ned_m": {"type": "array", "items": _VEC3},
        "velocities_ned_mps": {"type": "array", "items": _VEC3},
        "plan_id": _INT,
        "yaw_rate_radps": _NUM,
        "yaw_target_rad": _NUM,
        "brake": _BOOL,
    },
}
_VEHICLE_STATE = {
    "type": "object",
    "properties": {
        "stamp_s": _NUM,
        "position_ned_m": _VEC3,
        "velocity_ned_mps": _VEC3,
        "yaw_rad": _NUM,
    },
}

CHANNELS: dict[str, Channel] = {
    c.topic: c
    for c in (
        Channel(
            "/camera/image",
            "camera",
            "foxglove.CompressedImage",
            _schema("foxglove.CompressedImage", _IMAGE, "colour image (PNG, lossless), BGR"),
        ),
        Channel(
            "/camera/disparity",
            "camera",
            "wireavoid.Disparity",
            _schema(
                "wireavoid.Disparity",
                {
                    **_IMAGE,
                    "width": _INT,
                    "height": _INT,
                    "encoding": {"type": "string", "description": DISPARITY_ENCODING},
                },
                "disparity of the reference camera, px (NaN invalid, 0 no return): float32, "
                "little-endian, bytes shuffled by significance, zstd",
            ),
        ),
        Channel(
            "/camera/disparity_preview",
            "camera",
            "foxglove.CompressedImage",
            _schema("foxglove.CompressedImage", _IMAGE, "disparity, colour-mapped JPEG (view)"),
        ),
        Channel(
            "/perception/wire_mask",
            "perception",
            "foxglove.CompressedImage",
            _schema(
                "foxglove.CompressedImage",
                {**_IMAGE, "has_mask": _BOOL, "wire_pixels": _INT},
                "the CNN's wire mask (thesis 4.4.1) on the colour image's pixels, PNG: 255 wire, "
                "128 not ruled out (probability >= perception.no_wire_below), 0 no wire",
            ),
        ),
        Channel(
            "/vehicle",
            "vehicle",
            "foxglove.PoseInFrame",
            _schema(
                "foxglove.PoseInFrame",
                {
                    "timestamp": _TIME,
                    "frame_id": _STR,
                    "pose": _POSE,
                    "stamp_s": _NUM,
                    "last_update_s": _NUM,
                    "position_ned_m": _VEC3,
                    "velocity_ned_mps": _VEC3,
                    "pose_stamp_s": _NUM,
                    "roll_pitch_yaw_rad": _VEC3,
                    "attitude_stamp_s": _NUM,
                    "flight_mode": _STR,
                    "armed": {"type": ["boolean", "null"]},
                    "landed_state": _STR,
                    "battery_voltage_v": _NUM,
                    "battery_remaining_frac": _NUM,
                },
                "telemetry: body FRD in local NED, velocity NED m/s, mode, armed, battery",
            ),
        ),
        Channel(
            "/map",
            "map",
            "foxglove.PoseInFrame",
            _schema(
                "foxglove.PoseInFrame",
                {
                    "timestamp": _TIME,
                    "frame_id": _STR,
                    "pose": _POSE,
                    "stamp_s": _NUM,
                    "sequence": _INT,
                    "world_from_camera": _MATRIX,
                    "result": {"type": ["string", "null"], "description": "null: not fused"},
                    "nodes": _INT,
                    "wires": _INT,
                    "wire_evidence": {
                        **_BOOL,
                        "description": "the frame's wire mask was fused (else its stereo only)",
                    },
                },
                "a frame fused into DROAN (4.4.6): the camera pose it was registered at",
            ),
        ),
        Channel(
            "/plan",
            "plan",
            "wireavoid.Plan",
            _schema(
                "wireavoid.Plan",
                {
                    "timestamp": _TIME,
                    "stamp_s": _NUM,
                    "state": _STR,
                    "label": _STR,
                    "cost": _NUM,
                    "distance_to_goal_m": _NUM,
                    "checked": _INT,
                    "queries": _INT,
                    "points": _INT,
                    "reference": _REFERENCE,
                    "vehicle": _VEHICLE_STATE,
                    "frame_stamp_s": _NUM,
                    "goal_index": _INT,
                    "goal_ned_m": {"type": ["array", "null"], "items": _NUM},
                    "hold": _BOOL,
                    "speed_mps": _NUM,
                    "commanded_velocity_ned_mps": _VEC3,
                },
                "one planning cycle (4.5): the chosen trajectory, why (label, cost eq. 4.8, "
                "state), and every input the replay needs",
            ),
        ),
        Channel(
            "/plan/path",
            "plan",
            "foxglove.PosesInFrame",
            _schema(
                "foxglove.PosesInFrame",
                {
                    "timestamp": _TIME,
                    "frame_id": _STR,
                    "poses": {"type": "array", "items": _POSE},
                },
                "the chosen trajectory's waypoints, local NED (for the 3D panel)",
            ),
        ),
        Channel(
            "/setpoint",
            "setpoint",
            "wireavoid.Setpoint",
            _schema(
                "wireavoid.Setpoint",
                {
                    "timestamp": _TIME,
                    "stamp_s": _NUM,
                    "kind": _STR,
                    "velocity_ned_mps": _VEC3,
                    "position_ned_m": {"type": ["array", "null"], "items": _NUM},
                    "acceleration_ned_mps2": {"type": ["array", "null"], "items": _NUM},
                    "yaw_rad": _NUM,
                    "yaw_rate_radps": _NUM,
                    "valid": _BOOL,
                },
                "a setpoint handed to the link (planning.types.Setpoint), local NED",
            ),
        ),
        Channel(
            "/mission",
            "mission",
            "foxglove.Log",
            _schema(
                "foxglove.Log",
                {
                    "timestamp": _TIME,
                    "level": {"type": "integer", "description": "2 info, 3 warning"},
                    "message": _STR,
                    "name": _STR,
                    "file": _STR,
                    "line": _INT,
                    "stamp_s": _NUM,
                    "state": _STR,
                    "warning": _BOOL,
                },
                "mission transitions, failsafes and warnings",
            ),
        ),
        Channel(
            "/timing",
            "timing",
            "wireavoid.StageTimes",
            _schema(
                "wireavoid.StageTimes",
                {"timestamp": _TIME, "stages": {"type": "object"}},
                "p50/p99/max latency of each stage, ms, dropped frames, planning overruns",
            ),
        ),
        Channel(
            "/tf",
            "static",
            "foxglove.FrameTransform",
            _schema(
                "foxglove.FrameTransform",
                {
                    "timestamp": _TIME,
                    "parent_frame_id": _STR,
                    "child_frame_id": _STR,
                    "translation": _VECTOR3,
                    "rotation": _QUATERNION,
                },
                "local NED under a z-up world (a half turn about north)",
            ),
        ),
    )
}


# ---------------------------------------------------------------------------- encoding


def _num(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


def _nums(values: np.ndarray) -> list[float | None]:
    return [_num(float(v)) for v in np.asarray(values, dtype=np.float64).reshape(-1)]


def stamp_ns(stamp_s: float) -> int:
    """A process-clock time as MCAP's and Foxglove's nanoseconds (0 for non-finite or < 0)."""
    return max(round(stamp_s * 1e9), 0) if math.isfinite(stamp_s) else 0


def foxglove_time(stamp_s: float) -> dict[str, int]:
    """A process-clock time as Foxglove's `{sec, nsec}`."""
    ns = stamp_ns(stamp_s)
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def _b64(data: bytes) -> str:
    return base64.b64encode(data).decode("ascii")


def _png(image: np.ndarray) -> bytes:
    ok, buffer = cv2.imencode(".png", image)
    if not ok:
        raise ValueError(f"cannot PNG-encode an image of shape {image.shape}")
    return buffer.tobytes()


def _pose_json(pose: Pose) -> dict[str, Any]:
    w, x, y, z = quaternion_from_rotation(pose.rotation)
    px, py, pz = (float(v) for v in pose.translation_m)
    return {
        "position": {"x": px, "y": py, "z": pz},
        "orientation": {"x": float(x), "y": float(y), "z": float(z), "w": float(w)},
    }


def _matrix(pose: Pose | None) -> list[float | None] | None:
    if pose is None:
        return None
    return _nums(np.concatenate([pose.rotation.reshape(-1), pose.translation_m]))


def disparity_bytes(disparity_px: np.ndarray) -> bytes:
    """`(H, W) float32` disparity -> little-endian float32 bytes shuffled by significance
    (all first bytes, then all second, ...), zstd-compressed: lossless, ~20 % smaller than
    zstd alone on noisy stereo."""
    raw = np.ascontiguousarray(disparity_px, dtype="<f4").view(np.uint8).reshape(-1, 4)
    return zstandard.ZstdCompressor(level=3).compress(np.ascontiguousarray(raw.T).tobytes())


def disparity_from_bytes(data: bytes, height_px: int, width_px: int) -> np.ndarray:
    """The inverse of `disparity_bytes`: `(height_px, width_px) float32`."""
    shuffled = np.frombuffer(zstandard.ZstdDecompressor().decompress(data), dtype=np.uint8)
    raw = np.ascontiguousarray(shuffled.reshape(4, -1).T)
    return raw.view("<f4").reshape(height_px, width_px).astype(np.float32)


def disparity_preview_jpeg(disparity_px: np.ndarray, max_disparity_px: float) -> bytes:
    """A colour-mapped, half-size JPEG of a disparity image (black: invalid or no return)."""
    d = np.nan_to_num(np.asarray(disparity_px, dtype=np.float32), nan=0.0)[::2, ::2]
    grey = np.clip(d * (255.0 / max(max_disparity_px, 1e-6)), 0, 255).astype(np.uint8)
    colour = cv2.applyColorMap(grey, cv2.COLORMAP_TURBO)
    colour[grey == 0] = 0
    ok, buffer = cv2.imencode(".jpg", colour, [cv2.IMWRITE_JPEG_QUALITY, 80])
    return buffer.tobytes() if ok else b""


def _image_fields(stamp_s: float, sequence: int, frame_id: str) -> dict[str, Any]:
    return {
        "timestamp": foxglove_time(stamp_s),
        "frame_id": frame_id,
        "stamp_s": _num(stamp_s),
        "sequence": int(sequence),
    }


def encode_camera(
    frame: CameraFrame, stamp_s: float, preview_max_disparity_px: float | None
) -> list[Encoded]:
    """A camera frame: colour PNG, lossless disparity, and (when asked) a disparity preview."""
    out = []
    base = _image_fields(frame.stamp_s, frame.sequence, CAMERA_FRAME_ID)
    if frame.image_bgr is not None:
        data = _b64(_png(frame.image_bgr))
        out.append(Encoded("/camera/image", stamp_s, {**base, "data": data, "format": "png"}))
    if frame.disparity_px is not None:
        h, w = frame.disparity_px.shape
        out.append(
            Encoded(
                "/camera/disparity",
                stamp_s,
                {
                    **base,
                    "data": _b64(disparity_bytes(frame.disparity_px)),
                    "format": "raw",
                    "width": int(w),
                    "height": int(h),
                    "encoding": DISPARITY_ENCODING,
                },
            )
        )
        if preview_max_disparity_px is not None:
            jpeg = disparity_preview_jpeg(frame.disparity_px, preview_max_disparity_px)
            out.append(
                Encoded(
                    "/camera/disparity_preview",
                    stamp_s,
                    {**base, "data": _b64(jpeg), "format": "jpeg"},
                )
            )
    return out


def encode_perception(perception: Perception, stamp_s: float) -> list[Encoded]:
    """The wire mask as a PNG, 255 on wire pixels, 128 on the others of the possible mask,
    0 elsewhere (the disparity is the camera frame's)."""
    mask = perception.wire_mask
    payload = _image_fields(perception.stamp_s, perception.sequence, CAMERA_FRAME_ID)
    if mask is None:
        payload.update(data="", format="png", has_mask=False, wire_pixels=0)
    else:
        possible = mask if perception.possible_mask is None else perception.possible_mask
        image = np.where(mask, 255, np.where(possible, 128, 0)).astype(np.uint8)
        payload.update(
            data=_b64(_png(image)),
            format="png",
            has_mask=True,
            wire_pixels=int(np.count_nonzero(mask)),
        )
    return [Encoded("/perception/wire_mask", stamp_s, payload)]


def encode_vehicle(snap: TelemetrySnapshot, stamp_s: float) -> list[Encoded]:
    """A telemetry snapshot (the fields the process reads)."""
    payload: dict[str, Any] = {
        "timestamp": foxglove_time(snap.pose.stamp_s if snap.pose else snap.stamp_s),
        "frame_id": FRAME_ID,
        "stamp_s": _num(snap.stamp_s),
        "last_update_s": _num(snap.last_update_s),
        "flight_mode": snap.flight_mode.value,
        "armed": snap.armed,
        "landed_state": snap.landed_state.value,
        "battery_voltage_v": None if snap.battery is None else _num(snap.battery.voltage_v),
        "battery_remaining_frac": None
        if snap.battery is None
        else _num(snap.battery.remaining_frac),
    }
    if snap.pose is not None:
        payload.update(
            position_ned_m=_nums(snap.pose.position_ned_m),
            velocity_ned_mps=_nums(snap.pose.velocity_ned_mps),
            pose_stamp_s=_num(snap.pose.stamp_s),
        )
    if snap.attitude is not None:
        a = snap.attitude
        payload.update(
            roll_pitch_yaw_rad=_nums(np.array([a.roll_rad, a.pitch_rad, a.yaw_rad])),
            attitude_stamp_s=_num(a.stamp_s),
        )
    world_from_body = snap.world_from_body()
    if world_from_body is not None:
        payload["pose"] = _pose_json(world_from_body)
    return [Encoded("/vehicle", stamp_s, payload)]


def encode_map(update: MapUpdate, stamp_s: float) -> list[Encoded]:
    """A map update: the camera pose of the fused frame and what DROAN did with it."""
    payload: dict[str, Any] = {
        "timestamp": foxglove_time(update.stamp_s),
        "frame_id": FRAME_ID,
        "stamp_s": _num(update.stamp_s),
        "sequence": int(update.sequence),
        "world_from_camera": _matrix(update.world_from_camera),
        "result": None if update.result is None else update.result.value,
        "nodes": int(update.nodes),
        "wires": int(update.wires),
        "wire_evidence": bool(update.wire_evidence),
    }
    if update.world_from_camera is not None:
        payload["pose"] = _pose_json(update.world_from_camera)
    return [Encoded("/map", stamp_s, payload)]


def _reference_json(ref: Reference) -> dict[str, Any]:
    return {
        "start_s": _num(ref.start_s),
        "times_s": _nums(ref.times_s),
        "positions_ned_m": [_nums(p) for p in np.asarray(ref.positions_ned_m)],
        "velocities_ned_mps": [_nums(v) for v in np.asarray(ref.velocities_ned_mps)],
        "plan_id": int(ref.plan_id),
        "yaw_rate_radps": _num(ref.yaw_rate_radps),
        "yaw_target_rad": _num(ref.yaw_target_rad),
        "brake": bool(ref.brake),
    }


def vehicle_state_json(v: VehicleState) -> dict[str, Any]:
    """A `VehicleState` as JSON."""
    return {
        "stamp_s": _num(v.stamp_s),
        "position_ned_m": _nums(v.position_ned_m),
        "velocity_ned_mps": _nums(v.velocity_ned_mps),
        "yaw_rad": _num(v.yaw_rad),
    }


def plan_json(update: PlanUpdate) -> dict[str, Any]:
    """A planning cycle as the `/plan` message (without the timestamp)."""
    out = update.output
    return {
        "stamp_s": _num(out.stamp_s),
        "state": out.state.value,
        "label": out.label,
        "cost": _num(out.cost),
        "distance_to_goal_m": _num(out.distance_to_goal_m),
        "checked": int(out.checked),
        "queries": int(out.queries),
        "points": int(out.points),
        "reference": _reference_json(out.reference),
        "vehicle": vehicle_state_json(update.vehicle),
        "frame_stamp_s": _num(update.frame_stamp_s),
        "goal_index": int(update.goal_index),
        "goal_ned_m": None if update.goal_ned_m is None else _nums(update.goal_ned_m),
        "hold": bool(update.hold),
        "speed_mps": _num(update.speed_mps),
        "commanded_velocity_ned_mps": _nums(update.commanded_velocity_ned_mps),
    }


def encode_plan(update: PlanUpdate, stamp_s: float) -> list[Encoded]:
    """A planning cycle, and its chosen trajectory as poses for the 3D panel."""
    payload = {"timestamp": foxglove_time(update.output.stamp_s), **plan_json(update)}
    identity = {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}
    poses = [
        {"position": dict(zip("xyz", (float(c) for c in p), strict=True)), "orientation": identity}
        for p in np.asarray(update.output.reference.positions_ned_m)
    ]
    path = {"timestamp": foxglove_time(update.output.stamp_s), "frame_id": FRAME_ID, "poses": poses}
    return [Encoded("/plan", stamp_s, payload), Encoded("/plan/path", stamp_s, path)]


def encode_setpoint(setpoint: Setpoint, stamp_s: float) -> list[Encoded]:
    """A setpoint handed to the link."""
    payload = {
        "timestamp": foxglove_time(setpoint.stamp_s),
        "stamp_s": _num(setpoint.stamp_s),
        "kind": setpoint.kind.value,
        "velocity_ned_mps": _nums(setpoint.velocity_ned_mps),
        "position_ned_m": None
        if setpoint.position_ned_m is None
        else _nums(setpoint.position_ned_m),
        "acceleration_ned_mps2": None
        if setpoint.acceleration_ned_mps2 is None
        else _nums(setpoint.acceleration_ned_mps2),
        "yaw_rad": _num(setpoint.yaw_rad),
        "yaw_rate_radps": _num(setpoint.yaw_rate_radps),
        "valid": bool(setpoint.valid),
    }
    return [Encoded("/setpoint", stamp_s, payload)]


def encode_mission(event: MissionEvent, stamp_s: float) -> list[Encoded]:
    """A mission event as a Foxglove log line."""
    payload = {
        "timestamp": foxglove_time(event.stamp_s),
        "level": 3 if event.warning else 2,
        "message": event.text,
        "name": "mission",
        "file": "",
        "line": 0,
        "stamp_s": _num(event.stamp_s),
        "state": event.state.value,
        "warning": bool(event.warning),
    }
    return [Encoded("/mission", stamp_s, payload)]


def encode_timing(stages: dict[str, object], stamp_s: float) -> list[Encoded]:
    """The stage timings (`StageTimes.to_dict()`)."""
    return [Encoded("/timing", stamp_s, {"timestamp": foxglove_time(stamp_s), "stages": stages})]


def encode_static(stamp_s: float) -> list[Encoded]:
    """The transform that shows local NED upright in Foxglove (x north, y west, z up)."""
    payload = {
        "timestamp": foxglove_time(stamp_s),
        "parent_frame_id": WORLD_FRAME_ID,
        "child_frame_id": FRAME_ID,
        "translation": {"x": 0.0, "y": 0.0, "z": 0.0},
        "rotation": {"x": 1.0, "y": 0.0, "z": 0.0, "w": 0.0},
    }
    return [Encoded("/tf", stamp_s, payload)]


ENCODERS: dict[str, Callable[[Any, float], list[Encoded]]] = {
    "perception": encode_perception,
    "vehicle": encode_vehicle,
    "map": encode_map,
    "plan": encode_plan,
    "setpoint": encode_setpoint,
    "mission": encode_mission,
}


# ---------------------------------------------------------------------------- decoding


def _f(x: float | None, missing: float = math.nan) -> float:
    return missing if x is None else float(x)


def _arr(values: list[float | None]) -> np.ndarray:
    return np.array([_f(v) for v in values], dtype=np.float64)


def _pose_from_matrix(values: list[float | None] | None) -> Pose | None:
    if values is None:
        return None
    m = _arr(values)
    return Pose(m[:9].reshape(3, 3), m[9:])


def image_from_json(payload: dict[str, Any], flags: int = cv2.IMREAD_COLOR) -> np.ndarray:
    """A PNG/JPEG image of a `foxglove.CompressedImage` message."""
    data = np.frombuffer(base64.b64decode(payload["data"]), dtype=np.uint8)
    image = cv2.imdecode(data, flags)
    if image is None:
        raise ValueError(f"cannot decode the image of sequence {payload.get('sequence')}")
    return image


def decode_disparity(payload: dict[str, Any]) -> np.ndarray:
    """The `(H, W) float32` disparity of a `/camera/disparity` message."""
    if payload.get("encoding") != DISPARITY_ENCODING:
        raise ValueError(f"unknown disparity encoding {payload.get('encoding')!r}")
    data = base64.b64decode(payload["data"])
    return disparity_from_bytes(data, int(payload["height"]), int(payload["width"]))


def decode_camera(image: dict[str, Any] | None, disparity: dict[str, Any] | None) -> CameraFrame:
    """A `CameraFrame` from its `/camera/image` and `/camera/disparity` messages."""
    first = image if image is not None else disparity
    assert first is not None
    return CameraFrame(
        _f(first["stamp_s"]),
        int(first["sequence"]),
        None if image is None else image_from_json(image),
        None if disparity is None else decode_disparity(disparity),
    )


def decode_perception(payload: dict[str, Any], disparity_px: np.ndarray | None) -> Perception:
    """A `Perception` from its `/perception/wire_mask` message and its frame's disparity
    (recordings from before the possible mask: it is the wire mask, the same map)."""
    mask = possible = None
    if payload.get("has_mask"):
        image = image_from_json(payload, cv2.IMREAD_GRAYSCALE)
        mask, possible = image > 191, image > 63
    return Perception(
        _f(payload["stamp_s"]), int(payload["sequence"]), mask, disparity_px, possible
    )


def decode_vehicle(p: dict[str, Any]) -> TelemetrySnapshot:
    """The `TelemetrySnapshot` fields the process reads, as recorded."""
    pose = attitude = battery = None
    if p.get("position_ned_m") is not None:
        pose = LocalPosition(
            _arr(p["position_ned_m"]), _arr(p["velocity_ned_mps"]), _f(p["pose_stamp_s"])
        )
    if p.get("roll_pitch_yaw_rad") is not None:
        roll, pitch, yaw = _arr(p["roll_pitch_yaw_rad"])
        attitude = Attitude(float(roll), float(pitch), float(yaw), _f(p["attitude_stamp_s"]))
    if p.get("battery_remaining_frac") is not None or p.get("battery_voltage_v") is not None:
        battery = Battery(
            _f(p.get("battery_voltage_v")), _f(p.get("battery_remaining_frac")), _f(p["stamp_s"])
        )
    last = p.get("last_update_s")
    return TelemetrySnapshot(
        stamp_s=_f(p["stamp_s"]),
        last_update_s=None if last is None else float(last),
        pose=pose,
        attitude=attitude,
        flight_mode=FlightMode.from_name(p.get("flight_mode", "UNKNOWN")),
        armed=p.get("armed"),
        landed_state=LandedState.from_name(p.get("landed_state", "UNKNOWN")),
        battery=battery,
    )


def decode_map(p: dict[str, Any]) -> MapUpdate:
    """A `MapUpdate` as recorded."""
    return MapUpdate(
        _f(p["stamp_s"]),
        int(p["sequence"]),
        _pose_from_matrix(p.get("world_from_camera")),
        None if p.get("result") is None else InsertResult(p["result"]),
        int(p["nodes"]),
        int(p["wires"]),
        bool(p.get("wire_evidence", True)),  # recordings from before the field: always
    )


def decode_vehicle_state(p: dict[str, Any]) -> VehicleState:
    """A `VehicleState` as recorded."""
    return VehicleState(
        _f(p["stamp_s"]), _arr(p["position_ned_m"]), _arr(p["velocity_ned_mps"]), _f(p["yaw_rad"])
    )


def _decode_reference(r: dict[str, Any]) -> Reference:
    return Reference(
        start_s=_f(r["start_s"]),
        times_s=_arr(r["times_s"]),
        positions_ned_m=np.array([_arr(p) for p in r["positions_ned_m"]]).reshape(-1, 3),
        velocities_ned_mps=np.array([_arr(v) for v in r["velocities_ned_mps"]]).reshape(-1, 3),
        plan_id=int(r["plan_id"]),
        yaw_rate_radps=None if r.get("yaw_rate_radps") is None else float(r["yaw_rate_radps"]),
        yaw_target_rad=None if r.get("yaw_target_rad") is None else float(r["yaw_target_rad"]),
        brake=bool(r["brake"]),
    )


def decode_plan(p: dict[str, Any]) -> PlanUpdate:
    """A `PlanUpdate` (its `PlannerOutput` and the inputs of the cycle) as recorded."""
    output = PlannerOutput(
        stamp_s=_f(p["stamp_s"]),
        state=PlannerState(p["state"]),
        reference=_decode_reference(p["reference"]),
        label=p["label"],
        cost=_f(p["cost"]),
        distance_to_goal_m=_f(p["distance_to_goal_m"]),
        checked=int(p["checked"]),
        queries=int(p["queries"]),
        points=int(p["points"]),
    )
    goal = p.get("goal_ned_m")
    speed = p.get("speed_mps")
    return PlanUpdate(
        output=output,
        vehicle=decode_vehicle_state(p["vehicle"]),
        frame_stamp_s=_f(p["frame_stamp_s"], -math.inf),
        goal_index=int(p["goal_index"]),
        goal_ned_m=None if goal is None else _arr(goal),
        hold=bool(p["hold"]),
        speed_mps=None if speed is None else float(speed),
        commanded_velocity_ned_mps=_arr(p["commanded_velocity_ned_mps"]),
    )


def decode_setpoint(p: dict[str, Any]) -> Setpoint:
    """A `Setpoint` as recorded."""
    position = p.get("position_ned_m")
    acceleration = p.get("acceleration_ned_mps2")  # absent in recordings before it existed
    return Setpoint(
        _f(p["stamp_s"]),
        SetpointKind(p["kind"]),
        _arr(p["velocity_ned_mps"]),
        None if position is None else _arr(position),
        _f(p["yaw_rad"]),
        _f(p["yaw_rate_radps"]),
        bool(p["valid"]),
        None if acceleration is None else _arr(acceleration),
    )


def decode_mission(p: dict[str, Any]) -> MissionEvent:
    """A `MissionEvent` as recorded."""
    return MissionEvent(_f(p["stamp_s"]), MissionState(p["state"]), p["message"], p["warning"])
