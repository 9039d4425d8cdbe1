"""The solver's hot path: residuals and analytic Jacobian of one hypothesis in one compiled pass.

`residuals_and_jacobian` evaluates the chain Theta -> P_W -> P_C -> p -> r of eq. 3.6 and its
derivative dr/dTheta (eq. 3.14: dr/dp of eq. 3.17, dp/dP_C of eq. 3.21, R_ext of eq. 3.23,
dP_W/dTheta of eq. 3.30) for every (view, sample) pair in registers, where the numpy form
(`catenary_jacobian.project_catenary` + `residual_jacobian`, which define the arithmetic and
serve everything off the hot path) builds a few dozen (N, M) temporaries per evaluation.
A test holds the two to the same numbers; `wireavoid bench catenary` measures the fit.
"""

from __future__ import annotations

import numba
import numpy as np

from mapping.catenary.residuals import CatenaryViews


@numba.njit(cache=True, nogil=True, error_model="numpy", boundscheck=False)
def _kernel(
    theta: np.ndarray,
    x_cat_m: np.ndarray,
    rotation: np.ndarray,
    translation: np.ndarray,
    fields: np.ndarray,
    intrinsics: np.ndarray,
    min_depth_m: float,
    exit_gate_px: float,
) -> tuple[np.ndarray, np.ndarray]:
    """(N, M) residuals and (N, M, 5) dr/dTheta; exit_gate_px <= 0 means phi = 1 (eq. 3.4)."""
    fx, fy, cx, cy = intrinsics[0], intrinsics[1], intrinsics[2], intrinsics[3]
    n_views, height, width = fields.shape
    n_points = x_cat_m.size
    diagonal = np.sqrt(height * height + width * width)
    x_v, y_v, z_v, psi, a = theta[0], theta[1], theta[2], theta[3], theta[4]
    cos_psi, sin_psi = np.cos(psi), np.sin(psi)
    residuals = np.empty((n_views, n_points))
    jacobian = np.empty((n_views, n_points, 5))
    for j in range(n_points):
        x_cat = x_cat_m[j]
        t = x_cat / a
        half_sinh = np.sinh(0.5 * t)
        world = (x_v + x_cat * cos_psi, y_v + x_cat * sin_psi, z_v - 2.0 * a * half_sinh**2)
        sag_slope = t * np.sinh(t) - 2.0 * half_sinh**2  # -dz_W/da (eq. 3.30, NED)
        for i in range(n_views):
            r = rotation[i]
            pc_x = r[0, 0] * world[0] + r[0, 1] * world[1] + r[0, 2] * world[2] + translation[i, 0]
            pc_y = r[1, 0] * world[0] + r[1, 1] * world[1] + r[1, 2] * world[2] + translation[i, 1]
            pc_z = r[2, 0] * world[0] + r[2, 1] * world[1] + r[2, 2] * world[2] + translation[i, 2]
            clamped = pc_z < min_depth_m  # eq. 3.18: depth clamped, no derivative in depth
            inv_z = 1.0 / max(pc_z, min_depth_m)
            live_inv_z = 0.0 if clamped else inv_z
            u = fx * pc_x * inv_z + cx
            v = fy * pc_y * inv_z + cy
            # eq. 3.4-3.5 and 3.17: bilinear inside, continuous extrapolation outside
            u_b = min(max(u, 0.0), width - 1.0)
            v_b = min(max(v, 0.0), height - 1.0)
            u0 = min(int(u_b), width - 2)
            v0 = min(int(v_b), height - 2)
            fu = u_b - u0
            fv = v_b - v0
            field = fields[i]
            d00, d01 = field[v0, u0], field[v0, u0 + 1]
            d10, d11 = field[v0 + 1, u0], field[v0 + 1, u0 + 1]
            slope_top = d01 - d00
            slope_bottom = d11 - d10
            top = d00 + fu * slope_top
            bottom = d10 + fu * slope_bottom
            boundary = top + fv * (bottom - top)
            du = u - u_b
            dv = v - v_b
            outside = np.sqrt(du * du + dv * dv)
            grad_u = slope_top + fv * (slope_bottom - slope_top) if du == 0.0 else 0.0
            grad_v = bottom - top if dv == 0.0 else 0.0
            phi = 1.0
            if exit_gate_px > 0.0:
                ramp = boundary * (diagonal / exit_gate_px)
                phi = min(ramp, 1.0)
                if ramp < 1.0:
                    grad_u *= 1.0 + outside / exit_gate_px
                    grad_v *= 1.0 + outside / exit_gate_px
            residuals[i, j] = boundary + phi * outside / diagonal
            if outside > 0.0:
                scale = phi / outside / diagonal
                grad_u += du * scale
                grad_v += dv * scale
            # dr/dP_W = dr/du du/dP_W + dr/dv dv/dP_W (eq. 3.21, 3.23)
            gu = grad_u * fx * inv_z
            gv = grad_v * fy * inv_z
            xz = pc_x * live_inv_z
            yz = pc_y * live_inv_z
            g0 = gu * (r[0, 0] - xz * r[2, 0]) + gv * (r[1, 0] - yz * r[2, 0])
            g1 = gu * (r[0, 1] - xz * r[2, 1]) + gv * (r[1, 1] - yz * r[2, 1])
            g2 = gu * (r[0, 2] - xz * r[2, 2]) + gv * (r[1, 2] - yz * r[2, 2])
            jac = jacobian[i, j]
            jac[0] = g0
            jac[1] = g1
            jac[2] = g2
            jac[3] = x_cat * (cos_psi * g1 - sin_psi * g0)
            jac[4] = g2 * sag_slope
    return residuals, jacobian


def residuals_and_jacobian(
    theta: np.ndarray,
    x_cat_m: np.ndarray,
    views: CatenaryViews,
    min_depth_m: float,
    exit_gate_px: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """`(N M,)` residuals r (eq. 3.4) and `(N M, 5)` J = dr/dTheta (eq. 3.14) of Theta `(5,)`.

    The same numbers as `project_catenary(...).residuals` and `residual_jacobian(...)`.
    exit_gate_px: off-image extrapolation, see `catenary_residuals.distance_lookup`.
    """
    camera = views.camera
    residuals, jacobian = _kernel(
        np.asarray(theta, dtype=np.float64),
        np.asarray(x_cat_m, dtype=np.float64),
        views.rotation_cam_from_world,
        views.translation_cam_from_world_m,
        views.distance_fields,
        np.array([camera.fx_px, camera.fy_px, camera.cx_px, camera.cy_px]),
        float(min_depth_m),
        -1.0 if exit_gate_px is None else float(exit_gate_px),
    )
    return residuals.reshape(-1), jacobian.reshape(-1, 5)
