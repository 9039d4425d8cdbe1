"""The camera source `camera.source` names, for `wireavoid run` (simulators bring their own)."""

from __future__ import annotations

import asyncio

from companion.config import Settings
from companion.ingest.frames import CameraError, CameraFrame, CameraSource
from companion.ingest.oakd import OakdCameraSource
from geometry.camera import stereo_rig_from_params


class NoCamera:
    """`camera.source = "none"`: a source that never delivers a frame (bench tests of the
    process without a camera); perception stays stale, so the mission never flies."""

    async def open(self) -> None:
        """Nothing to open."""

    async def next_frame(self) -> CameraFrame:
        """Never returns a frame (waits until cancelled)."""
        await asyncio.Event().wait()
        raise CameraError("no camera")

    async def close(self) -> None:
        """Nothing to close."""


def camera_source(settings: Settings) -> CameraSource:
    """The configured camera source."""
    if settings.camera.source == "oakd":
        return OakdCameraSource(settings.camera, stereo_rig_from_params(settings.mapping.camera))
    return NoCamera()
