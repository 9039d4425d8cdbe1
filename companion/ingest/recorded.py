"""A recorded flight as a camera source: the frames of a recording, on the process' clock.

`RecordedCameraSource` plays the camera frames of a recording (`companion.record`) to a
flight process as its camera would have: `open()` anchors the recording's first delivery
to the clock's now; each frame is delivered when the clock reaches its recorded delivery
time, stamped with its recorded exposure shifted by the same offset (so the latency between
exposure and delivery is the recorded one). After the last frame `next_frame` raises
`CameraError` ("end of recording"), as a camera that died would.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

from companion.clock import Clock
from companion.ingest.frames import CameraError, CameraFrame
from companion.record.reader import iter_bus, recording_parts


class RecordedCameraSource:
    """`CameraSource` over the camera frames of the recording at `path` (and its parts)."""

    def __init__(self, path: str | Path, clock: Clock) -> None:
        self._parts = recording_parts(path)
        self._clock = clock
        self._frames: Iterator[tuple[float, CameraFrame]] | None = None
        self._offset_s = 0.0
        self.delivered = 0

    async def open(self) -> None:
        """Start from the recording's first frame, now."""
        frames = ((m.stamp_s, m.message) for m in iter_bus(self._parts, {"camera"}))
        first = next(frames, None)
        if first is None:
            raise CameraError(f"{self._parts[0]}: no camera frames")
        self._offset_s = self._clock.now_s() - first[0]
        self._frames = _chain(first, frames)

    async def next_frame(self) -> CameraFrame:
        """The next recorded frame, at its recorded time after the first."""
        if self._frames is None:
            raise CameraError("recorded camera not open")
        item = next(self._frames, None)
        if item is None:
            raise CameraError(f"{self._parts[-1]}: end of recording")
        delivered_s, frame = item
        await self._clock.sleep(delivered_s + self._offset_s - self._clock.now_s())
        self.delivered += 1
        return replace(frame, stamp_s=frame.stamp_s + self._offset_s)

    async def close(self) -> None:
        """Stop playing (idempotent)."""
        self._frames = None


def _chain(
    first: tuple[float, CameraFrame], rest: Iterator[tuple[float, CameraFrame]]
) -> Iterator[tuple[float, CameraFrame]]:
    yield first
    yield from rest
