"""Residuals (eq. 3.4, 3.5) and the analytic Jacobian (eq. 3.14-3.32) against finite differences."""

import numpy as np
import pytest

from mapping.catenary.jacobian import project_catenary, residual_jacobian
from mapping.catenary.kernel import residuals_and_jacobian
from mapping.catenary.model import sample_abscissae_m
from mapping.catenary.residuals import distance_lookup, normalised_distance_transform
from mapping.catenary.sim import random_scenario, sim_camera
from mapping.catenary.uncertainty import (
    inverse_depth_from_theta,
    theta_from_inverse_depth,
    theta_jacobian_wrt_inverse_depth,
)

CAMERA = sim_camera()
MIN_DEPTH_M = 0.1


@pytest.fixture(scope="module")
def views():
    scenario = random_scenario(np.random.default_rng(3), CAMERA, 4, "random", False, 5.0)
    return scenario.views(CAMERA), scenario.theta_true


def test_distance_transform_is_zero_on_wire_and_normalised_by_the_diagonal() -> None:
    mask = np.zeros((30, 40), bool)
    mask[10, :] = True
    field = normalised_distance_transform(mask)
    assert field[10].max() == 0.0
    np.testing.assert_allclose(field[20, 5] * np.hypot(30, 40), 10.0, rtol=1e-3)
    with pytest.raises(ValueError):
        normalised_distance_transform(np.zeros((5, 5), bool))


def test_extrapolation_outside_the_image_is_continuous_and_follows_eq_3_4() -> None:
    mask = np.zeros((30, 40), bool)
    mask[:, 7] = True
    fields = normalised_distance_transform(mask)[None]
    diag = np.hypot(30, 40)
    uv = np.array([[[39.0 - 1e-9, 12.0], [39.0 + 1e-9, 12.0], [45.0, 12.0], [45.0, -4.0]]])
    value, _ = distance_lookup(fields, uv)
    assert abs(value[0, 0] - value[0, 1]) < 1e-9  # continuous across the border
    boundary = fields[0, 12, 39]
    np.testing.assert_allclose(value[0, 2], boundary + 6.0 / diag, rtol=1e-6)
    np.testing.assert_allclose(value[0, 3], fields[0, 0, 39] + np.hypot(6.0, 4.0) / diag, rtol=1e-6)


@pytest.mark.parametrize("exit_gate_px", [None, 3.0])
def test_pixel_gradient_matches_finite_differences_inside_and_outside(exit_gate_px) -> None:
    rng = np.random.default_rng(1)
    mask = np.zeros((30, 40), bool)
    mask[12:14, 5:35] = True
    fields = normalised_distance_transform(mask)[None]
    uv = np.concatenate(
        (rng.uniform([1, 1], [38, 28], (20, 2)), rng.uniform([-30, -30], [70, 60], (20, 2)))
    )
    uv = uv[(np.abs(uv - np.round(uv)) > 1e-3).all(axis=1)][None]  # off the interpolant's kinks
    if exit_gate_px is not None:  # and off the kink where phi saturates
        boundary = distance_lookup(fields, np.clip(uv, 0, [39, 29]))[0] * np.hypot(30, 40)
        uv = uv[:, np.abs(boundary[0] - exit_gate_px) > 1e-3]
    _, grad = distance_lookup(fields, uv, exit_gate_px)
    for axis in range(2):
        step = np.zeros(2)
        step[axis] = 1e-6
        plus = distance_lookup(fields, uv + step, exit_gate_px)[0]
        minus = distance_lookup(fields, uv - step, exit_gate_px)[0]
        np.testing.assert_allclose(grad[..., axis], (plus - minus) / 2e-6, atol=1e-7)


def test_leaving_the_image_where_the_wire_leaves_costs_nothing_with_the_exit_gate() -> None:
    mask = np.zeros((30, 40), bool)
    mask[12:14, :] = True  # a wire crossing the whole image
    fields = normalised_distance_transform(mask)[None]
    beyond = np.array([[[60.0, 12.5], [60.0, 25.0]]])
    thesis, _ = distance_lookup(fields, beyond)
    gated, _ = distance_lookup(fields, beyond, 3.0)
    assert thesis[0, 0] > 0.3 and gated[0, 0] == 0.0  # on the wire's way out
    np.testing.assert_allclose(gated[0, 1], thesis[0, 1])  # elsewhere: eq. 3.4


