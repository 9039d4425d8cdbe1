"""The perception stage: a camera frame's colour image -> the wire mask of thesis 4.4.1."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from companion.ingest.frames import CameraFrame
from perception.postprocess import continued_wires, stereo_surface
from perception.segmenter import WireSegmenter


@dataclass(frozen=True, slots=True)
class Perception:
    """What the CNN made of one frame (stamped with the frame's exposure, process clock).

    wire_mask: `(h, w) bool` on the colour image's pixels (thresholded at the confidence
        threshold and speckle-filtered, 4.4.1), or None when the frame had no colour image.
    disparity_px: the frame's disparity, passed through to the map (or None).
    possible_mask: `(h, w) bool`, the pixels the CNN does not rule out as wire (probability
        at or above `perception.no_wire_below`; contains `wire_mask`), or None: then every
        pixel outside `wire_mask` is evidence of no wire (the thesis' mask, 4.4.5).
    """

    stamp_s: float
    sequence: int
    wire_mask: np.ndarray | None
    disparity_px: np.ndarray | None
    possible_mask: np.ndarray | None = None


class WireDetector:
    """Runs the wire CNN on frames; synchronous (the process calls it on a worker thread)."""

    def __init__(self, segmenter: WireSegmenter) -> None:
        self._segmenter = segmenter

    def __call__(self, frame: CameraFrame) -> Perception:
        """The perception of `frame`."""
        if frame.image_bgr is None:
            return Perception(frame.stamp_s, frame.sequence, None, frame.disparity_px)
        prob = self._segmenter.probability(frame.image_bgr, "bgr")
        mask = self._segmenter.mask_of(prob)
        possible = self._segmenter.possible_of(prob, mask)
        mask = self.continued(mask, frame.disparity_px)
        possible = possible | mask
        return Perception(frame.stamp_s, frame.sequence, mask, frame.disparity_px, possible)

    def continued(self, mask: np.ndarray, disparity_px: np.ndarray | None) -> np.ndarray:
        """The thresholded `mask` with its straight wires continued (`continued_wires`), up to
        the surfaces stereo sees in `disparity_px` (the same exposure's, or None)."""
        params = self._segmenter.params
        surface = None
        if params.wire_continuation_stops_at_surfaces and disparity_px is not None:
            surface = stereo_surface(disparity_px, mask.shape)
        return continued_wires(
            mask,
            params.wire_continuation_min_length_px,
            params.wire_continuation_max_angle_deg,
            params.wire_continuation_factor,
            surface,
        )
