"""Wire labels from image-space polylines: anti-aliased coverage and the geometric mask.

Shared by the synthetic generator (`synthetic`) and the labelled real photographs
(`real_photos`), so that a wire is labelled the same way in both.
"""

from __future__ import annotations

import cv2
import numpy as np

_SHIFT = 4  # fixed-point fractional bits of OpenCV drawing coordinates


def rasterise(
    segments_px: np.ndarray, widths_px: np.ndarray, h: int, w: int, supersampling: int
) -> np.ndarray:
    """Anti-aliased coverage (H, W) float32 in [0, 1] of segments of given widths (supersampled)."""
    s = supersampling
    canvas = np.zeros((h * s, w * s), np.uint8)
    pts = np.round((segments_px * s + (s - 1) / 2) * (1 << _SHIFT)).astype(np.int32)
    levels = np.maximum(1, np.round(widths_px * s)).astype(np.int32)
    for level in np.unique(levels):
        cv2.polylines(
            canvas, list(pts[levels == level]), False, 255, int(level), cv2.LINE_8, _SHIFT
        )
    return cv2.resize(canvas, (w, h), interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0


def label_mask(segments_px: np.ndarray, coverage: np.ndarray) -> np.ndarray:
    """Geometric wire mask (H, W) uint8 {0, 1} of segments whose anti-aliased `coverage`
    (`rasterise`) is given: the centreline, 8-connected and 1 px wide, plus every pixel the wire
    covers at least half. A sub-pixel wire is a connected 1-px line; a wider one is as wide as
    it is drawn (a 1-px wire straddling two pixels marks both)."""
    mask = (coverage >= 0.5).astype(np.uint8)
    pts = np.round(segments_px * (1 << _SHIFT)).astype(np.int32)
    cv2.polylines(mask, list(pts), False, 1, 1, cv2.LINE_8, _SHIFT)
    return mask