@pytest.mark.parametrize("offset", [np.zeros(5), np.array([0.4, -0.3, 0.2, 0.1, 5.0])])
def test_analytic_jacobian_matches_finite_differences(views, offset) -> None:
    catenary_views, theta_true = views
    theta = theta_true + offset
    x_cat = sample_abscissae_m(5.0, 50)
    projection = project_catenary(theta, x_cat, catenary_views, MIN_DEPTH_M)
    jac = residual_jacobian(theta, x_cat, catenary_views, projection, MIN_DEPTH_M)
    steps = np.array([1e-6, 1e-6, 1e-6, 1e-8, 1e-5])
    for k in range(5):
        step = np.zeros(5)
        step[k] = steps[k]
        plus = project_catenary(theta + step, x_cat, catenary_views, MIN_DEPTH_M).residuals
        minus = project_catenary(theta - step, x_cat, catenary_views, MIN_DEPTH_M).residuals
        numeric = ((plus - minus) / (2 * steps[k])).reshape(-1)
        # The bilinear interpolant has kinks on pixel lines: compare where both sides agree.
        smooth = np.abs(numeric - jac[:, k]) <= 1e-6 + 1e-4 * np.abs(numeric)
        assert smooth.mean() > 0.97, f"parameter {k}"
        assert np.abs(jac[:, k]).max() > 0.0


@pytest.mark.parametrize("exit_gate_px", [None, 3.0])
@pytest.mark.parametrize("case", ["on_wire", "off_wire", "behind_camera"])
def test_compiled_kernel_gives_the_numpy_residuals_and_jacobian(views, case, exit_gate_px):
    catenary_views, theta_true = views
    theta = theta_true + (np.array([0.4, -0.3, 0.2, 0.1, 5.0]) if case == "off_wire" else 0.0)
    if case == "behind_camera":  # the vertex 2 m behind view 0: clamped depths, off the image
        rotation = catenary_views.rotation_cam_from_world[0]
        centre = -rotation.T @ catenary_views.translation_cam_from_world_m[0]
        theta[:3] = centre - 2.0 * rotation.T @ np.array([0.0, 0.0, 1.0])
    x_cat = sample_abscissae_m(5.0, 50)
    projection = project_catenary(theta, x_cat, catenary_views, MIN_DEPTH_M, exit_gate_px)
    jac = residual_jacobian(theta, x_cat, catenary_views, projection, MIN_DEPTH_M)
    residuals, kernel_jac = residuals_and_jacobian(
        theta, x_cat, catenary_views, MIN_DEPTH_M, exit_gate_px
    )
    assert projection.clamped.any() == (case == "behind_camera")
    np.testing.assert_allclose(residuals, projection.residuals.reshape(-1), rtol=0, atol=1e-12)
    np.testing.assert_allclose(kernel_jac, jac, rtol=1e-9, atol=1e-12)


def test_inverse_depth_round_trip_and_its_jacobian(views) -> None:
    catenary_views, theta_true = views
    psi = inverse_depth_from_theta(theta_true, catenary_views)
    np.testing.assert_allclose(theta_from_inverse_depth(psi, catenary_views), theta_true, atol=1e-9)
    jac = theta_jacobian_wrt_inverse_depth(psi, catenary_views)
    steps = np.array([1e-4, 1e-4, 1e-7, 1e-6, 1e-4])
    for k in range(5):
        step = np.zeros(5)
        step[k] = steps[k]
        numeric = (
            theta_from_inverse_depth(psi + step, catenary_views)
            - theta_from_inverse_depth(psi - step, catenary_views)
        ) / (2 * steps[k])
        np.testing.assert_allclose(jac[:, k], numeric, rtol=1e-5, atol=1e-8)
