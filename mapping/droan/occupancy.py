"""Occupancy inference in disparity space (thesis 4.4.4, 4.4.5): confidence, Table 4.1, eq. 4.5.

The numpy functions are elementwise over arrays of any (broadcastable) shape and define the
inference; `summed_costs` is the planner's hot path, the same arithmetic compiled (numba) into
one pass per pose-graph node that gathers each pair's pixel, costs it and sums it in
registers, without the dozen (nodes x points) temporaries of the numpy form (about 2x faster,
`wireavoid bench mapping`); a test holds the two to the same answers. Disparities in px.
"""

from __future__ import annotations

import numba
import numpy as np


def confidence(disparity_px: np.ndarray, sigma_px: float) -> np.ndarray:
    """C(d) = (d - sigma) / d (eq. 4.4), clipped to [0, 1]; 0 where d <= sigma."""
    d = np.asarray(disparity_px, dtype=np.float32)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.clip((d - sigma_px) / d, 0.0, 1.0)


def confidence_odds(disparity_px: np.ndarray, sigma_px: float) -> np.ndarray:
    """C / (1 - C) = (d - sigma) / sigma, the occupied cost of Table 4.1; 0 where d <= sigma."""
    d = np.asarray(disparity_px, dtype=np.float32)
    return np.maximum(d - np.float32(sigma_px), 0.0) / np.float32(sigma_px)


