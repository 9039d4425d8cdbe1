"""Post-processing of thesis 4.4.1: wire probability map -> binary wire-obstacle mask."""

from __future__ import annotations

import cv2
import numpy as np

from perception.params import PerceptionParams


def remove_small_components(binary: np.ndarray, min_px: int) -> np.ndarray:
    """(H, W) bool: `binary` without its 8-connected components of fewer than `min_px` pixels.

    The speckle filter of 4.4.1 (and the morphological filtering of the Candamo baseline,
    2.4.3). One labelling pass plus a lookup table over the labels; no per-pixel loop.
    """
    binary = np.asarray(binary, dtype=bool)
    if min_px <= 1 or not binary.any():
        return binary.copy()
    _, labels, stats, _ = cv2.connectedComponentsWithStats(
        binary.astype(np.uint8), connectivity=8, ltype=cv2.CV_32S
    )
    keep = stats[:, cv2.CC_STAT_AREA] >= min_px
    keep[0] = False  # label 0 is the background
    return keep[labels]


def wire_mask(
    prob: np.ndarray, params: PerceptionParams | None = None, threshold: float | None = None
) -> np.ndarray:
    """(H, W) bool wire-obstacle mask of an (H, W) wire probability map in [0, 1] (4.4.1).

    Pixels with confidence < `threshold` (None: `params.confidence_threshold`, 0.95 in the
    thesis) are removed, then 8-connected speckles smaller than `params.min_wire_component_px`.
    """
    params = params or PerceptionParams()
    cut = params.confidence_threshold if threshold is None else threshold
    return remove_small_components(np.asarray(prob) >= cut, params.min_wire_component_px)
