"""The perception stage: a camera frame's colour image -> the wire mask of thesis 4.4.1."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from companion.ingest.frames import CameraFrame
from perception.segmenter import WireSegmenter


@dataclass(frozen=True, slots=True)
class Perception:
    """What the CNN made of one frame (stamped with the frame's exposure, process clock).

    wire_mask: `(h, w) bool` on the colour image's pixels (thresholded at the confidence
        threshold and speckle-filtered, 4.4.1), or None when the frame had no colour image.
    disparity_px: the frame's disparity, passed through to the map (or None).
    """

    stamp_s: float
    sequence: int
    wire_mask: np.ndarray | None
    disparity_px: np.ndarray | None


class WireDetector:
    """Runs the wire CNN on frames; synchronous (the process calls it on a worker thread)."""

    def __init__(self, segmenter: WireSegmenter) -> None:
        self._segmenter = segmenter

    def __call__(self, frame: CameraFrame) -> Perception:
        """The perception of `frame`."""
        mask = None if frame.image_bgr is None else self._segmenter.mask(frame.image_bgr, "bgr")
        return Perception(frame.stamp_s, frame.sequence, mask, frame.disparity_px)
