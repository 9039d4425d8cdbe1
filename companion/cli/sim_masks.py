"""Wire masks from the simulator's truth, to measure how far perception limits the loop.

`sim.wire_masks` picks what a simulated flight's map gets instead of the shipped CNN's mask
(the product, `cnn`): the renderer's true wire pixels (`truth`: perfect detection in the
image, the depth still unknown), the CNN's mask without its false marks (`cnn_misses`), or the
true wires with the CNN's false marks (`cnn_false_marks`). A mark counts as false farther
than `NEAR_WIRE_PX` from every true wire pixel. The flight process runs the detector it is
given and cannot tell; only the `sim` command composes one of these.
"""

from __future__ import annotations

from typing import get_args

import cv2
import numpy as np

from companion.cli.settings import WireMasks
from companion.cli.sim_camera import SimulatedCameraSource
from companion.flight.perceive import Perception, WireDetector
from companion.ingest.frames import CameraFrame

NEAR_WIRE_PX = 7
"""A CNN mark within this many colour pixels (square window) of a true wire is on the wire:
the CNN's masks are a few pixels thick around a thin wire."""
_NEAR_WIRE_WINDOW = np.ones((2 * NEAR_WIRE_PX + 1,) * 2, np.uint8)


class TruthWireDetector:
    """A `WireDetector` stand-in mixing the CNN's mask with the camera's truth (`mode`)."""

    def __init__(self, cnn: WireDetector, camera: SimulatedCameraSource, mode: WireMasks) -> None:
        if mode not in get_args(WireMasks) or mode == "cnn":
            raise ValueError(f"not a truth-mask mode of sim.wire_masks: {mode!r}")
        self._cnn = cnn
        self._camera = camera
        self.mode = mode

    def __call__(self, frame: CameraFrame) -> Perception:
        """The perception of `frame` with the truth of its exposure mixed in."""
        truth = self._camera.truth_masks.get(frame.stamp_s)
        if frame.image_bgr is None or truth is None:
            raise LookupError(f"no true wire mask for the frame exposed at {frame.stamp_s} s")
        if self.mode == "truth":
            return Perception(frame.stamp_s, frame.sequence, truth, frame.disparity_px, truth)
        cnn = self._cnn(frame)
        assert cnn.wire_mask is not None and cnn.possible_mask is not None
        on_wire = cv2.dilate(truth.astype(np.uint8), _NEAR_WIRE_WINDOW) > 0
        if self.mode == "cnn_misses":
            mask, possible = cnn.wire_mask & on_wire, cnn.possible_mask & on_wire
        else:
            mask = truth | (cnn.wire_mask & ~on_wire)
            possible = truth | (cnn.possible_mask & ~on_wire)
        return Perception(frame.stamp_s, frame.sequence, mask, frame.disparity_px, possible)
