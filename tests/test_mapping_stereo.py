"""SGBM disparity and sigma calibration on rendered stereo pairs (thesis 4.4.2)."""

import numpy as np
import pytest

from geometry.camera import body_from_camera_mount, stereo_rig_from_params
from geometry.pose import Pose
from geometry.shapes import Box
from hil.sensors.cameras import SimulatedStereoCamera
from hil.sensors.params import CameraSimParams
from hil.world.model import Checkerboard, Solid, World
from mapping.droan.calibration import (
    corner_depths_m,
    find_corners,
    fit_disparity_sigma,
    sample_disparity,
)
from mapping.droan.params import MappingParams
from mapping.droan.stereo import disparity_from_pair, sgbm_matcher

PARAMS = MappingParams()
RIG = stereo_rig_from_params(PARAMS.camera)
MOUNT = body_from_camera_mount([0.0, 0.0, 0.0])
VEHICLE = Pose.from_yaw_pitch_roll(0.0, 0.0, 0.0, [0.0, 0.0, -5.0])


def test_sgbm_recovers_the_depth_of_a_textured_wall() -> None:
    wall_m = 6.0
    world = World(solids=[Solid(Box([wall_m, -10.0, -10.0], [wall_m + 1.0, 10.0, 0.0]))])
    left, right = SimulatedStereoCamera(
        world, RIG, MOUNT, CameraSimParams(), colour_downscale=1
    ).render_pair(VEHICLE)
    disparity = disparity_from_pair(sgbm_matcher(PARAMS.stereo, 128), left, right)
    centre = disparity[100:380, 200:600]
    assert np.isfinite(centre).mean() > 0.95
    depth = RIG.depth_from_disparity(np.nanmedian(centre))
    assert depth == pytest.approx(wall_m, rel=0.03)
    # the left border, where the search range leaves the image, stays invalid (NaN)
    assert np.isnan(disparity[:, :100]).all()


@pytest.mark.parametrize("injected_px", [0.23, 0.4])
def test_sigma_calibration_recovers_the_injected_noise(injected_px: float) -> None:
    measured, expected = [], []
    inner = (8, 5)
    for k, distance_m in enumerate([2.0, 2.5, 3.0, 3.5]):
        board = Checkerboard(distance_m, -0.45, -5.3, (9, 6), 0.1)
        # corners are found in the disparity camera's own image: colour at full resolution
        sensor = CameraSimParams(disparity_noise_px=injected_px)
        camera = SimulatedStereoCamera(
            World(boards=[board]), RIG, MOUNT, sensor, colour_downscale=1
        )
        for shot in range(4):
            frame = camera.render(k + 0.1 * shot, VEHICLE)
            corners = find_corners(frame.image_bgr.mean(axis=2).astype(np.uint8), inner)
            assert corners is not None
            depths = corner_depths_m(RIG, corners, inner, board.square_m)
            assert np.median(depths) == pytest.approx(distance_m, rel=0.02)
            measured.append(sample_disparity(frame.disparity_px, corners))
            expected.append(RIG.disparity_from_depth(depths))
    fit = fit_disparity_sigma(np.concatenate(measured), np.concatenate(expected))
    assert fit.samples == 16 * 40
    assert fit.sigma_px == pytest.approx(injected_px, rel=0.12)
    assert abs(fit.bias_px) < 0.1


def test_device_disparity_fixed_point_and_zero_policy() -> None:
    from mapping.droan.stereo import disparity_from_device

    raw = np.array([[0, 8, 100]], np.uint16)
    np.testing.assert_allclose(disparity_from_device(raw, 3, False), [[0.0, 1.0, 12.5]])
    strict = disparity_from_device(raw, 3, True)
    assert np.isnan(strict[0, 0]) and strict[0, 2] == 12.5
