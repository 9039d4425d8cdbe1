"""Occupancy inference in disparity space (thesis 4.4.4, 4.4.5): confidence, Table 4.1, eq. 4.5.

All functions are elementwise over arrays of any (broadcastable) shape; disparities in px.
"""

from __future__ import annotations

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
    (`mapping.expansion.ExpandedImage`); front < 0 is unknown (cost 0).
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
    disparity_px: np.ndarray, front_px: np.ndarray, back_px: np.ndarray, free_discount: float
) -> np.ndarray:
    """Wire cost: C(d) with sigma = 0 (= 1) inside the wire slab [d_b, d_f], -discount elsewhere
    in view (4.4.5 note); 0 where the node has no wire observation (front < 0)."""
    known = front_px >= 0
    occupied = known & (disparity_px <= front_px) & (disparity_px >= back_px) & (front_px > 0)
    return np.where(occupied, np.float32(1), np.where(known, -np.float32(free_discount), 0.0))


def occupancy_measure(costs: np.ndarray, axis: int = 0) -> np.ndarray:
    """M = max(sum over nodes of occ(d_s), 0) (eq. 4.5)."""
    return np.maximum(np.sum(costs, axis=axis, dtype=np.float32), 0.0)
