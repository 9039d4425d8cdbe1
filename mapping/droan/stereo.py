"""Disparity from a rectified stereo pair with OpenCV SGBM (thesis 4.4.2).

The OAK-D computes disparity on the camera; this is the path for plain stereo pairs. Output
follows the disparity convention of `mapping.droan.expansion`: `float32 (H, W)` px, NaN where the
matcher found no valid match (including the left border where the search range leaves the
image, and speckles removed by the speckle filter), 0 for a match at zero shift.
"""

from __future__ import annotations

import cv2
import numpy as np

from mapping.droan.params import StereoMatchParams


def sgbm_matcher(params: StereoMatchParams, max_disparity_px: int) -> cv2.StereoSGBM:
    """OpenCV SGBM in its 3-way mode (the fastest here) with speckle filtering."""
    block = params.block_size_px | 1
    channels = 1
    return cv2.StereoSGBM_create(
        minDisparity=0,
        numDisparities=int(np.ceil(max_disparity_px / 16) * 16),
        blockSize=block,
        P1=8 * channels * block * block,
        P2=32 * channels * block * block,
        disp12MaxDiff=1,
        uniquenessRatio=params.uniqueness_ratio_pct,
        speckleWindowSize=params.speckle_window_px,
        speckleRange=int(np.ceil(params.speckle_range_px)),
        mode=cv2.StereoSGBM_MODE_SGBM_3WAY,
    )


def disparity_from_pair(
    matcher: cv2.StereoSGBM, left_gray: np.ndarray, right_gray: np.ndarray
) -> np.ndarray:
    """`(H, W) float32` disparity (px, NaN invalid) of rectified `uint8` grey images."""
    raw = matcher.compute(left_gray, right_gray)  # int16, disparity * 16, invalid < 0
    disparity = raw.astype(np.float32) / 16.0
    disparity[raw < 0] = np.nan
    return disparity


def disparity_from_device(
    raw: np.ndarray, subpixel_fraction_bits: int, zero_is_invalid: bool
) -> np.ndarray:
    """`(H, W) float32` disparity (px) from a camera's fixed-point disparity (OAK-D: uint8, or
    uint16 with 3-5 sub-pixel bits).

    The device reports 0 both for "no match" and for "nothing within range" (sky): with
    `zero_is_invalid` those pixels become NaN (unknown), otherwise 0 (no return, free out to the
    sensing range when `MappingParams.no_return_is_free`).
    """
    disparity = np.asarray(raw).astype(np.float32) / np.float32(1 << subpixel_fraction_bits)
    if zero_is_invalid:
        disparity[raw == 0] = np.nan
    return disparity
