"""The catenary model (eq. 3.1-3.3), its derivative (eq. 3.30) and keyframe selection (3.4.2)."""

import numpy as np

from geometry.keyframes import select_keyframes
from geometry.pose import Pose
from mapping.catenary.model import (
    catenary_points_jacobian,
    catenary_points_ned_m,
    catenary_tangents,
    chain_through_points,
    sag_height_m,
    sample_abscissae_m,
)

THETA = np.array([3.0, -2.0, -10.0, 0.7, 12.0])


def test_vertex_is_the_lowest_point_and_the_curve_rises_in_ned() -> None:
    x_cat = sample_abscissae_m(5.0, 11)
    points = catenary_points_ned_m(THETA, x_cat)
    np.testing.assert_allclose(points[5], THETA[:3])
    assert np.all(points[:, 2] <= THETA[2])  # NED: up is -z
    # eq. 3.1 at the span end: a (cosh(x/a) - 1)
    assert points[0, 2] == np.float64(THETA[2] - 12.0 * (np.cosh(5.0 / 12.0) - 1.0))
    horizontal = points[-1, :2] - points[0, :2]
    np.testing.assert_allclose(np.arctan2(horizontal[1], horizontal[0]), THETA[3])


def test_sag_height_stays_exact_for_near_straight_wires() -> None:
    # cosh(x/a) - 1 cancels catastrophically for large a; the sinh form must match x^2 / 2a.
    x = np.array([1.0, 5.0])
    np.testing.assert_allclose(sag_height_m(x, 1e7), x**2 / 2e7, rtol=1e-9)


def test_points_jacobian_matches_finite_differences() -> None:
    x_cat = sample_abscissae_m(8.0, 17)
    jac = catenary_points_jacobian(THETA, x_cat)
    for k in range(5):
        step = np.zeros(5)
        step[k] = 1e-6
        numeric = (
            catenary_points_ned_m(THETA + step, x_cat) - catenary_points_ned_m(THETA - step, x_cat)
        ) / 2e-6
        np.testing.assert_allclose(jac[:, :, k], numeric, atol=1e-7)


def test_sparse_chain_equals_the_dense_product() -> None:
    x_cat = sample_abscissae_m(8.0, 9)
    grad = np.random.default_rng(0).normal(size=(4, 9, 3))
    dense = np.einsum("nmk,mkp->nmp", grad, catenary_points_jacobian(THETA, x_cat))
    np.testing.assert_allclose(chain_through_points(grad, THETA, x_cat), dense, atol=1e-12)


def test_tangents_are_unit_derivatives_along_the_curve() -> None:
    x_cat = np.array([-4.0, 0.0, 2.0])
    numeric = (
        catenary_points_ned_m(THETA, x_cat + 1e-6) - catenary_points_ned_m(THETA, x_cat - 1e-6)
    ) / 2e-6
    numeric /= np.linalg.norm(numeric, axis=1, keepdims=True)
    np.testing.assert_allclose(catenary_tangents(THETA, x_cat), numeric, atol=1e-8)


def test_keyframes_need_half_a_metre_or_eighteen_degrees() -> None:
    def pose(x_m: float, yaw_deg: float) -> Pose:
        return Pose.from_yaw_pitch_roll(np.deg2rad(yaw_deg), 0.0, 0.0, np.array([x_m, 0, 0]))

    poses = [pose(0.0, 0), pose(0.3, 0), pose(0.49, 0), pose(0.5, 0), pose(0.6, 17), pose(0.6, 19)]
    np.testing.assert_array_equal(select_keyframes(poses, 0.5, np.deg2rad(18.0)), [0, 3, 5])
