"""Classical wire baselines as score maps: the per-frame Candamo et al. (2009) baseline of
thesis 2.4.3, and an LSD line-segment baseline (issue 20), the floor a CNN must beat.

LSD baseline (``lsd_scores``): OpenCV's LSD line-segment detector (von Gioi et al. 2010) on the
grey image; each segment is drawn `lsd_baseline_width_px` wide (0: the width LSD estimates for
its line-support region) and scores min(1, length / `lsd_baseline_full_length_px`), so long
straight segments, which is what wires are, rank first; where segments overlap the longest wins.

Candamo baseline:

Edges (Canny, with the same thresholds as RGBLE's E map; the thesis used Lu et al.'s
CannyPF), morphological filtering that drops 8-connected edge components of fewer than 30
pixels, a windowed Hough transform on 4x4 subwindows, and the detected lines rasterised back
into the image. The thesis' temporal parts (optical-flow edge weighting, line tracking) are
left out, as in the thesis.

The thesis rasterises the lines 1 to 5 pixels thick and reports the best F1 and precision
over the thicknesses. Here the score of a pixel is (T + 1 - t) / T for the thinnest
thickness t in 1..T that covers it (0 for none), so thresholding the score at level
(T + 1 - t) / T gives exactly the t-pixel rasterisation: the ODS F1 of `perception.metrics`
over this score map is that best F1 over thicknesses, and the PR curve has T points.
"""

from __future__ import annotations

import itertools

import cv2
import numpy as np

from perception.params import PerceptionParams
from perception.postprocess import remove_small_components


def filtered_edges(image_rgb: np.ndarray, params: PerceptionParams) -> np.ndarray:
    """(H, W) bool Canny edges of an RGB (H, W, 3) or grey (H, W) uint8 image, without
    8-connected components smaller than `params.baseline_min_component_px` (2.4.3)."""
    image = np.ascontiguousarray(image_rgb)
    grey = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY) if image.ndim == 3 else image
    edges = cv2.Canny(grey, params.canny_low_threshold, params.canny_high_threshold) > 0
    return remove_small_components(edges, params.baseline_min_component_px)


def window_lines(edges: np.ndarray, params: PerceptionParams) -> np.ndarray:
    """(L, 2) float32 (rho_px, theta_rad) Hough lines of one subwindow, strongest first.

    Lines are in the subwindow's pixel frame (x right, y down, origin at its top-left), with
    x cos(theta) + y sin(theta) = rho; at most `baseline_max_lines_per_window` of them, each
    with at least `baseline_hough_votes_fraction` x (shorter window side) edge pixels on it.
    """
    votes = max(1, round(params.baseline_hough_votes_fraction * min(edges.shape)))
    lines = cv2.HoughLines(edges.astype(np.uint8), 1.0, np.pi / 180.0, votes)
    if lines is None:
        return np.zeros((0, 2), np.float32)
    return lines.reshape(-1, 2)[: params.baseline_max_lines_per_window]


def rasterised_lines(
    shape: tuple[int, int], lines: np.ndarray, max_thickness_px: int
) -> np.ndarray:
    """(H, W) float32 thickness-level scores of (rho, theta) lines in a window of `shape`.

    A pixel covered by the t-pixel-thick rasterisation (t = 1..T) scores (T + 1 - t) / T.
    """
    scores = np.zeros(shape, np.float32)
    if len(lines) == 0:
        return scores
    reach = 2.0 * (shape[0] + shape[1])  # far enough that cv2.line clips to the window
    rho, theta = lines[:, 0], lines[:, 1]
    cos_t, sin_t = np.cos(theta), np.sin(theta)
    x0, y0 = rho * cos_t, rho * sin_t
    p1 = np.round(np.stack([x0 - reach * sin_t, y0 + reach * cos_t], 1)).astype(np.int64)
    p2 = np.round(np.stack([x0 + reach * sin_t, y0 - reach * cos_t], 1)).astype(np.int64)
    for t in range(max_thickness_px, 0, -1):
        level = (max_thickness_px + 1 - t) / max_thickness_px
        canvas = np.zeros(shape, np.uint8)
        for a, b in zip(p1, p2, strict=True):
            cv2.line(canvas, (int(a[0]), int(a[1])), (int(b[0]), int(b[1])), 1, t)
        scores[canvas > 0] = level
    return scores


def lsd_scores(image_rgb: np.ndarray, params: PerceptionParams | None = None) -> np.ndarray:
    """(H, W) float32 wire scores in [0, 1] of the LSD line-segment baseline (module doc).

    image_rgb: RGB (H, W, 3) or grey (H, W) uint8.
    """
    params = params or PerceptionParams()
    image = np.ascontiguousarray(image_rgb)
    grey = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY) if image.ndim == 3 else image
    lines, widths, _, _ = cv2.createLineSegmentDetector(cv2.LSD_REFINE_STD).detect(grey)
    scores = np.zeros(grey.shape, np.float32)
    if lines is None:
        return scores
    ends = lines.reshape(-1, 4).astype(np.float64)
    length = np.hypot(ends[:, 2] - ends[:, 0], ends[:, 3] - ends[:, 1])
    fixed = params.lsd_baseline_width_px
    thickness = (
        np.full(len(ends), fixed) if fixed else np.maximum(1, np.round(widths.reshape(-1)))
    ).astype(int)
    score = np.minimum(1.0, length / params.lsd_baseline_full_length_px)
    pts = np.round(ends * 16).astype(np.int64)
    for i in np.argsort(length, kind="stable"):  # longest last: overlaps keep the best score
        x0, y0, x1, y1 = (int(v) for v in pts[i])
        cv2.line(scores, (x0, y0), (x1, y1), float(score[i]), int(thickness[i]), cv2.LINE_8, 4)
    return scores


def candamo_scores(image_rgb: np.ndarray, params: PerceptionParams | None = None) -> np.ndarray:
    """(H, W) float32 wire scores in [0, 1] of the per-frame Candamo baseline (2.4.3).

    image_rgb: RGB (H, W, 3) or grey (H, W) uint8. The image is cut into
    `baseline_windows` x `baseline_windows` subwindows (edges split as evenly as possible);
    each gets its own Hough transform and its lines are drawn only inside it.
    """
    params = params or PerceptionParams()
    edges = filtered_edges(image_rgb, params)
    h, w = edges.shape
    n = params.baseline_windows
    rows = np.linspace(0, h, n + 1).round().astype(int)
    cols = np.linspace(0, w, n + 1).round().astype(int)
    scores = np.zeros((h, w), np.float32)
    for r0, r1 in itertools.pairwise(rows):
        for c0, c1 in itertools.pairwise(cols):
            window = edges[r0:r1, c0:c1]
            if window.size == 0:
                continue
            lines = window_lines(window, params)
            scores[r0:r1, c0:c1] = rasterised_lines(
                window.shape, lines, params.baseline_max_thickness_px
            )
    return scores
