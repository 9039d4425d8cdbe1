"""Reading recordings back: the messages in the bus' order, decoded into the product's types.

A recording is one MCAP file or the parts of a split one (`flight.mcap`, `flight-001.mcap`,
...; `recording_parts` finds them). `iter_recorded` yields the JSON of every message in the
order the bus published them (the MCAP `sequence` the writer numbered them with);
`iter_bus` decodes them into what the stages exchanged (`CameraFrame`, `Perception`,
`TelemetrySnapshot`, `MapUpdate`, `PlanUpdate`, `Setpoint`, `MissionEvent`); `summary` is what
`wireavoid log info` prints.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mcap.reader import make_reader

from companion.record.codec import (
    CHANNELS,
    decode_camera,
    decode_map,
    decode_mission,
    decode_plan,
    decode_setpoint,
    decode_vehicle,
)
from companion.record.writer import PROFILE, part_path


class RecordingError(ValueError):
    """The file is not a wireavoid recording, or is damaged; the message says which."""


@dataclass(frozen=True, slots=True)
class RecordedMessage:
    """One MCAP message: its index in the recording, channel, bus topic, publication time (s)
    and JSON payload."""

    index: int
    channel: str
    bus_topic: str
    stamp_s: float
    payload: dict[str, Any]


@dataclass(frozen=True, slots=True)
class BusMessage:
    """A bus message decoded: topic, publication time (s) and the product's object; for
    `perception`, `message` is the recorded JSON (its disparity is its camera frame's)."""

    topic: str
    stamp_s: float
    message: Any


def recording_parts(path: str | Path) -> list[Path]:
    """`path` and the parts that follow it (`stem-001.mcap`, ...), in order."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(path)
    parts = [path]
    while (nxt := part_path(path, len(parts))).exists():
        parts.append(nxt)
    return parts


def read_metadata(path: str | Path) -> dict[str, str]:
    """The wireavoid metadata of one part (settings JSON, format version, part index)."""
    with Path(path).open("rb") as f:
        reader = make_reader(f)
        try:
            header = reader.get_header()
        except Exception as e:
            raise RecordingError(f"{path}: not an MCAP file ({e})") from e
        if header.profile != PROFILE:
            raise RecordingError(f"{path}: MCAP profile {header.profile!r}, not {PROFILE!r}")
        for record in reader.iter_metadata():
            if record.name == "wireavoid":
                return dict(record.metadata)
    raise RecordingError(f"{path}: no wireavoid metadata")


def recorded_settings(path: str | Path) -> dict[str, Any]:
    """The settings the recording was made with, as a dict (simulator sections included)."""
    return json.loads(read_metadata(path)["settings"])


def iter_recorded(
    paths: Iterable[str | Path], channels: set[str] | None = None
) -> Iterator[RecordedMessage]:
    """Every message of the parts `paths` (in their order) in the bus' order."""
    for path in paths:
        with Path(path).open("rb") as f:
            reader = make_reader(f)
            messages = []
            for _, channel, message in reader.iter_messages(log_time_order=False):
                if channels is not None and channel.topic not in channels:
                    continue
                if channel.topic == "/tf":
                    continue
                messages.append((message.sequence, channel, message))
            messages.sort(key=lambda m: m[0])
            for index, channel, message in messages:
                yield RecordedMessage(
                    index,
                    channel.topic,
                    channel.metadata.get("bus_topic", ""),
                    message.log_time / 1e9,
                    json.loads(message.data),
                )


_DECODERS = {
    "vehicle": decode_vehicle,
    "map": decode_map,
    "plan": decode_plan,
    "setpoint": decode_setpoint,
    "mission": decode_mission,
}


def iter_bus(paths: Iterable[str | Path], topics: set[str] | None = None) -> Iterator[BusMessage]:
    """The recorded bus messages, decoded, in publication order (camera frames joined from
    their image and disparity messages)."""
    wanted = None
    if topics is not None:
        wanted = {c.topic for c in CHANNELS.values() if c.bus_topic in topics}
        wanted -= {"/camera/disparity_preview", "/plan/path"}
    pending: list[RecordedMessage] = []

    def flush() -> Iterator[BusMessage]:
        if pending:
            image = next((m.payload for m in pending if m.channel == "/camera/image"), None)
            disparity = next((m.payload for m in pending if m.channel == "/camera/disparity"), None)
            if image is not None or disparity is not None:
                yield BusMessage("camera", pending[0].stamp_s, decode_camera(image, disparity))
            pending.clear()

    for m in iter_recorded(paths, wanted):
        if m.bus_topic == "camera":
            if pending and pending[0].payload.get("sequence") != m.payload.get("sequence"):
                yield from flush()
            pending.append(m)
            continue
        yield from flush()
        if m.bus_topic == "perception":
            yield BusMessage("perception", m.stamp_s, m.payload)
        elif m.bus_topic in _DECODERS and m.channel != "/plan/path":
            yield BusMessage(m.bus_topic, m.stamp_s, _DECODERS[m.bus_topic](m.payload))
    yield from flush()


def summary(path: str | Path) -> dict[str, Any]:
    """What `wireavoid log info` reports: parts, size, time span, channels (count, rate),
    frames and their size, mission events, the final mission state, stage timings."""
    parts = recording_parts(path)
    metadata = read_metadata(parts[0])
    channels: dict[str, dict[str, Any]] = {}
    first_s, last_s = math.inf, -math.inf
    events: list[dict[str, Any]] = []
    timing: dict[str, Any] | None = None
    image_shape = disparity_shape = None
    for m in iter_recorded(parts):
        entry = channels.setdefault(
            m.channel,
            {"schema": CHANNELS[m.channel].schema_name, "messages": 0, "bytes": 0},
        )
        entry["messages"] += 1
        entry["bytes"] += len(json.dumps(m.payload))
        first_s, last_s = min(first_s, m.stamp_s), max(last_s, m.stamp_s)
        if m.channel == "/mission":
            events.append(
                {
                    "t_s": round(m.stamp_s, 3),
                    "state": m.payload["state"],
                    "text": m.payload["message"],
                }
            )
        elif m.channel == "/timing":
            timing = m.payload["stages"]
        elif m.channel == "/camera/disparity" and disparity_shape is None:
            disparity_shape = [m.payload["height"], m.payload["width"]]
        elif m.channel == "/camera/image" and image_shape is None:
            from companion.record.codec import image_from_json

            image_shape = list(image_from_json(m.payload).shape[:2])
    duration_s = last_s - first_s if math.isfinite(first_s) else 0.0
    for entry in channels.values():
        entry["rate_hz"] = round(entry["messages"] / duration_s, 2) if duration_s > 0 else None
    settings = json.loads(metadata["settings"])
    return {
        "file": str(parts[0]),
        "parts": [str(p) for p in parts],
        "size_bytes": sum(p.stat().st_size for p in parts),
        "format_version": metadata.get("format_version"),
        "start_s": round(first_s, 3) if math.isfinite(first_s) else None,
        "end_s": round(last_s, 3) if math.isfinite(last_s) else None,
        "duration_s": round(duration_s, 3),
        "messages": sum(e["messages"] for e in channels.values()),
        "channels": channels,
        "frames": channels.get("/camera/disparity", channels.get("/camera/image", {})).get(
            "messages", 0
        ),
        "image_shape": image_shape,
        "disparity_shape": disparity_shape,
        "mission_state": events[-1]["state"] if events else None,
        "events": events,
        "stages": timing,
        "camera_rate_hz": settings.get("camera", {}).get("frame_rate_hz"),
        "source": metadata.get("source"),
    }
