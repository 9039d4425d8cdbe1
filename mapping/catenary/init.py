"""Initial catenary hypotheses inside the view frustum of the reference keyframe (3.3.3, 3.4.1).

The thesis starts from a (possibly bad) hypothesis; here the hypotheses come from the data:
the wire pixels of view 0 (where its distance field is zero) give an image line (principal
axis), which is back-projected at depths sampled within the wire depth prior (the 4-20 m of
4.4.3) into straight-ish catenaries. Ranked by their cost (eq. 3.13) over all views, they
seed the fit, so every initialisation lies inside view 0's frustum.
"""

from __future__ import annotations

import numpy as np

from mapping.catenary.jacobian import Projection, project_catenary
from mapping.catenary.model import catenary_points_ned_m, sample_abscissae_m
from mapping.catenary.params import CatenaryParams
from mapping.catenary.residuals import CatenaryViews, points_in_cameras_m
from mapping.catenary.uncertainty import inverse_depth_from_theta, theta_from_inverse_depth

SCORING_POINTS = 20


def wire_pixel_axis_px(distance_field: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """(anchor `(2,)`, unit direction `(2,)`, half length) of a view's wire pixels, px (u, v).

    The anchor is the wire pixel nearest to the centroid (on the wire even when it curves);
    the direction is the principal axis; the half length is two standard deviations along it.
    """
    flat = np.flatnonzero(distance_field.reshape(-1) == 0.0)
    uv = np.stack((flat % distance_field.shape[1], flat // distance_field.shape[1]), axis=1)
    uv = uv.astype(float)
    centroid = uv.mean(axis=0)
    _, singular_values, axes = np.linalg.svd(uv - centroid, full_matrices=False)
    anchor = uv[np.argmin(np.linalg.norm(uv - centroid, axis=1))]
    half_length_px = 2.0 * singular_values[0] / np.sqrt(max(len(uv), 1))
    return anchor, axes[0], max(half_length_px, 1.0)


def seed_hypotheses(
    views: CatenaryViews, params: CatenaryParams, depth_near_m: float, depth_far_m: float
) -> np.ndarray:
    """`(K, 5)` Theta hypotheses back-projected from view 0 at K depths in [near, far], m."""
    depths_m = np.geomspace(depth_near_m, depth_far_m, params.init_depth_samples)
    return np.array([wire_axis_hypothesis(views, d, params.init_sag_m) for d in depths_m])


def wire_axis_hypothesis(views: CatenaryViews, depth_m: float, sag_m: float) -> np.ndarray:
    """`(5,)` Theta along view 0's wire pixels back-projected at `depth_m`, with sag `sag_m`.

    The vertex is the anchor pixel of `wire_pixel_axis_px` at that depth; the yaw is that of
    the line joining the back-projected ends of the pixel axis.
    """
    anchor, direction, half_length_px = wire_pixel_axis_px(views.distance_fields[0])
    ends = [
        theta_from_inverse_depth(
            np.array([*(anchor + sign * half_length_px * direction), 1.0 / depth_m, 0, 1]), views
        )[:3]
        for sign in (-1.0, 1.0)
    ]
    yaw_rad = float(np.arctan2(ends[1][1] - ends[0][1], ends[1][0] - ends[0][0]))
    return theta_from_inverse_depth(np.array([*anchor, 1.0 / depth_m, yaw_rad, sag_m]), views)


HOP_DEPTH_FACTORS = (0.5, 1.0, 2.0)
HOP_YAW_OFFSETS_RAD = (0.0, np.pi / 4, -np.pi / 4, np.pi / 2)
HOP_SAGS_M = (20.0, 1000.0)


def hop_hypotheses(
    views: CatenaryViews, params: CatenaryParams, theta: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(`(K, 5)` hypotheses around a fit, `(L, 5)` re-anchored ones) for basin hopping (3.3.3).

    The vertex stays on its ray through view 0 (so every hypothesis stays inside that frustum)
    at half, the same or twice its inverse depth; the yaw turns by 0, +-45 or 90 degrees; the
    sag a is kept or set to a curved or a near-straight value. The fit itself is left out.
    Besides, the fit is re-anchored on the data: `wire_axis_hypothesis` at half, the same and
    twice the view-0 depth of the fitted sample that projects nearest to view 0's wire
    anchor pixel, with the fit's sag, so a fit that slid off the wire can come back to it.
    Both empty if the vertex is behind view 0.
    """
    rotation, translation = views.rotation_cam_from_world[0], views.translation_cam_from_world_m[0]
    if (rotation @ theta[:3] + translation)[2] <= params.min_depth_m:
        return np.empty((0, 5)), np.empty((0, 5))
    psi = inverse_depth_from_theta(theta, views)
    grid = np.array(
        [
            (factor, yaw, sag)
            for factor in HOP_DEPTH_FACTORS
            for yaw in HOP_YAW_OFFSETS_RAD
            for sag in (theta[4], *HOP_SAGS_M)
        ]
    )
    grid = grid[~((grid[:, 0] == 1.0) & (grid[:, 1] == 0.0) & (grid[:, 2] == theta[4]))]
    hypotheses = np.tile(psi, (len(grid), 1))
    hypotheses[:, 2] *= grid[:, 0]
    hypotheses[:, 3] += grid[:, 1]
    hypotheses[:, 4] = np.clip(grid[:, 2], params.sag_min_m, params.sag_max_m)
    around = [theta_from_inverse_depth(h, views) for h in hypotheses]
    anchor_depth_m = _depth_at_wire_anchor_m(views, params, theta)
    anchored = [
        wire_axis_hypothesis(views, anchor_depth_m / factor, float(theta[4]))
        for factor in HOP_DEPTH_FACTORS
        if params.min_depth_m < anchor_depth_m / factor < params.max_depth_m
    ]
    return np.array(around), np.array(anchored).reshape(-1, 5)


def _depth_at_wire_anchor_m(
    views: CatenaryViews, params: CatenaryParams, theta: np.ndarray
) -> float:
    """View-0 depth of the sample of Theta in front of view 0 that projects nearest to the wire
    anchor pixel of `wire_pixel_axis_px`, m; NaN if no sample is in front of view 0."""
    x_cat_m = sample_abscissae_m(params.half_span_m, params.points_per_curve)
    points_cam_m = points_in_cameras_m(views, catenary_points_ned_m(theta, x_cat_m))[0]
    in_front = points_cam_m[:, 2] > params.min_depth_m
    if not in_front.any():
        return float("nan")
    uv_px, depth_m = views.camera.project(points_cam_m[in_front])
    anchor, _, _ = wire_pixel_axis_px(views.distance_fields[0])
    return float(depth_m[np.argmin(np.linalg.norm(uv_px - anchor, axis=1))])


def ranked_hypotheses(
    views: CatenaryViews, params: CatenaryParams, hypotheses: np.ndarray
) -> np.ndarray:
    """`(K, 5)` hypotheses by increasing cost f (eq. 3.13), scored on `SCORING_POINTS` samples."""
    x_cat_m = sample_abscissae_m(params.half_span_m, min(SCORING_POINTS, params.points_per_curve))
    gate_px = params.extrapolation_gate_px
    costs = [
        _cost(project_catenary(theta, x_cat_m, views, params.min_depth_m, gate_px))
        for theta in hypotheses
    ]
    return hypotheses[np.argsort(costs)]


def _cost(projection: Projection) -> float:
    """f = r^T r / 2 (eq. 3.13)."""
    return 0.5 * float(np.sum(projection.residuals**2))
