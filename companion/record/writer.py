"""The flight recorder: every message of the process' bus, in order, to MCAP files.

It hangs on the bus as a subscriber (`companion.topics.Bus.subscribe`), never inside a stage:
on the event loop it only puts the message in a bounded queue (full: the message is dropped
and counted, the recorder never stalls the flight); a writer thread encodes it
(`companion.record.codec`: one JSON Schema per channel, PNG images, lossless disparity) and
writes it to an MCAP file with `record.compression` chunks. Every `record.timing_period_s` of
process time it also records the stage timings. A file that reaches `record.split_size_mb`
is finished and the next part opened (`flight.mcap`, `flight-001.mcap`, ...; each a complete
MCAP with its schemas, channels and the settings); parts beyond `record.max_total_mb` are
deleted oldest first, as a dashcam does. Each message's MCAP `sequence` is its index in the
whole recording, so a reader restores the bus' order across channels and parts.
"""

from __future__ import annotations

import json
import logging
import math
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from mcap.writer import CompressionType, Writer

from companion.record.codec import (
    CHANNELS,
    ENCODERS,
    Encoded,
    encode_camera,
    encode_static,
    encode_timing,
    stamp_ns,
)
from companion.record.params import RecordParams
from companion.topics import Bus, Stamped

log = logging.getLogger(__name__)

PROFILE = "wireavoid"
FORMAT_VERSION = "1"
_COMPRESSION = {
    "zstd": CompressionType.ZSTD,
    "lz4": CompressionType.LZ4,
    "none": CompressionType.NONE,
}
_MB = 1024 * 1024


def part_path(path: Path, index: int) -> Path:
    """The file of part `index` of the recording at `path` (0: `path` itself)."""
    return path if index == 0 else path.with_name(f"{path.stem}-{index:03d}{path.suffix}")


@dataclass
class RecordingStats:
    """What the recorder wrote: messages per channel, messages dropped, the parts on disk."""

    messages: int = 0
    per_channel: dict[str, int] = field(default_factory=dict)
    dropped: int = 0
    errors: int = 0
    parts: list[Path] = field(default_factory=list)
    deleted: list[Path] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {
            "messages": self.messages,
            "per_channel": dict(self.per_channel),
            "dropped": self.dropped,
            "errors": self.errors,
            "parts": [str(p) for p in self.parts],
            "deleted": [str(p) for p in self.deleted],
        }


class FlightRecorder:
    """Records a bus to MCAP (see the module docstring).

    settings_json: the flight's `Settings` as JSON, kept in each part's metadata (the replay
        runs the stages with them). timings: the process' `StageTimes.to_dict`, called on the
        event loop at most every `timing_period_s`. preview_max_disparity_px: the disparity
        that maps to the top of the preview's colour scale.
    """

    def __init__(
        self,
        path: str | Path,
        params: RecordParams,
        settings_json: str,
        *,
        timings: Callable[[], dict[str, object]] | None = None,
        preview_max_disparity_px: float = 64.0,
        metadata: dict[str, str] | None = None,
    ) -> None:
        self.path = Path(path)
        self.params = params
        self._settings_json = settings_json
        self._metadata = dict(metadata or {})
        self._timings = timings
        self._preview = preview_max_disparity_px if params.disparity_preview else None
        self._queue: queue.Queue[Stamped | tuple[str, float, Any] | None] = queue.Queue(
            params.queue_messages
        )
        self._next_timing_s = -math.inf
        self._thread: threading.Thread | None = None
        self._writer: Writer | None = None
        self._stream: IO[bytes] | None = None
        self._channel_ids: dict[str, int] = {}
        self._part = 0
        self._index = 0
        self.stats = RecordingStats()

    # ------------------------------------------------------------------ the loop's side

    def attach(self, bus: Bus) -> FlightRecorder:
        """Start the writer thread and record every message `bus` publishes from now on."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._open_part()
        self._thread = threading.Thread(target=self._run, name="recorder", daemon=True)
        self._thread.start()
        bus.subscribe(self.on_message)
        return self

    def on_message(self, stamped: Stamped) -> None:
        """The bus' subscriber: queue the message (drop it when the writer is behind)."""
        self._put(stamped)
        if self._timings is not None and stamped.stamp_s >= self._next_timing_s:
            self._next_timing_s = stamped.stamp_s + self.params.timing_period_s
            self._put(("timing", stamped.stamp_s, self._timings()))

    def close(self) -> RecordingStats:
        """Write what is queued, finish the file and stop the thread (idempotent)."""
        thread, self._thread = self._thread, None
        if thread is not None:
            self._queue.put(None)
            thread.join()
        if self._writer is not None:
            self._finish_part()
        return self.stats

    def _put(self, item: Stamped | tuple[str, float, Any]) -> None:
        try:
            self._queue.put_nowait(item)
        except queue.Full:
            self.stats.dropped += 1

    # ------------------------------------------------------------------ the writer thread

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                return
            try:
                for encoded in self._encode(item):
                    self._write(encoded)
            except Exception:  # a message the codec cannot write must not end the recording
                self.stats.errors += 1
                log.exception("recorder: cannot record %r", getattr(item, "topic", item))

    def _encode(self, item: Stamped | tuple[str, float, Any]) -> list[Encoded]:
        if isinstance(item, tuple):
            _, stamp_s, stages = item
            return encode_timing(stages, stamp_s)
        if item.topic == "camera":
            return encode_camera(item.message, item.stamp_s, self._preview)
        return ENCODERS[item.topic](item.message, item.stamp_s)

    def _write(self, encoded: Encoded) -> None:
        assert self._writer is not None and self._stream is not None
        ns = stamp_ns(encoded.stamp_s)
        self._writer.add_message(
            self._channel_ids[encoded.channel], ns, encoded.data(), ns, self._index & 0xFFFFFFFF
        )
        self._index += 1
        self.stats.messages += 1
        self.stats.per_channel[encoded.channel] = self.stats.per_channel.get(encoded.channel, 0) + 1
        if self._stream.tell() >= self.params.split_size_mb * _MB:
            self._finish_part()
            self._part += 1
            self._open_part()
            self._enforce_cap()

    def _open_part(self) -> None:
        path = part_path(self.path, self._part)
        self._stream = path.open("wb")
        metadata = {
            **self._metadata,
            "part": str(self._part),
            "first_index": str(self._index),
            "settings": self._settings_json,
        }
        self._writer, self._channel_ids = open_mcap(
            self._stream, metadata, self.params.chunk_size_kb * 1024, self.params.compression
        )
        self.stats.parts.append(path)

    def _finish_part(self) -> None:
        assert self._writer is not None and self._stream is not None
        self._writer.finish()
        self._stream.close()
        self._writer = self._stream = None

    def _enforce_cap(self) -> None:
        """Delete the oldest finished parts until they and a full current part fit the cap."""
        budget = (self.params.max_total_mb - self.params.split_size_mb) * _MB
        finished = [p for p in self.stats.parts[:-1] if p.exists()]
        total = sum(p.stat().st_size for p in finished)
        while finished and total > budget:
            oldest = finished.pop(0)
            total -= oldest.stat().st_size
            oldest.unlink()
            self.stats.deleted.append(oldest)
            log.info("recorder: deleted %s (record.max_total_mb)", oldest)


