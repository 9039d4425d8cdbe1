"""The OAK-D camera source (depthai v3): colour and stereo depth aligned to it, in sync.

The pipeline runs the colour camera (CAM_A) at the CNN's size and the stereo pair (CAM_B,
CAM_C) into StereoDepth with its depth aligned to the colour camera at the rig's size
(`mapping.camera_width_px` x `camera_height_px`, the colour image an integer down-scale of it,
`companion.ingest.frames`), and a Sync node pairs each colour frame with its depth. Depth
(uint16 mm, 0 = no match) becomes disparity d = b f / z (eq. 4.1) in the rig's own b f, so the
map uses one camera model; no match is NaN (unknown: stereo cannot tell "nothing there" from
"could not match"). Frames are stamped with depthai's host-synchronised timestamp, which is on
the host's monotonic clock, the `WallClock`'s.

depthai is an optional dependency (`pip install 'wireavoid[oakd]'`); without it, or without a
device, `open()` raises `CameraError` (depthai blocks about 11 s looking for a device first).
"""

from __future__ import annotations

import asyncio
from datetime import timedelta
from typing import Any

import numpy as np

from companion.ingest.frames import CameraError, CameraFrame
from companion.ingest.params import CameraParams
from geometry.camera import StereoRig

_MM_PER_M = 1000.0


def disparity_from_depth_mm(depth_mm: np.ndarray, rig: StereoRig) -> np.ndarray:
    """`(H, W) float32` disparity, px, of an OAK-D depth image in mm (0 = no match -> NaN)."""
    depth_m = np.asarray(depth_mm, dtype=np.float32) / np.float32(_MM_PER_M)
    with np.errstate(divide="ignore"):
        disparity = np.float32(rig.bf_px_m) / depth_m
    disparity[depth_m <= 0] = np.nan
    return disparity


def frame_from_messages(colour: Any, depth: Any, sequence: int, rig: StereoRig) -> CameraFrame:
    """A `CameraFrame` from one synchronised pair of depthai `ImgFrame`s (colour BGR, depth
    mm aligned to it), stamped with the colour exposure's host timestamp."""
    image = colour.getCvFrame()
    depth_mm = depth.getFrame()
    if depth_mm.shape != rig.camera.shape:
        raise CameraError(f"OAK-D depth {depth_mm.shape} is not the rig's {rig.camera.shape}")
    stamp: timedelta = colour.getTimestamp()
    return CameraFrame(
        stamp.total_seconds(),
        sequence,
        np.ascontiguousarray(image),
        disparity_from_depth_mm(depth_mm, rig),
    )


class OakdCameraSource:
    """`CameraSource` of an OAK-D (depthai v3); see the module docstring."""

    def __init__(self, params: CameraParams, rig: StereoRig) -> None:
        self._params = params
        self._rig = rig
        self._pipeline: Any = None
        self._queue: Any = None
        self._sequence = 0

    async def open(self) -> None:
        """Find the device and start the pipeline (blocking work on a thread)."""
        if self._pipeline is None:
            self._pipeline, self._queue = await asyncio.to_thread(self._start)

    def _start(self) -> tuple[Any, Any]:
        try:
            import depthai as dai
        except ImportError as e:
            raise CameraError("depthai is not installed: pip install 'wireavoid[oakd]'") from e
        p, rig = self._params, self._rig
        try:
            device = dai.Device(p.oakd_device) if p.oakd_device else dai.Device()
            pipeline = dai.Pipeline(device)
            colour = pipeline.create(dai.node.Camera).build(dai.CameraBoardSocket.CAM_A)
            left = pipeline.create(dai.node.Camera).build(dai.CameraBoardSocket.CAM_B)
            right = pipeline.create(dai.node.Camera).build(dai.CameraBoardSocket.CAM_C)
            stereo = pipeline.create(dai.node.StereoDepth)
            stereo.setDefaultProfilePreset(dai.node.StereoDepth.PresetMode.ROBOTICS)
            stereo.setLeftRightCheck(True)
            stereo.setDepthAlign(dai.CameraBoardSocket.CAM_A)
            stereo.setOutputSize(rig.camera.width_px, rig.camera.height_px)
            mono_size = (p.mono_width_px, p.mono_height_px)
            left.requestOutput(mono_size, fps=p.frame_rate_hz).link(stereo.left)
            right.requestOutput(mono_size, fps=p.frame_rate_hz).link(stereo.right)
            size = (
                rig.camera.width_px // p.colour_downscale,
                rig.camera.height_px // p.colour_downscale,
            )
            colour_out = colour.requestOutput(size, dai.ImgFrame.Type.BGR888i, fps=p.frame_rate_hz)
            sync = pipeline.create(dai.node.Sync)
            sync.setSyncThreshold(timedelta(seconds=p.sync_threshold_s))
            colour_out.link(sync.inputs["colour"])
            stereo.depth.link(sync.inputs["depth"])
            queue = sync.out.createOutputQueue(maxSize=1, blocking=False)
            pipeline.start()
        except RuntimeError as e:
            raise CameraError(f"OAK-D: {e}") from e
        return pipeline, queue

    async def next_frame(self) -> CameraFrame:
        """The next synchronised colour + depth pair."""
        if self._queue is None:
            raise CameraError("OAK-D not open")
        try:
            group = await asyncio.to_thread(self._queue.get)
        except RuntimeError as e:
            raise CameraError(f"OAK-D: {e}") from e
        self._sequence += 1
        return frame_from_messages(group["colour"], group["depth"], self._sequence, self._rig)

    async def close(self) -> None:
        """Stop the pipeline and release the device."""
        pipeline, self._pipeline, self._queue = self._pipeline, None, None
        if pipeline is not None:
            await asyncio.to_thread(pipeline.stop)
