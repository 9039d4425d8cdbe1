"""Wires seen by a pinhole camera: anti-aliased, sub-pixel coverage, depth and the true mask.

A wire is a tube of radius r around a polyline; its image is a line `2 r f / z` px wide
(thinner with distance). Segments are clipped to the near plane and split where their depth
changes by more than 25 %, so the width follows the distance along them. Coverage is drawn
supersampled with each line's integral equal to its width, so a 0.2 px wire is a faint line
whose pixels add up to 20 % of one pixel, at its sub-pixel position. Depth per pixel is a
z-buffer of points sampled every half pixel along the wires, spread to the wire's coverage by
the nearest sample (distance transform). The true mask is the training labels' rule
(`labels.label_mask`: the centreline plus every pixel covered at least half).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from geometry.camera import PinholeCamera
from geometry.pose import Pose
from hil.sensors.raycast import NEAR_M
from hil.world.model import World
from perception.training.labels import label_mask

_SHIFT = 4  # fixed-point fractional bits of OpenCV drawing coordinates
_MAX_DEPTH_RATIO = 1.25
_SAMPLE_PX = 0.5
_LIMIT_PX = 2.0e5


@dataclass(frozen=True, slots=True)
class WireLayer:
    """The wires of one image, before occlusion by the scene; all `(H, W)`.

    coverage: float32 in [0, 1], the anti-aliased share of each pixel the wires cover.
    label: bool, the true wire mask (see module docstring).
    depth_m: float32 camera-z depth of the nearest wire, inf where no wire is near.
    width_px: float32 apparent width of that wire, px (0 where none).
    wire: int32 its index in `world.wires` (-1 where none).
    tangent_ned: `(H, W, 3) float32` its direction in the world (zero where none).
    """

    coverage: np.ndarray
    label: np.ndarray
    depth_m: np.ndarray
    width_px: np.ndarray
    wire: np.ndarray
    tangent_ned: np.ndarray


def _camera_segments(
    world: World, camera_from_world: Pose
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """All wire segments in the camera frame, near-clipped and split by depth ratio.

    Returns `a (N, 3)`, `b (N, 3)` camera-frame ends, `wire (N,)` indices and world
    `tangent (N, 3)`.
    """
    ends_a, ends_b, ids, tangents = [], [], [], []
    for k, wire in enumerate(world.wires):
        points = wire.points_ned_m
        pc = camera_from_world.apply(points)
        a, b = pc[:-1], pc[1:]
        keep = (a[:, 2] > NEAR_M) | (b[:, 2] > NEAR_M)
        if not keep.any():
            continue
        step = np.diff(points, axis=0)[keep]
        ends_a.append(a[keep])
        ends_b.append(b[keep])
        ids.append(np.full(int(keep.sum()), k))
        tangents.append(step / np.maximum(np.linalg.norm(step, axis=1, keepdims=True), 1e-12))
    if not ends_a:
        empty = np.zeros((0, 3))
        return empty, empty, np.zeros(0, int), empty
    a, b = np.concatenate(ends_a), np.concatenate(ends_b)
    wire_ids, tangent = np.concatenate(ids), np.concatenate(tangents)
    for p, q in ((a, b), (b, a)):
        behind = p[:, 2] <= NEAR_M
        s = (NEAR_M - p[behind, 2]) / (q[behind, 2] - p[behind, 2])
        p[behind] = p[behind] + s[:, None] * (q[behind] - p[behind])
    ratio = np.maximum(a[:, 2], b[:, 2]) / np.minimum(a[:, 2], b[:, 2])
    pieces = np.clip(np.ceil(np.log(ratio) / np.log(_MAX_DEPTH_RATIO)), 1, 64).astype(int)
    if pieces.max() > 1:
        seg = np.repeat(np.arange(len(a)), pieces)
        first = np.repeat(np.cumsum(pieces) - pieces, pieces)
        k = (np.arange(len(seg)) - first)[:, None]
        n = pieces[seg][:, None]
        a, b = a[seg] + (b[seg] - a[seg]) * k / n, a[seg] + (b[seg] - a[seg]) * (k + 1) / n
        wire_ids, tangent = wire_ids[seg], tangent[seg]
    return a, b, wire_ids, tangent


def _coverage(
    segments_px: np.ndarray, widths_px: np.ndarray, h: int, w: int, supersampling: int
) -> np.ndarray:
    """`(H, W) float32` anti-aliased coverage of `(N, 2, 2)` segments `widths_px` wide, the
    integral across each line equal to its width (sub-pixel widths included).

    Drawn supersampled (OpenCV's thick lines are odd widths, thickness t > 1 drawing t + 1
    samples), each segment at the smallest odd width covering its own, weighted by true /
    drawn width, then area-averaged.
    """
    s = supersampling
    canvas = np.zeros((h * s, w * s), np.float32)
    drawn = np.maximum(2 * np.ceil((widths_px * s - 1) / 2) + 1, 1).astype(np.int64)
    level = np.round(widths_px * s / drawn * 64).astype(np.int64)  # weight in 1/64 steps
    pts = np.round((segments_px * s + (s - 1) / 2) * (1 << _SHIFT)).astype(np.int32)
    thickness = np.where(drawn == 1, 1, drawn - 1)
    groups = np.unique(np.stack([level, thickness], axis=1), axis=0)
    for weight, t in groups:  # ascending weight: overlaps keep the heavier
        chosen = (level == weight) & (thickness == t)
        cv2.polylines(canvas, list(pts[chosen]), False, weight / 64, int(t), cv2.LINE_8, _SHIFT)
    small = cv2.resize(canvas, (w, h), interpolation=cv2.INTER_AREA)
    return np.minimum(small, 1.0)


def project_wires(
    world: World, camera: PinholeCamera, world_from_cam: Pose, supersampling: int
) -> WireLayer:
    """Draw every wire of `world` seen from `world_from_cam` (see module docstring)."""
    h, w = camera.shape
    a, b, wire_ids, tangent = _camera_segments(world, world_from_cam.inverse())
    none = WireLayer(
        np.zeros((h, w), np.float32),
        np.zeros((h, w), bool),
        np.full((h, w), np.inf, np.float32),
        np.zeros((h, w), np.float32),
        np.full((h, w), -1, np.int32),
        np.zeros((h, w, 3), np.float32),
    )
    if not len(a):
        return none
    uv_a = np.clip(camera.project(a)[0], -_LIMIT_PX, _LIMIT_PX)
    uv_b = np.clip(camera.project(b)[0], -_LIMIT_PX, _LIMIT_PX)
    lo, hi = np.minimum(uv_a, uv_b), np.maximum(uv_a, uv_b)
    radius = np.array([wire.radius_m for wire in world.wires])[wire_ids]
    width = 2.0 * radius * camera.fx_px / (0.5 * (a[:, 2] + b[:, 2]))
    margin = 2.0 + width / 2
    inside = (hi[:, 0] > -margin) & (lo[:, 0] < w + margin)
    inside &= (hi[:, 1] > -margin) & (lo[:, 1] < h + margin)
    if not inside.any():
        return none
    a, b, uv_a, uv_b = a[inside], b[inside], uv_a[inside], uv_b[inside]
    wire_ids, tangent, width = wire_ids[inside], tangent[inside], width[inside]
    segments = np.stack([uv_a, uv_b], axis=1)
    coverage = _coverage(segments, width, h, w, supersampling)
    label = label_mask(segments, coverage).astype(bool)
    # z-buffer of points every half pixel along each segment
    length = np.linalg.norm(uv_b - uv_a, axis=1)
    counts = np.minimum(np.ceil(length / _SAMPLE_PX).astype(int) + 1, 4 * (w + h))
    seg = np.repeat(np.arange(len(a)), counts)
    first = np.repeat(np.cumsum(counts) - counts, counts)
    t = ((np.arange(len(seg)) - first) / np.maximum(counts[seg] - 1, 1))[:, None]
    points = a[seg] + t * (b[seg] - a[seg])
    uv, z = camera.project(points)
    col, row = np.rint(uv[:, 0]).astype(np.int64), np.rint(uv[:, 1]).astype(np.int64)
    ok = (col >= 0) & (col < w) & (row >= 0) & (row < h)
    pixel, z, seg = row[ok] * w + col[ok], z[ok], seg[ok]
    order = np.lexsort((z, pixel))
    pixel, z, seg = pixel[order], z[order], seg[order]
    first_of_pixel = np.ones(len(pixel), bool)
    first_of_pixel[1:] = pixel[1:] != pixel[:-1]
    pixel, z, seg = pixel[first_of_pixel], z[first_of_pixel], seg[first_of_pixel]
    if not len(pixel):
        return none
    near = (coverage > 0) | label
    rows_near, cols_near = np.flatnonzero(near.any(axis=1)), np.flatnonzero(near.any(axis=0))
    depth = np.full((h, w), np.inf, np.float32)
    widths = np.zeros((h, w), np.float32)
    wires = np.full((h, w), -1, np.int32)
    tangents = np.zeros((h, w, 3), np.float32)
    if len(rows_near):
        # nearest sample of every pixel near a wire, within the wires' bounding rectangle
        r0, r1 = rows_near[0], rows_near[-1] + 1
        c0, c1 = cols_near[0], cols_near[-1] + 1
        row_s, col_s = pixel // w, pixel % w
        inside = (row_s >= r0) & (row_s < r1) & (col_s >= c0) & (col_s < c1)
        seeds = np.full((r1 - r0, c1 - c0), 255, np.uint8)
        seeds[row_s[inside] - r0, col_s[inside] - c0] = 0
        if inside.any():
            _, labels = cv2.distanceTransformWithLabels(
                seeds, cv2.DIST_L2, 3, labelType=cv2.DIST_LABEL_PIXEL
            )
            # DIST_LABEL_PIXEL numbers the seeds 1.. in raster order, the order of `pixel`
            window = (slice(r0, r1), slice(c0, c1))
            sub = near[window]
            nearest = labels[sub] - 1
            z_in, seg_in = z[inside], seg[inside]
            chosen = seg_in[nearest]
            depth[window][sub] = z_in[nearest]
            widths[window][sub] = width[chosen]
            wires[window][sub] = wire_ids[chosen]
            tangents[window][sub] = tangent[chosen]
    return WireLayer(coverage, label, depth, widths, wires, tangents)
