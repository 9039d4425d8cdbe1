"""Residuals and the analytic Jacobian of a catenary hypothesis (thesis Fig. 3.5, eq. 3.14-3.32).

The chain Theta -> P_W -> P_C -> p -> r (eq. 3.6) is evaluated once, vectorised over N views
and M samples; the Jacobian is the product of its factors (eq. 3.14):
dr/dp (eq. 3.17) . dp/dP_C (eq. 3.21) . dP_C/dP_W = R_ext (eq. 3.23) . dP_W/dTheta (eq. 3.30).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mapping.catenary.model import catenary_points_ned_m, chain_through_points
from mapping.catenary.residuals import (
    CatenaryViews,
    clamped_pixels_px,
    distance_lookup,
    points_in_cameras_m,
)


@dataclass(frozen=True, slots=True)
class Projection:
    """A catenary hypothesis seen by N views.

    points_ned_m: `(M, 3)` curve samples, NED world, m.
    points_cam_m: `(N, M, 3)` the samples in each camera frame, m.
    uv_px: `(N, M, 2)` their pixels (depth clamped, see `clamped_pixels_px`).
    clamped: `(N, M) bool`, True where the sample is behind / too close to the camera.
    residuals: `(N, M)` r_i^j (eq. 3.4), normalised by the image diagonal.
    residual_grad: `(N, M, 2)` dr/dp (eq. 3.17), per pixel.
    """

    points_ned_m: np.ndarray
    points_cam_m: np.ndarray
    uv_px: np.ndarray
    clamped: np.ndarray
    residuals: np.ndarray
    residual_grad: np.ndarray


def project_catenary(
    theta: np.ndarray,
    x_cat_m: np.ndarray,
    views: CatenaryViews,
    min_depth_m: float,
    exit_gate_px: float | None = None,
) -> Projection:
    """Evaluate the chain of eq. 3.6 for Theta `(5,)` at abscissae `(M,)`, m.

    exit_gate_px: off-image extrapolation, see `distance_lookup` (None: eq. 3.4).
    """
    points_ned_m = catenary_points_ned_m(theta, x_cat_m)
    points_cam_m = points_in_cameras_m(views, points_ned_m)
    uv_px, clamped = clamped_pixels_px(views, points_cam_m, min_depth_m)
    residuals, grad = distance_lookup(views.distance_fields, uv_px, exit_gate_px)
    return Projection(points_ned_m, points_cam_m, uv_px, clamped, residuals, grad)


def _pixel_gradients_wrt_points(
    views: CatenaryViews, projection: Projection, min_depth_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """`(N, M, 3)` du/dP_W and dv/dP_W: rows of eq. 3.21 times R_ext (eq. 3.23).

    du/dP_W = fx/z (R[0] - x/z R[2]), dv/dP_W = fy/z (R[1] - y/z R[2]); where the depth is
    clamped (`Projection.clamped`) the depth column of eq. 3.21 is zero.
    """
    camera = views.camera
    points = projection.points_cam_m
    inv_z = 1.0 / np.maximum(points[..., 2], min_depth_m)
    live_inv_z = np.where(projection.clamped, 0.0, inv_z)
    rotation = views.rotation_cam_from_world[:, None, :, :]
    depth_row = rotation[..., 2, :]
    du_dpw = (camera.fx_px * inv_z)[..., None] * (
        rotation[..., 0, :] - (points[..., 0] * live_inv_z)[..., None] * depth_row
    )
    dv_dpw = (camera.fy_px * inv_z)[..., None] * (
        rotation[..., 1, :] - (points[..., 1] * live_inv_z)[..., None] * depth_row
    )
    return du_dpw, dv_dpw


def pixel_jacobian(
    theta: np.ndarray,
    x_cat_m: np.ndarray,
    views: CatenaryViews,
    projection: Projection,
    min_depth_m: float,
) -> np.ndarray:
    """`(N, M, 2, 5)` dp/dTheta = dp/dP_C (eq. 3.21) R_ext (eq. 3.23) dP_W/dTheta (eq. 3.30)."""
    du_dpw, dv_dpw = _pixel_gradients_wrt_points(views, projection, min_depth_m)
    dp_dtheta = chain_through_points(np.stack((du_dpw, dv_dpw), axis=1), theta, x_cat_m)
    return dp_dtheta.transpose(0, 2, 1, 3)


def residual_jacobian(
    theta: np.ndarray,
    x_cat_m: np.ndarray,
    views: CatenaryViews,
    projection: Projection,
    min_depth_m: float,
) -> np.ndarray:
    """`(N M, 5)` J = dr/dTheta (eq. 3.14): dr/dp (eq. 3.17) dp/dP_W, then dP_W/dTheta."""
    du_dpw, dv_dpw = _pixel_gradients_wrt_points(views, projection, min_depth_m)
    grad = projection.residual_grad
    dr_dpw = grad[..., 0, None] * du_dpw + grad[..., 1, None] * dv_dpw
    return chain_through_points(dr_dpw, theta, x_cat_m).reshape(-1, 5)
