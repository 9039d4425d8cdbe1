"""The OAK-D camera source (`companion.ingest.oakd`) without a device: the depth-to-disparity
conversion, the frames it builds from depthai messages, and the clear error when it cannot
open. depthai messages are stood in for by objects with the same methods (no hardware here)."""

from __future__ import annotations

import asyncio
import sys
from datetime import timedelta

import numpy as np
import pytest

from companion.config import Settings
from companion.ingest.frames import CameraError
from companion.ingest.oakd import OakdCameraSource, disparity_from_depth_mm, frame_from_messages
from companion.ingest.params import CameraParams
from companion.ingest.sources import NoCamera, camera_source
from geometry.camera import stereo_rig_from_params
from mapping.droan.params import MappingParams

RIG = stereo_rig_from_params(MappingParams().camera)


class ImgFrame:
    """The methods of depthai's ImgFrame the source reads."""

    def __init__(self, frame: np.ndarray, stamp_s: float) -> None:
        self._frame, self._stamp = frame, timedelta(seconds=stamp_s)

    def getCvFrame(self) -> np.ndarray:
        return self._frame

    def getFrame(self) -> np.ndarray:
        return self._frame

    def getTimestamp(self) -> timedelta:
        return self._stamp


def test_depth_in_mm_becomes_disparity_in_the_rigs_bf_and_no_match_unknown() -> None:
    depth = np.array([[4000, 0], [2000, 65535]], np.uint16)
    disparity = disparity_from_depth_mm(depth, RIG)
    assert disparity.dtype == np.float32
    assert disparity[0, 0] == pytest.approx(RIG.bf_px_m / 4.0, rel=1e-6)  # eq. 4.1
    assert disparity[1, 0] == pytest.approx(RIG.bf_px_m / 2.0, rel=1e-6)
    assert np.isnan(disparity[0, 1])  # no stereo match: unknown, not free
    assert 0 < disparity[1, 1] < 1.0  # 65.5 m: a far return, not a hole


def test_a_synchronised_pair_becomes_one_frame_stamped_at_the_colour_exposure() -> None:
    colour = ImgFrame(np.zeros((240, 320, 3), np.uint8), 123.456)
    depth = ImgFrame(np.full(RIG.camera.shape, 5000, np.uint16), 123.460)
    frame = frame_from_messages(colour, depth, 7, RIG)
    assert frame.stamp_s == pytest.approx(123.456) and frame.sequence == 7
    assert frame.image_bgr.shape == (240, 320, 3)
    assert frame.disparity_px.shape == RIG.camera.shape
    with pytest.raises(CameraError, match="not the rig's"):
        frame_from_messages(colour, ImgFrame(np.zeros((400, 640), np.uint16), 0.0), 8, RIG)


def test_without_depthai_the_source_fails_with_a_clear_error(monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "depthai", None)  # as on a machine without the extra
    source = OakdCameraSource(CameraParams(), RIG)
    with pytest.raises(CameraError, match=r"pip install 'wireavoid\[oakd\]'"):
        asyncio.run(source.open())
    with pytest.raises(CameraError, match="not open"):
        asyncio.run(source.next_frame())


def test_the_configured_source_is_built() -> None:
    assert isinstance(camera_source(Settings()), OakdCameraSource)
    none = camera_source(Settings(camera=CameraParams(source="none")))
    assert isinstance(none, NoCamera)

    async def no_frame() -> bool:
        await none.open()
        try:
            await asyncio.wait_for(none.next_frame(), 0.05)
        except TimeoutError:
            return True
        return False

    assert asyncio.run(no_frame())
