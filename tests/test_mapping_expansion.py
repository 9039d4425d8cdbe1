"""C-space expansion in disparity space (thesis 4.4.3, Fig. 4.2b, eq. 4.3)."""

import numpy as np
import pytest

from geometry.camera import PinholeCamera, StereoRig, stereo_rig_from_params
from mapping.droan.expansion import (
    DisparityExpander,
    back_disparity,
    expansion_lut,
    front_disparity,
)
from mapping.droan.params import MappingParams

PARAMS = MappingParams()
RIG = stereo_rig_from_params(PARAMS.camera)
BF = RIG.bf_px_m


def test_lut_is_the_exact_tangent_interval_of_the_sphere() -> None:
    camera = PinholeCamera(400.0, 400.0, 100.0, 50.0, 201, 101)
    bf, r, z = 40.0, 0.5, 4.0
    lo, hi = expansion_lut(camera, bf, r, np.array([bf / z]), axis=0)
    # on the axis: +- f tan(asin(r / z))
    half = 400.0 * np.tan(np.arcsin(r / z))
    assert hi[0, 100] - 100 == pytest.approx(half) and 100 - lo[0, 100] == pytest.approx(half)
    # off axis the interval is wider than the small-angle f r / z (conservative LUT)
    assert hi[0, 200] - lo[0, 200] > 2 * 400.0 * r / z
    # a sphere containing the camera centre covers everything
    lo, hi = expansion_lut(camera, bf, r, np.array([bf / 0.4]), axis=0)
    assert lo[0, 100] == -np.inf and hi[0, 100] == np.inf


def test_depth_expansion_is_eq_4_3() -> None:
    d = np.array([BF / 5.0], np.float32)
    assert front_disparity(d, BF, 0.5, 0.23)[0] == pytest.approx(BF / 4.5 + 0.23, rel=1e-6)
    assert back_disparity(d, BF, 0.5, 0.23)[0] == pytest.approx(BF / 5.5 - 0.23, rel=1e-6)
    assert np.isinf(front_disparity(np.array([BF / 0.4], np.float32), BF, 0.5, 0.0)[0])


def test_area_expansion_covers_the_robot_radius_around_a_point_obstacle() -> None:
    expander = DisparityExpander(RIG, PARAMS)
    disparity = np.zeros(RIG.camera.shape, np.float32)
    disparity[236:244, 316:324] = BF / 5.0  # a small obstacle at 5 m on the axis
    image = expander.expand_stereo(disparity)
    grid = expander.grid_camera
    occupied_cols = np.flatnonzero(image.front_px[60] > 0)
    # the expansion must reach r_v (+ lambda sigma) sideways at the obstacle's depth
    needed_px = RIG.camera.fx_px * np.tan(np.arcsin(0.5 / (BF / (BF / 5.0 + 0.23))))
    reach_left = (grid.cx_px - occupied_cols[0]) * PARAMS.pool_factor
    reach_right = (occupied_cols[-1] - grid.cx_px) * PARAMS.pool_factor
    assert min(reach_left, reach_right) >= needed_px + 4 - PARAMS.pool_factor
    assert max(reach_left, reach_right) <= 1.6 * needed_px + 2 * PARAMS.pool_factor
    assert image.front_px[60, 80] == pytest.approx(BF / 4.5 + 0.23, rel=1e-5)
    assert image.front_px[0, 0] == 0.0 and image.back_px[0, 0] == 0.0  # free (no return)


def test_near_obstacle_fringe_hides_the_far_surface_instead_of_bridging() -> None:
    expander = DisparityExpander(RIG, PARAMS)
    disparity = np.full(RIG.camera.shape, BF / 15.0, np.float32)  # wall at 15 m
    disparity[200:280, 300:340] = BF / 3.0  # pole at 3 m in front of it
    image = expander.expand_stereo(disparity)
    # in the pole's fringe, the band is the pole's (3 m), not 2.5 m .. 15.5 m
    fringe = (60, 73)  # grid cell right of the pole, inside its expansion
    assert image.front_px[fringe] == pytest.approx(BF / 2.5 + 0.23, rel=1e-5)
    assert image.back_px[fringe] == pytest.approx(BF / 3.5 - 0.23, rel=1e-5)
    # far from the pole the wall band is intact
    assert image.back_px[60, 150] == pytest.approx(BF / 15.5 - 0.23, rel=1e-5)


