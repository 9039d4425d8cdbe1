"""The flight recorder on a bus: every message in order, rotation into parts that each open
alone, the size cap deleting the oldest parts, `wireavoid log info`, and the recording played
back as a camera source."""

from __future__ import annotations

import asyncio
import json
import math
from pathlib import Path

import numpy as np
from typer.testing import CliRunner

from companion.cli import app
from companion.ingest.frames import CameraError, CameraFrame
from companion.ingest.recorded import RecordedCameraSource
from companion.mission import MissionEvent, MissionState
from companion.record.params import RecordParams
from companion.record.reader import iter_bus, read_metadata, recording_parts, summary
from companion.record.writer import FlightRecorder
from companion.topics import Bus
from planning.types import Setpoint


class _Clock:
    """A clock whose sleeps pass at once (a Clock: now_s, sleep)."""

    def __init__(self, t: float = 100.0) -> None:
        self.t = t

    def now_s(self) -> float:
        return self.t

    async def sleep(self, duration_s: float) -> None:
        self.t += max(duration_s, 0.0)
        await asyncio.sleep(0)


def _frame(i: int, rng: np.random.Generator) -> CameraFrame:
    image = rng.integers(0, 256, (24, 32, 3), dtype=np.uint8)
    disparity = rng.uniform(0.0, 20.0, (48, 64)).astype(np.float32)
    return CameraFrame(0.1 * i, i, image, disparity)


async def _record(path: Path, params: RecordParams, frames: int) -> FlightRecorder:
    now = [0.0]
    bus = Bus(lambda: now[0])
    recorder = FlightRecorder(path, params, '{"camera": {"frame_rate_hz": 10.0}}',
                              timings=lambda: {"cnn": {"p50_ms": 1.0}})  # fmt: skip
    recorder.attach(bus)
    rng = np.random.default_rng(0)
    for i in range(1, frames + 1):
        now[0] = 0.1 * i + 0.03
        bus.publish("camera", _frame(i, rng))
        bus.publish("setpoint", Setpoint.brake(math.nan, now[0]))
        if i % 10 == 0:
            bus.publish("mission", MissionEvent(now[0], MissionState.NAVIGATE, f"tick {i}"))
    recorder.close()
    return recorder


def test_the_recorder_keeps_every_message_in_bus_order(tmp_path: Path) -> None:
    path = tmp_path / "flight.mcap"
    recorder = asyncio.run(_record(path, RecordParams(), frames=30))
    stats = recorder.stats
    assert stats.dropped == 0 and stats.errors == 0 and stats.parts == [path]
    assert stats.per_channel["/camera/image"] == 30 and stats.per_channel["/setpoint"] == 30
    topics = [m.topic for m in iter_bus([path])]
    assert topics[:3] == ["camera", "setpoint", "camera"] and topics.count("mission") == 3
    frames = [m.message for m in iter_bus([path], {"camera"})]
    rng = np.random.default_rng(0)
    for i, frame in enumerate(frames, start=1):
        expected = _frame(i, rng)
        np.testing.assert_array_equal(frame.image_bgr, expected.image_bgr)
        np.testing.assert_array_equal(frame.disparity_px, expected.disparity_px)
    assert read_metadata(path)["format_version"] == "1"


def test_rotation_splits_into_parts_and_the_cap_deletes_the_oldest(tmp_path: Path) -> None:
    path = tmp_path / "flight.mcap"
    params = RecordParams(split_size_mb=0.1, max_total_mb=0.35, chunk_size_kb=16)
    recorder = asyncio.run(_record(path, params, frames=60))
    stats = recorder.stats
    assert len(stats.parts) >= 5 and stats.deleted[0] == path  # the oldest went first
    kept = [p for p in stats.parts if p.exists()]
    assert sum(p.stat().st_size for p in kept) <= 0.35 * 1024 * 1024 + 0.1 * 1024 * 1024
    for part in kept:  # each part opens on its own, with its schemas and the settings
        assert read_metadata(part)["settings"].startswith("{")
        assert any(m.topic == "camera" for m in iter_bus([part], {"camera"}))
    # the parts that remain follow each other: the newest frames, none missing in between
    sequences = [m.message.sequence for m in iter_bus(kept, {"camera"})]
    assert sequences == list(range(sequences[0], 61))


def test_log_info_summarises_a_recording(tmp_path: Path) -> None:
    path = tmp_path / "flight.mcap"
    asyncio.run(_record(path, RecordParams(), frames=20))
    result = CliRunner().invoke(app, ["log", "info", str(path), "--json"])
    assert result.exit_code == 0, result.output
    info = json.loads(result.output)
    assert info["frames"] == 20 and info["image_shape"] == [24, 32]
    assert info["disparity_shape"] == [48, 64] and info["parts"] == [str(path)]
    assert (
        info["channels"]["/camera/image"]["rate_hz"]
        == summary(path)["channels"]["/camera/image"]["rate_hz"]
    )
    assert [e["text"] for e in info["events"]] == ["tick 10", "tick 20"]
    assert info["stages"] == {"cnn": {"p50_ms": 1.0}}
    text = CliRunner().invoke(app, ["log", "info", str(path)])
    assert text.exit_code == 0 and "foxglove.CompressedImage" in text.output
    bad = tmp_path / "not.mcap"
    bad.write_bytes(b"not an mcap file")
    assert CliRunner().invoke(app, ["log", "info", str(bad)]).exit_code != 0


def test_a_recording_plays_back_as_a_camera_source(tmp_path: Path) -> None:
    path = tmp_path / "flight.mcap"
    asyncio.run(_record(path, RecordParams(), frames=12))
    assert recording_parts(path) == [path]

    async def play() -> list[tuple[float, CameraFrame]]:
        clock = _Clock()
        source = RecordedCameraSource(path, clock)
        await source.open()
        out = []
        while True:
            try:
                frame = await source.next_frame()
            except CameraError as e:
                assert "end of recording" in str(e)
                break
            out.append((clock.now_s(), frame))
        await source.close()
        return out

    played = asyncio.run(play())
    assert [f.sequence for _, f in played] == list(range(1, 13))
    # delivered at the recorded pace, exposure stamps shifted onto this clock (latency kept)
    deliveries = np.array([t for t, _ in played])
    np.testing.assert_allclose(np.diff(deliveries), 0.1, atol=1e-9)
    np.testing.assert_allclose([t - f.stamp_s for t, f in played], 0.03, atol=1e-9)
