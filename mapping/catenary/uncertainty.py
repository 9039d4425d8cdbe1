"""Inverse-depth parameterisation and covariance of a catenary fit (thesis 3.7.2, eq. 3.33-3.40).

Psi = (u_v, v_v, d_v, psi, a) (eq. 3.33): the vertex as pixel (u_v column, v_v row, px) and
inverse depth d_v (1/m) in the reference keyframe C_1, plus the world yaw and sag of Theta.

The covariance follows eq. 3.39-3.40 with one change that makes it meaningful for a distance
transform: at convergence D_i is flat (zero) on the wire, so dr/dp carries no information
there. Each observed sample is instead linearised as a point-to-curve measurement: its pixel
moves only along the normal n of the projected curve with 1-sigma `pixel_sigma_px` (or half
the view's wire width, within which D_i is zero, or the view's RMS misfit, if larger), giving
one row n^T dp/dPsi / sigma per (view, sample), each view's rows weighted as a few
independent samples since one curve's errors are correlated. Tangential slip is
unobservable, exactly the degeneracy of Fig. 3.10 (wire parallel to the baseline), which
then shows as a huge condition number and per-point sigma instead of a wrong, confident
answer.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mapping.catenary.jacobian import Projection, pixel_jacobian
from mapping.catenary.model import catenary_points_jacobian, catenary_tangents
from mapping.catenary.residuals import CatenaryViews


def inverse_depth_from_theta(theta: np.ndarray, views: CatenaryViews) -> np.ndarray:
    """Psi `(5,)` of Theta w.r.t. view 0 (eq. 3.33); the vertex must be in front of it."""
    camera = views.camera
    vertex_cam = (
        views.rotation_cam_from_world[0] @ theta[:3] + views.translation_cam_from_world_m[0]
    )
    if vertex_cam[2] <= 0.0:
        raise ValueError("the catenary vertex is behind the reference keyframe")
    inv_depth = 1.0 / vertex_cam[2]
    u = camera.fx_px * vertex_cam[0] * inv_depth + camera.cx_px
    v = camera.fy_px * vertex_cam[1] * inv_depth + camera.cy_px
    return np.array([u, v, inv_depth, theta[3], theta[4]])


def theta_from_inverse_depth(psi: np.ndarray, views: CatenaryViews) -> np.ndarray:
    """Theta `(5,)` of Psi: undo the projection (eq. 3.34) and the extrinsics (eq. 3.36)."""
    vertex_cam = views.camera.back_project(psi[:2], 1.0 / psi[2])
    rotation_cw = views.rotation_cam_from_world[0]
    vertex_ned = rotation_cw.T @ (vertex_cam - views.translation_cam_from_world_m[0])
    return np.concatenate((vertex_ned, psi[3:]))


def theta_jacobian_wrt_inverse_depth(psi: np.ndarray, views: CatenaryViews) -> np.ndarray:
    """`(5, 5)` J_{Psi->Theta} = dTheta/dPsi: R_ext^T (eq. 3.37) times eq. 3.35, and I_2."""
    camera = views.camera
    u, v, inv_depth = psi[:3]
    dpc = np.array(
        [
            [
                1.0 / (camera.fx_px * inv_depth),
                0.0,
                -(u - camera.cx_px) / (camera.fx_px * inv_depth**2),
            ],
            [
                0.0,
                1.0 / (camera.fy_px * inv_depth),
                -(v - camera.cy_px) / (camera.fy_px * inv_depth**2),
            ],
            [0.0, 0.0, -1.0 / inv_depth**2],
        ]
    )
    jac = np.eye(5)
    jac[:3, :3] = views.rotation_cam_from_world[0].T @ dpc
    return jac


@dataclass(frozen=True, slots=True)
class FitUncertainty:
    """First-order uncertainty of a fitted catenary.

    covariance_theta: `(5, 5)` Sigma_Theta (eq. 3.40); inf on the diagonal when singular.
    condition_number: of the Jacobi-scaled information matrix J^T J (scale-free).
    point_sigma_m: `(M,)` sqrt of the largest eigenvalue of each sample's 3x3 covariance
        across the curve (the linearised catenary, 3.7.2; motion along the tangent does not
        move the wire), m; inf when singular.
    observed: `(M,) bool`, samples that land within the gate of a wire pixel in >= 1 view.
    """

    covariance_theta: np.ndarray
    condition_number: float
    point_sigma_m: np.ndarray
    observed: np.ndarray


def curve_normals_px(uv_px: np.ndarray) -> np.ndarray:
    """`(N, M, 2)` unit normals of the projected curves along the sample axis (0 if degenerate)."""
    tangent = np.gradient(uv_px, axis=1)
    normal = np.stack((-tangent[..., 1], tangent[..., 0]), axis=-1)
    length = np.linalg.norm(normal, axis=-1, keepdims=True)
    return np.where(length > 1e-9, normal / np.where(length > 1e-9, length, 1.0), 0.0)


def fit_uncertainty(
    theta: np.ndarray,
    x_cat_m: np.ndarray,
    views: CatenaryViews,
    projection: Projection,
    theta_jac_wrt_solved: np.ndarray,
    min_depth_m: float,
    pixel_sigma_px: float,
    observation_gate_px: float,
    slip_sigma_m: float,
    samples_per_view: float,
) -> FitUncertainty:
    """Sigma of the solved parameters (eq. 3.39), mapped to Theta (eq. 3.40) and to points.

    theta_jac_wrt_solved: `(5, 5)` dTheta/dx of the solved parameters x (identity for Theta,
    `theta_jacobian_wrt_inverse_depth` for Psi).
    slip_sigma_m: prior 1-sigma of the vertex sliding along the wire (`_slip_prior`), m.
    samples_per_view: independent samples one view's curve is worth (errors along one
        projected curve are correlated, so M samples do not shrink sigma by sqrt(M)).
    """
    _, height_px, width_px = views.distance_fields.shape
    u = projection.uv_px[..., 0]
    v = projection.uv_px[..., 1]
    inside = (u >= 0) & (u <= width_px - 1) & (v >= 0) & (v <= height_px - 1)
    near_wire = projection.residuals * views.diagonal_px <= observation_gate_px
    observed = inside & near_wire & ~projection.clamped
    dp_dtheta = pixel_jacobian(theta, x_cat_m, views, projection, min_depth_m)
    dp_dsolved = dp_dtheta @ theta_jac_wrt_solved
    normals = curve_normals_px(projection.uv_px)
    rows = np.einsum("nmi,nmip->nmp", normals, dp_dsolved) * observed[..., None]
    # Samples of one view share their errors (segmentation width, pixel grid, calibration):
    # each view counts as `samples_per_view` independent samples, not as M.
    # A misfit larger than the assumed noise inflates it (reduced chi-square, per view).
    misfit_px = np.sqrt(
        np.sum((projection.residuals * views.diagonal_px) ** 2 * inside, axis=1)
        / np.maximum(inside.sum(axis=1), 1)
    )
    sigma_px = np.maximum.reduce(
        [np.full(views.n_views, pixel_sigma_px), 0.5 * views.wire_width_px, misfit_px]
    )
    weight = samples_per_view / np.maximum(observed.sum(axis=1), 1) / sigma_px**2
    information = np.einsum("nmp,nmq,n->pq", rows, rows, weight)
    information += _slip_prior(theta, theta_jac_wrt_solved, slip_sigma_m)
    n_rows = int(observed.sum())
    scale = np.sqrt(np.diag(information))
    if n_rows < 5 or np.any(scale <= 0.0):
        return _singular(x_cat_m.size, observed.any(axis=0))
    eigenvalues = np.linalg.eigvalsh(information / np.outer(scale, scale))
    condition_number = float(eigenvalues[-1] / max(eigenvalues[0], 1e-300))
    if eigenvalues[0] <= 1e-14:
        return _singular(x_cat_m.size, observed.any(axis=0), condition_number)
    covariance_solved = np.linalg.inv(information)
    covariance_theta = theta_jac_wrt_solved @ covariance_solved @ theta_jac_wrt_solved.T
    point_jac = catenary_points_jacobian(theta, x_cat_m)
    across = np.eye(3) - np.einsum("mi,mj->mij", *(2 * [catenary_tangents(theta, x_cat_m)]))
    point_jac = across @ point_jac
    point_cov = point_jac @ covariance_theta @ point_jac.transpose(0, 2, 1)
    point_sigma_m = np.sqrt(np.maximum(np.linalg.eigvalsh(point_cov)[:, -1], 0.0))
    return FitUncertainty(covariance_theta, condition_number, point_sigma_m, observed.any(axis=0))


def _slip_prior(
    theta: np.ndarray, theta_jac_wrt_solved: np.ndarray, slip_sigma_m: float
) -> np.ndarray:
    """`(5, 5)` prior information on the vertex sliding along the wire's horizontal direction.

    For a near-straight wire that slide is a symmetry (the curve maps onto itself), so J^T J
    is singular without harming the curve's geometry; a weak prior (the vertex lies within
    `slip_sigma_m` of where the fit put it) removes that gauge freedom and only that one.
    """
    slide_theta = np.array([np.cos(theta[3]), np.sin(theta[3]), 0.0, 0.0, 0.0])
    metric = theta_jac_wrt_solved.T @ np.outer(slide_theta, slide_theta) @ theta_jac_wrt_solved
    return metric / slip_sigma_m**2


def _singular(
    n_points: int, observed: np.ndarray, condition_number: float = np.inf
) -> FitUncertainty:
    """The uncertainty of an unobservable fit: infinite everywhere."""
    return FitUncertainty(
        np.diag(np.full(5, np.inf)), condition_number, np.full(n_points, np.inf), observed
    )
