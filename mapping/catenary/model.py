"""The 5-parameter catenary model (thesis eq. 3.1-3.3) and its derivative dP_W/dTheta (eq. 3.30).

Theta = (x_v, y_v, z_v, psi, a) as a `(5,) float64` array: the vertex (lowest point) of the
curve in the local NED world frame (m), the yaw psi of the catenary plane about the NED down
axis (rad), and the sag parameter a (m). NED is z-down, so the curve rises from the vertex
towards negative z: z_W = z_v - a (cosh(x_cat / a) - 1), the thesis' z-up eq. 3.1 mirrored.

The curve is sampled at fixed catenary-frame abscissae x_cat (the thesis' fixed width and
resolution, 3.3.1), which are the independent sample parameter: the derivative is eq. 3.30
taken at fixed x_cat (the back-substitution of eq. 3.31-3.32 is not needed).
"""

from __future__ import annotations

import numpy as np

N_THETA = 5


def sample_abscissae_m(half_span_m: float, points_per_curve: int) -> np.ndarray:
    """`(M,)` catenary-frame abscissae x_cat, evenly spaced in [-half_span, half_span], m."""
    return np.linspace(-half_span_m, half_span_m, points_per_curve)


def sag_height_m(x_cat_m: np.ndarray, a_m: float) -> np.ndarray:
    """a (cosh(x/a) - 1) of eq. 3.1, written as 2 a sinh^2(x / 2a) to stay exact for large a."""
    return 2.0 * a_m * np.sinh(x_cat_m / (2.0 * a_m)) ** 2


def catenary_points_ned_m(theta: np.ndarray, x_cat_m: np.ndarray) -> np.ndarray:
    """`(M, 3)` NED world points of the catenary Theta at abscissae `x_cat_m` (eq. 3.3, 3.27)."""
    x_v, y_v, z_v, psi, a = theta
    points = np.empty((x_cat_m.size, 3))
    points[:, 0] = x_v + x_cat_m * np.cos(psi)
    points[:, 1] = y_v + x_cat_m * np.sin(psi)
    points[:, 2] = z_v - sag_height_m(x_cat_m, a)
    return points


def catenary_points_jacobian(theta: np.ndarray, x_cat_m: np.ndarray) -> np.ndarray:
    """`(M, 3, 5)` dP_W/dTheta at fixed x_cat (eq. 3.30, NED sign for the z row)."""
    _, _, _, psi, a = theta
    t = x_cat_m / a
    jac = np.zeros((x_cat_m.size, 3, N_THETA))
    jac[:, 0, 0] = 1.0
    jac[:, 1, 1] = 1.0
    jac[:, 2, 2] = 1.0
    jac[:, 0, 3] = -x_cat_m * np.sin(psi)
    jac[:, 1, 3] = x_cat_m * np.cos(psi)
    # d/da [a (cosh t - 1)] = cosh t - 1 - t sinh t, negated because NED z points down.
    jac[:, 2, 4] = -(2.0 * np.sinh(0.5 * t) ** 2 - t * np.sinh(t))
    return jac


def chain_through_points(
    grad_wrt_points: np.ndarray, theta: np.ndarray, x_cat_m: np.ndarray
) -> np.ndarray:
    """`(..., M, 5)` g dP_W/dTheta for `(..., M, 3)` row gradients g w.r.t. the points.

    Equal to `grad_wrt_points @ catenary_points_jacobian(theta, x_cat_m)` but uses the
    sparsity of eq. 3.30 (identity block, one yaw column, one sag entry): elementwise only.
    """
    _, _, _, psi, a = theta
    t = x_cat_m / a
    out = np.empty((*grad_wrt_points.shape[:-1], N_THETA))
    out[..., :3] = grad_wrt_points
    out[..., 3] = x_cat_m * (
        np.cos(psi) * grad_wrt_points[..., 1] - np.sin(psi) * grad_wrt_points[..., 0]
    )
    out[..., 4] = grad_wrt_points[..., 2] * (t * np.sinh(t) - 2.0 * np.sinh(0.5 * t) ** 2)
    return out


def catenary_tangents(theta: np.ndarray, x_cat_m: np.ndarray) -> np.ndarray:
    """`(M, 3)` unit tangents dP_W/dx_cat of the curve, NED."""
    _, _, _, psi, a = theta
    tangents = np.empty((x_cat_m.size, 3))
    tangents[:, 0] = np.cos(psi)
    tangents[:, 1] = np.sin(psi)
    tangents[:, 2] = -np.sinh(x_cat_m / a)
    return tangents / np.linalg.norm(tangents, axis=1, keepdims=True)
