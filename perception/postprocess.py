"""Post-processing of thesis 4.4.1: wire probability map -> binary wire-obstacle mask."""

from __future__ import annotations

import cv2
import numpy as np

from perception.params import PerceptionParams

_SURFACE_RUN_PX = 3  # surface pixels in a row that stop a continuation (not a stray return)


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


def continued_wires(
    mask: np.ndarray,
    min_length_px: float,
    max_angle_deg: float,
    factor: float,
    surface: np.ndarray | None = None,
) -> np.ndarray:
    """(H, W) bool: `mask` plus the continuation of each of its straight wire components.

    Beyond 4.4.1: a wire does not end in mid-air, so a wire the CNN finds only in part (a wire
    level with the camera is found where a tree stands behind it and missed against the tree
    line on the horizon) goes on beyond what was found. Each 8-connected component at least
    `min_length_px` long along its principal axis, within `max_angle_deg` of the image rows, is
    drawn on along that axis past both ends for `factor` times its length (clipped at the
    image border), as thick as the component is on average. `factor` 0: `mask` unchanged.

    `surface`: (H, W) bool, the pixels where stereo sees a surface (`stereo_surface`). A
    continuation stops at the first `_SURFACE_RUN_PX` surface pixels in a row: the CNN misses
    wires against the sky and the far tree line, while the long straight marks it makes on
    surfaces (shadows of poles and wires on the ground, kerbs, roof edges) continued across
    the ground would wall off the space in front of it.
    """
    mask = np.asarray(mask, dtype=bool)
    if factor <= 0 or not mask.any():
        return mask
    count, labels, stats, _ = cv2.connectedComponentsWithStats(
        mask.astype(np.uint8), connectivity=8, ltype=cv2.CV_32S
    )
    span = np.hypot(stats[:, cv2.CC_STAT_WIDTH], stats[:, cv2.CC_STAT_HEIGHT])
    candidates = [k for k in range(1, count) if span[k] >= min_length_px]
    if not candidates:
        return mask
    canvas = mask.astype(np.uint8)
    rows, cols = np.nonzero(labels)
    owner = labels[rows, cols]
    max_slope = np.tan(np.radians(max_angle_deg))
    for k in candidates:
        pts = np.stack([cols[owner == k], rows[owner == k]], axis=1).astype(np.float64)
        centre = pts.mean(axis=0)
        _, vectors = np.linalg.eigh(np.cov(pts - centre, rowvar=False))
        axis = vectors[:, 1] if vectors[0, 1] >= 0 else -vectors[:, 1]  # the principal axis
        if abs(axis[1]) > max_slope * abs(axis[0]):
            continue
        along = (pts - centre) @ axis
        length = float(along.max() - along.min())
        if length < min_length_px:
            continue
        thickness = max(1, round(len(pts) / max(length, 1.0)))
        reach = factor * length
        for end, sign in ((along.max(), 1.0), (along.min(), -1.0)):
            start = centre + end * axis
            step = sign * axis
            free = reach if surface is None else _free_reach_px(surface, start, step, reach)
            cv2.line(canvas, _px(start), _px(start + free * step), 1, thickness, cv2.LINE_8)
    return canvas.astype(bool)


def stereo_surface(disparity_px: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """(h, w) bool: the pixels of an image of `shape` (an integer down-scale of the
    disparity image, as the colour image is) where most of the disparity pixels they cover
    hold a return (> 0): a surface stereo sees, not the sky or a background beyond range
    (0) nor a texture-less area (NaN)."""
    h, w = shape
    d = np.asarray(disparity_px)
    ky, kx = d.shape[0] // h, d.shape[1] // w
    if ky < 1 or kx < 1 or d.shape[0] != ky * h or d.shape[1] != kx * w:
        raise ValueError(f"disparity {d.shape} is not an integer up-scale of {shape}")
    returns = np.nan_to_num(d, nan=0.0) > 0
    return returns.reshape(h, ky, w, kx).mean(axis=(1, 3)) >= 0.5


def _free_reach_px(surface: np.ndarray, start: np.ndarray, step: np.ndarray, reach: float) -> float:
    """How far from `start` along the unit `step` a continuation runs before the first
    `_SURFACE_RUN_PX` pixels of `surface` in a row (at most `reach`), px."""
    t = np.arange(1.0, max(reach, 0.0) + 1.0)
    if t.size < _SURFACE_RUN_PX:
        return reach  # too short to cross a run of surface
    cols = np.rint(start[0] + t * step[0]).astype(int)
    rows = np.rint(start[1] + t * step[1]).astype(int)
    inside = (cols >= 0) & (cols < surface.shape[1]) & (rows >= 0) & (rows < surface.shape[0])
    hit = np.zeros(t.shape, dtype=bool)
    hit[inside] = surface[rows[inside], cols[inside]]
    runs = np.convolve(hit, np.ones(_SURFACE_RUN_PX), mode="valid") >= _SURFACE_RUN_PX
    if not runs.any():
        return reach
    return float(t[int(np.argmax(runs))] - 1.0)


def _px(point: np.ndarray) -> tuple[int, int]:
    """An (x, y) point as the integer pixel cv2 draws to."""
    return int(np.rint(point[0])), int(np.rint(point[1]))
