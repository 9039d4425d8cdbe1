"""Several wires at once (thesis 3.7.3): instances per keyframe, association, one fit each.

1. Each keyframe's binarised segmentation is split into wire instances: 8-connected
   components, merged when they continue each other's image curve (gaps of missed
   detections), minus speckle and blobs (`wire_instances`).
2. Instances are associated keyframe to keyframe by reprojection, as 3.7.3 suggests for the
   avoidance scenario: pixels of an instance in the previous keyframe are back-projected at
   a sweep of depths (tracing their epipolar lines), projected into the next keyframe and
   scored by their distance to each instance there (its distance transform, extrapolated
   off-image by eq. 3.4); each pixel's best depth counts, and the cost is their lower quartile. A
   minimum-cost assignment with a gate of `association_gate_px` links instances into
   tracks; unmatched ones start tracks.
3. Each track with at least two keyframes is fitted on its own instance masks, so parallel
   wires never share a distance transform (the local minimum between them, 3.7.3).

Known limit: two wires crossing in an image form one connected component and one instance.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from itertools import combinations, pairwise

import cv2
import numpy as np
from scipy.optimize import linear_sum_assignment

from geometry.camera import PinholeCamera
from geometry.pose import Pose
from mapping.catenary.fit import CatenaryFit, reconstruct_catenary
from mapping.catenary.params import CatenaryParams
from mapping.catenary.residuals import (
    distance_lookup,
    normalised_distance_transform,
    views_from_keyframes,
)

ASSOCIATION_PIXELS = 40
ASSOCIATION_DEPTHS = 96  # fine enough that an epipolar segment steps < ~3 px
MIN_VISIBLE_FRACTION = 0.25
MIN_FRAGMENT_PIXELS = 6  # smaller components are speckle, even next to a wire
MIN_ELONGATION = 1.5  # length / width of a wire fragment, width = pixels / length
ASSOCIATION_QUANTILE = 0.25  # a quarter of the wire must be seen by both views


def wire_instances(
    wire_mask: np.ndarray, min_pixels: int, min_length_px: float, merge_gate_px: float
) -> list[np.ndarray]:
    """`(h, w) bool` masks of the wires in one binarised segmentation (3.7.3).

    Thin 8-connected components (`MIN_FRAGMENT_PIXELS`, `MIN_ELONGATION`) are merged when
    one quadratic image curve fits them together within `merge_gate_px`
    (`_merged_components`; 3.7.3 suggests polynomials), so a wire broken by missed
    detections stays one instance, end pieces included, while parallel wires stay apart;
    instances under `min_pixels` or shorter than `min_length_px` along their axis are dropped.
    """
    count, labels = cv2.connectedComponents(wire_mask.astype(np.uint8), connectivity=8)
    flat = labels.reshape(-1)
    order = np.argsort(flat, kind="stable")
    bounds = np.searchsorted(flat[order], np.arange(count + 1))
    width_px = wire_mask.shape[1]
    components = {
        k + 1: np.stack((order[a:b] % width_px, order[a:b] // width_px), axis=1).astype(float)
        for k, (a, b) in enumerate(pairwise(bounds[1:]))
        if b - a >= MIN_FRAGMENT_PIXELS
    }
    # Wire fragments are long and thin; compact blobs never join a wire.
    labels_kept = [
        k for k, uv in components.items() if _axis_length_px(uv) ** 2 >= MIN_ELONGATION * len(uv)
    ]
    pixels = [components[k] for k in labels_kept]
    instances = []
    for group in _merged_components(pixels, merge_gate_px):
        uv = np.concatenate([pixels[k] for k in group])
        if len(uv) >= min_pixels and _axis_length_px(uv) >= min_length_px:
            instances.append(np.isin(labels, [labels_kept[k] for k in group]))
    return instances


def _curve_residual_px(uv_px: np.ndarray) -> float:
    """Mean offset of pixels from one quadratic along their principal axis, px."""
    centroid = uv_px.mean(axis=0)
    _, _, axes = np.linalg.svd(uv_px - centroid, full_matrices=False)
    local = (uv_px - centroid) @ axes.T
    coefficients = np.polyfit(local[:, 0], local[:, 1], 2)
    return float(np.mean(np.abs(local[:, 1] - np.polyval(coefficients, local[:, 0]))))


def _axis_length_px(uv_px: np.ndarray) -> float:
    """Extent of pixels along their principal axis, px."""
    centroid = uv_px.mean(axis=0)
    _, _, axes = np.linalg.svd(uv_px - centroid, full_matrices=False)
    return float(np.ptp((uv_px - centroid) @ axes[0]))


def _merged_components(pixels: list[np.ndarray], gate_px: float) -> list[list[int]]:
    """Groups of components that lie on one image curve together (greedy, longest first).

    Two groups merge when the quadratic fitted to all their pixels (a catenary's image is
    close to one, 3.7.3) leaves a mean offset of at most `gate_px`, so fragments of one
    wire merge and parallel or crossing wires (or blobs) do not.
    """
    groups = [[k] for k in np.argsort([-len(p) for p in pixels])]
    merged = True
    while merged:
        merged = False
        for i, j in combinations(range(len(groups)), 2):
            a = np.concatenate([pixels[k] for k in groups[i]])
            b = np.concatenate([pixels[k] for k in groups[j]])
            if _curve_residual_px(np.concatenate((a, b))) <= gate_px:
                groups[i] = groups[i] + groups.pop(j)
                merged = True
                break
    return groups


@dataclass(slots=True)
class WireTrack:
    """One wire followed across keyframes: keyframe indices and its instance mask in each."""

    keyframe_indices: list[int] = field(default_factory=list)
    masks: list[np.ndarray] = field(default_factory=list)


def association_costs_px(
    camera: PinholeCamera,
    previous_pose: Pose,
    previous_instances: Sequence[np.ndarray],
    pose: Pose,
    instances: Sequence[np.ndarray],
    depths_m: np.ndarray,
) -> np.ndarray:
    """`(P, Q)` lower quartile over p's pixels of their closest reprojection onto q, px.

    Only pixels whose epipolar segment enters the next image count (inf when fewer than
    `MIN_VISIBLE_FRACTION` do); the quantile ignores gaps and views that share only part
    of the wire (`ASSOCIATION_QUANTILE`).
    """
    costs = np.full((len(previous_instances), len(instances)), np.inf)
    if not instances:
        return costs
    fields = np.stack([normalised_distance_transform(m) for m in instances])
    diagonal_px = float(np.hypot(*fields.shape[1:]))
    camera_from_world = pose.inverse()
    for p, mask in enumerate(previous_instances):
        rows, cols = np.nonzero(mask)
        pick = np.linspace(0, rows.size - 1, min(ASSOCIATION_PIXELS, rows.size)).astype(int)
        uv = np.stack((cols[pick], rows[pick]), axis=1).astype(float)
        rays_world = previous_pose.rotate(camera.rays(uv))
        points = previous_pose.translation_m + depths_m[:, None, None] * rays_world[None]
        points_cam = camera_from_world.apply(points.reshape(-1, 3))
        in_front = points_cam[:, 2] > 0.0
        uv_next, _ = camera.project(np.where(in_front[:, None], points_cam, 1.0))
        # Pixels whose whole epipolar segment leaves the next image carry no evidence.
        visible = (in_front & camera.contains(uv_next)).reshape(depths_m.size, -1).any(axis=0)
        if visible.mean() < MIN_VISIBLE_FRACTION:
            continue
        for q in range(len(instances)):
            distance, _ = distance_lookup(
                np.broadcast_to(fields[q], (1, *fields.shape[1:])), uv_next[None]
            )
            per_point = np.where(in_front, distance[0] * diagonal_px, np.inf)
            closest = per_point.reshape(depths_m.size, -1).min(axis=0)
            costs[p, q] = float(np.quantile(closest[visible], ASSOCIATION_QUANTILE))
    return costs


def track_wires(
    camera: PinholeCamera,
    poses: Sequence[Pose],
    instances_per_keyframe: Sequence[Sequence[np.ndarray]],
    params: CatenaryParams,
    depth_near_m: float,
    depth_far_m: float,
) -> list[WireTrack]:
    """Link instances of consecutive keyframes into wire tracks (3.7.3)."""
    # Even steps of inverse depth from the near limit to 4x the far one: along each
    # pixel's epipolar line in the next view, also beyond the wire prior.
    inverse_depths = np.linspace(1.0 / depth_near_m, 0.25 / depth_far_m, ASSOCIATION_DEPTHS)
    depths_m = 1.0 / inverse_depths
    tracks: list[WireTrack] = []
    open_tracks: list[WireTrack] = []
    for index, instances in enumerate(instances_per_keyframe):
        next_open: list[WireTrack | None] = [None] * len(instances)
        if open_tracks and instances:
            costs = association_costs_px(
                camera,
                poses[open_tracks[0].keyframe_indices[-1]],
                [t.masks[-1] for t in open_tracks],
                poses[index],
                instances,
                depths_m,
            )
            finite = np.where(np.isfinite(costs), costs, 1e9)
            for p, q in zip(*linear_sum_assignment(finite), strict=True):
                if costs[p, q] <= params.association_gate_px:
                    next_open[q] = open_tracks[p]
        for q, mask in enumerate(instances):
            track = next_open[q]
            if track is None:
                track = WireTrack()
                tracks.append(track)
                next_open[q] = track
            track.keyframe_indices.append(index)
            track.masks.append(mask)
        if instances:
            open_tracks = [t for t in next_open if t is not None]
    return tracks


def reconstruct_wires(
    camera: PinholeCamera,
    poses: Sequence[Pose],
    wire_masks: Sequence[np.ndarray],
    stamps_s: Sequence[float],
    params: CatenaryParams,
    depth_near_m: float,
    depth_far_m: float,
) -> list[CatenaryFit]:
    """One `CatenaryFit` per wire track seen in at least two keyframes (3.7.3).

    poses: world_from_camera per keyframe; wire_masks: `(h, w) bool` binarised segmentations;
    the last `max_keyframes` keyframes of each track are used.
    """
    instances = [
        wire_instances(
            m, params.instance_min_pixels, params.instance_min_length_px, params.merge_gate_px
        )
        for m in wire_masks
    ]
    tracks = track_wires(camera, poses, instances, params, depth_near_m, depth_far_m)
    fits = []
    for track in tracks:
        if len(track.keyframe_indices) < 2:
            continue
        keep = slice(-params.max_keyframes, None)
        indices = track.keyframe_indices[keep]
        views = views_from_keyframes(
            camera,
            [poses[i] for i in indices],
            track.masks[keep],
            [stamps_s[i] for i in indices],
        )
        fits.append(reconstruct_catenary(views, params, depth_near_m, depth_far_m))
    return fits