def open_mcap(
    stream: IO[bytes],
    metadata: dict[str, str],
    chunk_size_bytes: int = 1024 * 1024,
    compression: str = "zstd",
) -> tuple[Writer, dict[str, int]]:
    """Start an MCAP file of the wireavoid profile on `stream`: every channel of
    `companion.record.codec.CHANNELS` with its JSON Schema, the metadata (the settings, the
    format version) and the static transform; returns the writer and the channel ids."""
    writer = Writer(stream, chunk_size=chunk_size_bytes, compression=_COMPRESSION[compression])
    writer.start(profile=PROFILE, library="wireavoid")
    schema_ids: dict[tuple[str, str], int] = {}
    channel_ids: dict[str, int] = {}
    for channel in CHANNELS.values():
        data = json.dumps(channel.schema, sort_keys=True).encode()
        key = (channel.schema_name, data.decode())
        if key not in schema_ids:
            schema_ids[key] = writer.register_schema(channel.schema_name, "jsonschema", data)
        channel_ids[channel.topic] = writer.register_channel(
            channel.topic, "json", schema_ids[key], {"bus_topic": channel.bus_topic}
        )
    writer.add_metadata("wireavoid", {**metadata, "format_version": FORMAT_VERSION})
    for encoded in encode_static(0.0):
        writer.add_message(channel_ids[encoded.channel], 0, encoded.data(), 0, 0)
    return writer, channel_ids


def start_recording(process: Any) -> FlightRecorder | None:
    """The hook `wireavoid run` and `fly` call once their `FlightProcess` is built: record it
    to `record.path` (strftime fields filled in now), or None when the path is empty. The
    caller closes the recorder when the process ends."""
    pattern = process.settings.record.path
    if not pattern:
        return None
    return record_process(process, time.strftime(pattern), source="service")


def record_process(
    process: Any, path: str | Path, params: RecordParams | None = None, **metadata: str
) -> FlightRecorder:
    """Record a `FlightProcess`' bus to `path` (the hook `sim --record`, `run --record` use):
    its settings go into the file, its stage timings are sampled; `close()` it at the end."""
    settings = process.settings
    recorder = FlightRecorder(
        path,
        params or settings.record,
        settings.model_dump_json(),
        timings=process.times.to_dict,
        preview_max_disparity_px=float(settings.mapping.camera_max_disparity_px),
        metadata=metadata,
    )
    return recorder.attach(process.bus)
