"""Fitting the disparity noise sigma from checkerboard corners of known depth (4.4.2).

As in the thesis: a checkerboard is placed in front of the rectified stereo camera, its corners
are found in the left image, the disparity image is sampled at each corner and compared with
the disparity of the corner's known depth (eq. 4.1); a Gaussian fitted to the errors gives
sigma. The depth of each corner comes from the board's pose (solvePnP with the known square
size), or from a known board distance for a fronto-parallel board.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from geometry.camera import StereoRig


@dataclass(frozen=True, slots=True)
class SigmaFit:
    """Gaussian fit of disparity errors: sigma and bias (mean error) in px, sample count."""

    sigma_px: float
    bias_px: float
    samples: int
    rejected: int


def find_corners(left_gray: np.ndarray, inner_corners: tuple[int, int]) -> np.ndarray | None:
    """`(K, 2)` sub-pixel inner-corner pixels of a checkerboard, or None if not found."""
    found, corners = cv2.findChessboardCorners(left_gray, inner_corners)
    if not found:
        return None
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3)
    corners = cv2.cornerSubPix(left_gray, corners, (5, 5), (-1, -1), criteria)
    return corners.reshape(-1, 2).astype(np.float64)


def corner_depths_m(
    rig: StereoRig, corners_px: np.ndarray, inner_corners: tuple[int, int], square_m: float
) -> np.ndarray:
    """`(K,)` camera-z depths of the corners from the board pose (solvePnP), m."""
    cols, rows = inner_corners
    j, i = np.mgrid[0:rows, 0:cols]
    board = np.stack([i.ravel(), j.ravel(), np.zeros(i.size)], axis=1) * square_m
    ok, rvec, tvec = cv2.solvePnP(
        board, corners_px, rig.camera.intrinsic_matrix(), None, flags=cv2.SOLVEPNP_IPPE
    )
    if not ok:
        raise ValueError("solvePnP failed on the checkerboard corners")
    rotation, _ = cv2.Rodrigues(rvec)
    return (board @ rotation.T + tvec.reshape(1, 3))[:, 2]


def sample_disparity(disparity_px: np.ndarray, corners_px: np.ndarray) -> np.ndarray:
    """`(K,)` disparity at the corner pixels (nearest pixel), px; NaN where invalid."""
    h, w = disparity_px.shape
    u = np.clip(np.floor(corners_px[:, 0] + 0.5).astype(int), 0, w - 1)
    v = np.clip(np.floor(corners_px[:, 1] + 0.5).astype(int), 0, h - 1)
    return disparity_px[v, u].astype(np.float64)


def fit_disparity_sigma(measured_px: np.ndarray, expected_px: np.ndarray) -> SigmaFit:
    """Gaussian fit (mean, std) of `measured - expected` disparity errors, px.

    Invalid samples (NaN) are dropped; gross outliers (mismatches) beyond 5 robust sigmas
    (1.4826 MAD around the median) are rejected before the fit.
    """
    errors = np.asarray(measured_px, float) - np.asarray(expected_px, float)
    errors = errors[np.isfinite(errors)]
    if errors.size < 2:
        raise ValueError("need at least two valid disparity samples")
    median = np.median(errors)
    robust = 1.4826 * np.median(np.abs(errors - median))
    keep = np.abs(errors - median) <= 5.0 * max(robust, 1e-6)
    inliers = errors[keep]
    return SigmaFit(
        float(np.std(inliers, ddof=1)),
        float(np.mean(inliers)),
        int(inliers.size),
        int(errors.size - inliers.size),
    )