def test_invalid_pixels_are_unknown_unless_an_obstacle_expands_over_them() -> None:
    expander = DisparityExpander(RIG, PARAMS)
    disparity = np.full(RIG.camera.shape, np.nan, np.float32)
    disparity[236:244, 316:324] = BF / 5.0
    image = expander.expand_stereo(disparity)
    assert image.front_px[0, 0] < 0  # unknown
    assert image.front_px[60, 80] > 0
    strict = DisparityExpander(RIG, PARAMS.model_copy(update={"no_return_is_free": False}))
    assert strict.expand_stereo(np.zeros(RIG.camera.shape, np.float32)).front_px.max() < 0


def test_pool_factor_one_is_full_resolution() -> None:
    rig = StereoRig(PinholeCamera(100.0, 100.0, 31.5, 23.5, 64, 48), 0.1)
    expander = DisparityExpander(rig, PARAMS.model_copy(update={"pool_factor": 1}))
    image = expander.expand_stereo(np.full((48, 64), 2.0, np.float32))
    assert image.front_px.shape == (48, 64)
    assert image.front_px[24, 32] == pytest.approx(2.0 * 10 / (10 - 0.5 * 2.0) + 0.23, rel=1e-5)


def test_the_area_lut_is_looked_up_at_d_plus_lambda_sigma() -> None:
    def reach_px(sigma_multiplier: float) -> float:
        params = PARAMS.model_copy(update={"sigma_multiplier": sigma_multiplier})
        expander = DisparityExpander(RIG, params)
        disparity = np.zeros(RIG.camera.shape, np.float32)
        disparity[236:244, 316:324] = BF / 5.0
        cols = np.flatnonzero(expander.expand_stereo(disparity).front_px[60] > 0)
        return (expander.grid_camera.cx_px - cols[0]) * PARAMS.pool_factor

    def needed_px(disparity_px: float) -> float:  # the sphere's tangent at that disparity
        return RIG.camera.fx_px * np.tan(np.arcsin(PARAMS.robot_radius_m * disparity_px / BF))

    sigma = PARAMS.disparity_sigma_px
    boosted = BF / 5.0 + 10.0 * sigma  # lambda = 10: the window of an obstacle at ~3.7 m
    grows_px = needed_px(boosted) - needed_px(BF / 5.0)
    assert grows_px > 3 * PARAMS.pool_factor
    assert reach_px(10.0) >= needed_px(boosted) + 4 - PARAMS.pool_factor
    # the window widens as the LUT's disparity does (a lookup at d would not move at all)
    assert reach_px(10.0) - reach_px(0.0) >= grows_px - PARAMS.pool_factor


def test_a_wire_mask_of_a_registered_lower_resolution_camera_lands_on_the_same_cells() -> None:
    expander = DisparityExpander(RIG, PARAMS)
    full = np.zeros(RIG.camera.shape, bool)
    full[200:202, 100:500] = True  # a wire 2 px thick on the 640x480 disparity camera
    half = full[::2, ::2]  # the same wire seen by a colour camera at 320x240
    a, b = expander.expand_wire(full), expander.expand_wire(half)
    np.testing.assert_array_equal(a.front_px, b.front_px)
    np.testing.assert_array_equal(a.back_px, b.back_px)
    assert (a.front_px > 0).any()
    with pytest.raises(ValueError, match="down-scale"):
        expander.expand_wire(np.zeros((100, 100), bool))
    with pytest.raises(ValueError, match="down-scale"):  # 3 does not divide the 4x pooling
        expander.expand_wire(np.zeros((160, 213), bool))
