"""Initial catenary hypotheses inside the view frustum of the reference keyframe (3.3.3, 3.4.1).

The thesis starts from a (possibly bad) hypothesis; here the hypotheses come from the data:
the wire pixels of view 0 (where its distance field is zero) give an image line (principal
axis), which is back-projected at depths sampled within the wire depth prior (the 4-20 m of
4.4.3) into straight-ish catenaries. Ranked by their cost (eq. 3.13) over all views, they
seed the fit, so every initialisation lies inside view 0's frustum.
"""

from __future__ import annotations

import numpy as np

from mapping.catenary_jacobian import Projection, project_catenary
from mapping.catenary_model import sample_abscissae_m
from mapping.catenary_params import CatenaryParams
from mapping.catenary_residuals import CatenaryViews
from mapping.catenary_uncertainty import theta_from_inverse_depth

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
    anchor, direction, half_length_px = wire_pixel_axis_px(views.distance_fields[0])
    seeds = []
    for depth_m in np.geomspace(depth_near_m, depth_far_m, params.init_depth_samples):
        ends = [
            theta_from_inverse_depth(
                np.array([*(anchor + sign * half_length_px * direction), 1.0 / depth_m, 0, 1]),
                views,
            )[:3]
            for sign in (-1.0, 1.0)
        ]
        yaw_rad = float(np.arctan2(ends[1][1] - ends[0][1], ends[1][0] - ends[0][0]))
        seeds.append(
            theta_from_inverse_depth(
                np.array([*anchor, 1.0 / depth_m, yaw_rad, params.init_sag_m]), views
            )
        )
    return np.array(seeds)


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
