"""The simulated cameras behind the flight process' `CameraSource` protocol.

Exposures fall at `camera.frame_rate_hz` on the process clock. Each is rendered by the hil
renderer from the vehicle's pose at the exposure (the simulator's truth, or the autopilot's
estimate when flying an external PX4 SITL) and handed over `camera_sim.latency_s` after it,
stamped with its exposure time, as a real camera driver does. Under the lockstep clock the
rendering happens while simulated time stands still and no stage computes, so the simulator's
cost is never charged to the drone; on the wall clock it runs on a thread of its own.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable

import numpy as np

from companion.cli.settings import SimSettings
from companion.clock import Clock
from companion.ingest.frames import CameraError, CameraFrame
from geometry.camera import body_from_camera_from_params, stereo_rig_from_params
from geometry.pose import Pose
from hil.lockstep import LockstepClock
from hil.sensors.cameras import SimulatedStereoCamera
from hil.world.model import World


def settings_camera(settings: SimSettings, world: World) -> SimulatedStereoCamera:
    """The simulated cameras of `world` as `settings` configure the rig, its mount on the body,
    the stereo matcher and the colour camera's down-scale (`mapping`, `camera_sim`, `camera`)."""
    return SimulatedStereoCamera(
        world,
        stereo_rig_from_params(settings.mapping.camera),
        body_from_camera_from_params(settings.mapping.camera),
        settings.camera_sim,
        settings.mapping.stereo,
        settings.mapping.camera_max_disparity_px,
        colour_downscale=settings.camera.colour_downscale,
    )


_TRUTH_MASKS_KEPT = 32  # frames in flight between the camera and the detector, and more


class SimulatedCameraSource:
    """`CameraSource` rendering `SimulatedStereoCamera` frames at the camera rate.

    pose_at_exposure: the vehicle's `world_from_body` in the *world* frame, now (None when
        unknown: the frame is skipped).
    truth_masks: exposure stamp (s) -> `(h, w) bool` true wire pixels of the colour image, of
        the newest frames (`companion.cli.sim_masks` reads them).
    """

    def __init__(
        self,
        camera: SimulatedStereoCamera,
        pose_at_exposure: Callable[[], Pose | None],
        clock: Clock,
        frame_rate_hz: float,
        latency_s: float,
    ) -> None:
        self._camera = camera
        self._pose = pose_at_exposure
        self._clock = clock
        self._period_s = 1.0 / frame_rate_hz
        self._latency_s = latency_s
        self._next_s: float | None = None
        self._sequence = 0
        self.failed = False  # fault injection: next_frame raises CameraError
        self.truth_masks: dict[float, np.ndarray] = {}

    async def open(self) -> None:
        """Start exposing at the next frame period."""
        self._next_s = self._clock.now_s() + self._period_s

    async def next_frame(self) -> CameraFrame:
        """The next exposure, delivered `latency_s` after it."""
        if self._next_s is None:
            raise CameraError("camera not open")
        while True:
            await self._clock.sleep(self._next_s - self._clock.now_s())
            # a late exposure is taken now and the missed ones skipped, as a camera does
            exposure_s = max(self._next_s, self._clock.now_s())
            self._next_s = exposure_s + self._period_s
            if self.failed:
                raise CameraError("simulated camera failure")
            pose = self._pose()
            if pose is not None:
                break
        disparity, colour = await self._render(exposure_s, pose)
        await self._clock.sleep(exposure_s + self._latency_s - self._clock.now_s())
        self._sequence += 1
        return CameraFrame(exposure_s, self._sequence, colour, disparity)

    async def close(self) -> None:
        """Stop exposing."""
        self._next_s = None

    async def _render(self, stamp_s: float, world_from_body: Pose) -> tuple[np.ndarray, np.ndarray]:
        if isinstance(self._clock, LockstepClock):
            await self._clock.idle()
            return self._render_now(stamp_s, world_from_body)
        return await asyncio.to_thread(self._render_now, stamp_s, world_from_body)

    def _render_now(self, stamp_s: float, world_from_body: Pose) -> tuple[np.ndarray, np.ndarray]:
        frame = self._camera.render(stamp_s, world_from_body)
        self.truth_masks[stamp_s] = frame.image_wire_mask
        while len(self.truth_masks) > _TRUTH_MASKS_KEPT:
            del self.truth_masks[next(iter(self.truth_masks))]
        return frame.disparity_px, frame.image_bgr