def stereo_occupancy_cost(
    disparity_px: np.ndarray,
    front_px: np.ndarray,
    back_px: np.ndarray,
    own_front_px: np.ndarray,
    own_back_px: np.ndarray,
    sigma_px: float,
    free_discount: float,
    occluded_discount: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Table 4.1 cost occ(d_s) of a state at disparity d_s seen by one node, and whether the
    node observed it directly (not unknown, not occluded).

    front/back and own_front/own_back: the node's two bands at the state's pixel
    (`mapping.droan.expansion.ExpandedImage`); front < 0 is unknown (cost 0).
    Occupied (inside a band): C/(1-C); safe (in front of the first band, or between the bands):
    -free_discount C/(1-C); potentially safe (behind the last band, occluded):
    -occluded_discount C/(1-C) (the thesis uses the same 0.5 as for safe; 0 makes occlusion
    carry no evidence).
    """
    d = disparity_px
    # in-place steps: this runs on (nodes x points) arrays in the planner's hot path
    occupied = d <= front_px
    occupied &= d >= back_px
    in_own = d <= own_front_px
    in_own &= d >= own_back_px
    occupied |= in_own
    observed = d >= own_back_px
    sign = np.where(observed, np.float32(-free_discount), np.float32(-occluded_discount))
    cost = np.where(occupied, np.float32(1), sign)
    cost *= confidence_odds(d, sigma_px)
    known = front_px >= 0
    cost *= known
    observed &= known
    return cost, observed


def wire_occupancy_cost(
    disparity_px: np.ndarray,
    front_px: np.ndarray,
    back_px: np.ndarray,
    free_weight: float,
    near_px: float,
    possible_front_px: np.ndarray | None = None,
    possible_back_px: np.ndarray | None = None,
) -> np.ndarray:
    """Wire cost: C(d) with sigma = 0 (= 1) inside the wire slab [d_b, d_f], -free_weight
    elsewhere in view (4.4.5 note); 0 where the node has no wire observation (front < 0).

    Beyond the thesis: 0 also inside the slab of the pixels the detector did not rule out as
    wire (`possible_front_px`/`possible_back_px`, front <= 0 where none; `DroanMap.insert`'s
    `possible_mask`): a view whose CNN scored a wire 0.5-0.95 there does not vote it away.

    Beyond the thesis: 0 also nearer than the slab's front `near_px` (the near prior, 4.4.3,
    C-space expanded). The prior places a seen wire beyond 4 m so that it is avoided early,
    not because nearer space is known free of it: a vehicle passing a wire has it nearer than
    that, and its own views would otherwise vote the wire away as it passes (strikes at 0.1 m).
    """
    known = (front_px >= 0) & (disparity_px <= near_px)
    occupied = known & (disparity_px <= front_px) & (disparity_px >= back_px) & (front_px > 0)
    if possible_front_px is not None and possible_back_px is not None:
        known &= ~(
            (possible_front_px > 0)
            & (disparity_px <= possible_front_px)
            & (disparity_px >= possible_back_px)
        )
    return np.where(occupied, np.float32(1), np.where(known, -np.float32(free_weight), 0.0))


def occupancy_measure(costs: np.ndarray, axis: int = 0) -> np.ndarray:
    """M = max(sum over nodes of occ(d_s), 0) (eq. 4.5)."""
    return np.maximum(np.sum(costs, axis=axis, dtype=np.float32), 0.0)


@numba.njit(cache=True, nogil=True, error_model="numpy", boundscheck=False)
def summed_costs(
    points: np.ndarray,
    projection: np.ndarray,
    offset: np.ndarray,
    slots: np.ndarray,
    images: np.ndarray,
    height: int,
    width: int,
    bf_px_m: np.float32,
    min_depth_m: np.float32,
    max_range_m: np.float32,
    sigma_px: np.float32,
    free_discount: np.float32,
    occluded_discount: np.float32,
    wire_free_weight: np.float32,
    wire_near_px: np.float32,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(M_stereo, M_wire `(N,) float32`, seen `(N,) bool`) of `(N, 3) float32` world points
    over the nodes `slots`: `stereo_occupancy_cost`, `wire_occupancy_cost` and
    `occupancy_measure` fused.

    Each M = max(sum over nodes of occ, 0) (eq. 4.5); the map's M is their max. A pair
    counts only if the point is in the node's view: depth in (min_depth_m, max_range_m],
    inside the image. Node s projects with `projection[s]` (K R_cw) and `offset[s]` (K t_cw);
    its pixels are rows `s * height * width + v * width + u` of `images`, channels (front,
    back, own_front, own_back, wire_front, wire_back, possible_front, possible_back).
    """
    n = points.shape[0]
    stereo_sum = np.zeros(n, np.float32)
    wire_sum = np.zeros(n, np.float32)
    seen = np.zeros(n, np.bool_)
    rows = np.empty(n, np.int64)  # per node: the pair's pixel row, or -1 out of view
    disparity = np.empty(n, np.float32)
    zero, one, half = np.float32(0.0), np.float32(1.0), np.float32(0.5)
    for slot in slots:
        k = projection[slot]
        t = offset[slot]
        base = np.int64(slot) * height * width
        # pass 1: projection (branch-free, so it vectorises)
        for j in range(n):
            x, y, z_w = points[j, 0], points[j, 1], points[j, 2]
            z = k[2, 0] * x + k[2, 1] * y + k[2, 2] * z_w + t[2]
            inv_z = one / max(z, min_depth_m)  # a point on the camera plane stays finite
            u = (k[0, 0] * x + k[0, 1] * y + k[0, 2] * z_w + t[0]) * inv_z + half
            v = (k[1, 0] * x + k[1, 1] * y + k[1, 2] * z_w + t[1]) * inv_z + half
            in_view = (z > min_depth_m) & (z <= max_range_m)
            in_view &= (u >= zero) & (u < width) & (v >= zero) & (v < height)
            u_px = np.int64(min(max(u, zero), np.float32(width - 1)))  # int() is 4x slower
            v_px = np.int64(min(max(v, zero), np.float32(height - 1)))
            rows[j] = base + v_px * width + u_px if in_view else -1
            disparity[j] = bf_px_m * inv_z
        # pass 2: gather and Table 4.1 / 4.4.5 costs, summed per point
        for j in range(n):
            row = rows[j]
            if row < 0:
                continue
            d = disparity[j]
            front = images[row, 0]
            if front >= zero:  # stereo_occupancy_cost
                own_back = images[row, 3]
                observed = d >= own_back
                odds = max(d - sigma_px, zero) / sigma_px
                if (images[row, 1] <= d <= front) or (own_back <= d <= images[row, 2]):
                    stereo_sum[j] += odds
                else:
                    stereo_sum[j] -= (free_discount if observed else occluded_discount) * odds
                seen[j] |= observed
            wire_front = images[row, 4]
            if wire_front >= zero and d <= wire_near_px:  # wire_occupancy_cost
                if wire_front > zero and images[row, 5] <= d <= wire_front:
                    wire_sum[j] += one
                elif not (images[row, 6] > zero and images[row, 7] <= d <= images[row, 6]):
                    wire_sum[j] -= wire_free_weight
    return np.maximum(stereo_sum, zero), np.maximum(wire_sum, zero), seen
