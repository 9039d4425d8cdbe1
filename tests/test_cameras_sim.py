"""The simulated cameras of the SIL harness (hil.sensors): colour, disparity, truth."""

from types import SimpleNamespace

import numpy as np
import pytest

from companion.ingest.params import CameraParams
from geometry.camera import (
    body_from_camera_from_params,
    body_from_camera_mount,
    stereo_rig_from_params,
)
from geometry.pose import Pose
from geometry.shapes import Box, Wire
from hil.sensors.cameras import SimulatedStereoCamera
from hil.sensors.params import CameraSimParams
from hil.sensors.shading import wire_glint
from hil.sensors.wires import project_wires
from hil.world.model import Checkerboard, Lighting, Solid, World
from mapping.droan.calibration import (
    corner_depths_m,
    find_corners,
    fit_disparity_sigma,
    sample_disparity,
)
from mapping.droan.params import MappingParams
from mapping.droan.pose_graph import DroanMap

PARAMS = MappingParams(camera_width_px=320, camera_height_px=240)
RIG = stereo_rig_from_params(PARAMS.camera)
MOUNT = body_from_camera_mount([0.0, 0.0, 0.0])
LEVEL = Pose.from_yaw_pitch_roll(0.0, 0.0, 0.0, [0.0, 0.0, -5.0])
BEHIND = Lighting(sun_azimuth_rad=np.pi, sun_elevation_rad=0.6, cloud_cover=0.2)  # sun south
CLEAN = dict(read_noise_dn=0.0, shot_noise_dn=0.0)


def camera(world: World, colour_downscale: int = 2, **overrides) -> SimulatedStereoCamera:
    return SimulatedStereoCamera(
        world, RIG, MOUNT, CameraSimParams(**overrides), colour_downscale=colour_downscale
    )


def wall(north_m: float, material: str = "concrete", albedo: float = 0.6) -> Solid:
    return Solid(Box([north_m, -50.0, -50.0], [north_m + 1.0, 50.0, 10.0]), albedo, material)


def test_wall_depth_disparity_noise_and_determinism() -> None:
    sim = camera(World(solids=[wall(8.0)], lighting=BEHIND), disparity_noise_px=0.3, seed=7)
    frame = sim.render(1.0, LEVEL)
    np.testing.assert_allclose(frame.depth_m, 8.0, rtol=1e-5)  # camera z, not ray length
    valid = np.isfinite(frame.disparity_px)
    assert valid.mean() > 0.9  # a textured wall: stereo matches nearly everywhere
    errors = frame.disparity_px[valid] - RIG.bf_px_m / 8.0
    assert errors.mean() == pytest.approx(0.0, abs=0.01)
    assert errors.std() == pytest.approx(0.3, rel=0.03)
    again = sim.render(1.0, LEVEL)
    np.testing.assert_array_equal(again.disparity_px, frame.disparity_px)
    np.testing.assert_array_equal(again.image_bgr, frame.image_bgr)
    later = sim.render(1.1, LEVEL)
    assert not np.array_equal(later.image_bgr, frame.image_bgr)  # fresh sensor noise
    assert not np.array_equal(np.nan_to_num(later.disparity_px), np.nan_to_num(frame.disparity_px))
    assert frame.stamp_s == 1.0


def test_colour_is_the_pooled_reference_camera_and_registered_to_it() -> None:
    wire = Wire.straight([6.0, -20.0, -6.0], [6.0, 20.0, -4.0], radius_m=0.02)
    frame = camera(World(wires=[wire], lighting=BEHIND)).render(0.0, LEVEL)
    assert frame.image_bgr.shape == (120, 160, 3) and frame.image_bgr.dtype == np.uint8
    assert frame.disparity_px.shape == (240, 320) and frame.wire_mask.shape == (240, 320)
    pooled = frame.wire_mask.reshape(120, 2, 160, 2).any(axis=(1, 3))
    overlap = (pooled & frame.image_wire_mask).sum() / frame.image_wire_mask.sum()
    assert overlap > 0.85  # the same wire pixels at both resolutions
    assert camera(World(), colour_downscale=1).render(0.0, LEVEL).image_bgr.shape == (240, 320, 3)


def test_sky_and_out_of_range_give_no_return() -> None:
    far = World(solids=[wall(60.0)], ground_down_m=1000.0, lighting=BEHIND)
    frame = camera(far, max_range_m=40.0).render(0.0, LEVEL)
    assert np.all(frame.disparity_px == 0.0)
    assert np.isfinite(frame.depth_m).all()  # the wall is there, just beyond range
    sky = camera(World(ground_down_m=1000.0, lighting=BEHIND)).render(0.0, LEVEL)
    assert np.all(sky.disparity_px == 0.0)
    assert np.isinf(sky.depth_m[:120]).all()  # above the horizon: sky


def test_texture_less_surfaces_and_the_suns_glare_are_invalid() -> None:
    plain = camera(World(solids=[wall(6.0, "plain")], lighting=BEHIND)).render(0.0, LEVEL)
    textured = camera(World(solids=[wall(6.0, "brick")], lighting=BEHIND)).render(0.0, LEVEL)
    assert np.isnan(plain.disparity_px).mean() > 0.9
    assert np.isnan(textured.disparity_px).mean() < 0.1
    # the sun low ahead over an empty plain: glare around it is invalid, the rest of the sky 0
    sun_ahead = Lighting(sun_azimuth_rad=0.0, sun_elevation_rad=0.2, cloud_cover=0.0)
    frame = camera(World(ground_down_m=1000.0, lighting=sun_ahead)).render(0.0, LEVEL)
    sun_row = round(RIG.camera.cy_px - RIG.camera.fy_px * np.tan(0.2))
    assert np.isnan(frame.disparity_px[sun_row - 2 : sun_row + 3, 157:163]).all()
    assert np.isnan(frame.disparity_px).mean() < 0.1
    assert (frame.disparity_px[:40] == 0).mean() > 0.9
    assert frame.image_bgr[sun_row // 2, 80].min() >= 250  # over-exposed in the colour image


def test_a_thin_wire_is_in_the_colour_image_but_not_in_the_disparity() -> None:
    wire = Wire.straight([6.0, -30.0, -6.0], [6.0, 30.0, -6.0], radius_m=0.01)
    world = World(wires=[wire], ground_down_m=1000.0, lighting=BEHIND, wire_albedos=[0.05])
    sim = camera(world, **CLEAN)
    frame = sim.render(0.0, LEVEL)
    colour = sim.colour_camera
    row = colour.cy_px - colour.fy_px * 1.0 / 6.0  # 1 m above the camera, 6 m ahead
    rows = np.flatnonzero(frame.image_wire_mask.any(axis=1))
    assert np.abs(rows - row).max() <= 1.0
    assert frame.image_wire_mask.any(axis=0).mean() > 0.95  # continuous across the image
    # a sub-pixel line: its darkening integrates to its width (0.37 px) times its contrast
    linear = (frame.image_bgr.astype(float).mean(axis=2) / 255.0) ** 2.2
    r = round(row)
    sky = linear[[r - 7, r - 6, r + 6, r + 7]].mean(axis=0)
    darkening = (1.0 - linear[r - 4 : r + 5] / sky).sum(axis=0)[20:140]
    width = 2 * 0.01 * colour.fx_px / 6.0
    assert 0.7 * width < np.median(darkening) < 1.1 * width
    # stereo misses it: the disparity there shows the sky behind it (no return)
    assert frame.wire_mask.any() and np.all(frame.disparity_px[frame.wire_mask] == 0.0)


def test_a_sunlit_wire_glints_brighter_than_the_sky_where_the_eye_lies_on_its_reflection_cone():
    # the reflection keeps the sun's component along the axis, reversed: on the cone, full glint
    assert wire_glint(np.array([0.5]), np.array([-0.5]), 16.0) == pytest.approx(1.0)
    assert wire_glint(np.array([0.5]), np.array([0.5]), 16.0) < 1e-4  # the mirror side: none
    wire = Wire.straight([6.0, -30.0, -6.0], [6.0, 30.0, -6.0], radius_m=0.02)
    world = World(wires=[wire], ground_down_m=1000.0, lighting=BEHIND, wire_albedos=[0.2])
    contrast = {}
    for specular in (0.0, 0.5):
        frame = camera(world, wire_specular=specular, **CLEAN).render(0.0, LEVEL)
        luma = frame.image_bgr.astype(float).mean(axis=2)
        centre = slice(luma.shape[1] // 2 - 10, luma.shape[1] // 2 + 10)  # eye on the cone
        r = int(np.argmax(frame.image_wire_mask.sum(axis=1)))  # the wire's row
        contrast[specular] = luma[r, centre].mean() - luma[[r - 3, r + 3], centre].mean()
    # measured -14 and +57 levels: matte, dark against the sky; metal in the sun, brighter
    assert contrast[0.0] < -8 and contrast[0.5] > 30


def test_wide_wires_appear_in_stereo_with_holes_and_solids_hide_wires() -> None:
    thick = Wire.straight([3.0, -5.0, -5.0], [3.0, 5.0, -5.0], radius_m=0.05)
    world = World(wires=[thick], ground_down_m=1000.0, lighting=BEHIND)
    frame = camera(world, disparity_noise_px=0.0, stereo_wire_fill=0.5).render(0.0, LEVEL)
    on_wire = frame.disparity_px[frame.wire_mask]
    matched = np.isclose(on_wire, RIG.bf_px_m / 3.0, rtol=0.02)
    assert 0.3 < matched.mean() < 0.7  # half matched, the rest shows the sky behind
    assert np.all(on_wire[~matched] == 0.0)
    full = camera(world, disparity_noise_px=0.0, stereo_wire_fill=1.0).render(0.0, LEVEL)
    assert np.isclose(full.disparity_px[full.wire_mask], RIG.bf_px_m / 3.0, rtol=0.02).mean() > 0.9
    hidden = Wire.straight([20.0, -30.0, -5.0], [20.0, 30.0, -5.0], radius_m=0.05)
    occluded = camera(World(solids=[wall(8.0)], wires=[hidden])).render(0.0, LEVEL)
    assert not occluded.wire_mask.any() and not occluded.image_wire_mask.any()


def test_a_wires_width_falls_with_distance() -> None:
    camera_320 = RIG.camera
    widths = []
    for distance in (3.0, 6.0, 12.0):
        wire = Wire.straight([distance, -30.0, -5.0], [distance, 30.0, -5.0], radius_m=0.01)
        layer = project_wires(World(wires=[wire]), camera_320, LEVEL @ MOUNT, 4)
        widths.append(layer.coverage[:, 40:280].sum(axis=0).mean())  # px of wire per column
    expected = [2 * 0.01 * camera_320.fx_px / d for d in (3.0, 6.0, 12.0)]  # d f / z
    np.testing.assert_allclose(widths, expected, rtol=0.08)
    assert expected[2] < 0.5  # the farthest is sub-pixel, and still drawn


def test_the_cameras_tilt_with_the_airframe() -> None:
    sim = camera(World(lighting=BEHIND))
    f = RIG.camera.fy_px

    def horizon_rows(pose: Pose) -> np.ndarray:
        """Per column, the first row that sees the ground."""
        return np.argmax(np.isfinite(sim.render(0.0, pose).depth_m), axis=0).astype(float)

    level = horizon_rows(LEVEL)
    pitched = horizon_rows(Pose.from_yaw_pitch_roll(0.0, np.deg2rad(10.0), 0.0, [0, 0, -5.0]))
    # nose up by 10 deg: the horizon drops by f tan(10 deg) px
    assert np.median(pitched - level) == pytest.approx(f * np.tan(np.deg2rad(10.0)), abs=1.5)
    rolled = horizon_rows(Pose.from_yaw_pitch_roll(0.0, 0.0, np.deg2rad(10.0), [0, 0, -5.0]))
    slope = np.polyfit(np.arange(40, 280), rolled[40:280], 1)[0]
    assert slope == pytest.approx(-np.tan(np.deg2rad(10.0)), abs=0.01)  # right wing down


def test_the_same_surface_point_looks_the_same_from_every_pose() -> None:
    sim = camera(World(solids=[wall(5.0, "brick")], lighting=BEHIND), **CLEAN)
    shift_px = 10  # colour pixels
    step_m = shift_px * 5.0 / sim.colour_camera.fx_px
    a = sim.render(0.0, LEVEL).image_bgr.astype(float).mean(axis=2)
    moved = Pose.from_yaw_pitch_roll(0.0, 0.0, 0.0, [0.0, step_m, -5.0])
    b = sim.render(0.0, moved).image_bgr.astype(float).mean(axis=2)
    aligned = np.corrcoef(
        a[20:100, 30 + shift_px : 130].ravel(), b[20:100, 30 : 130 - shift_px].ravel()
    )
    unaligned = np.corrcoef(a[20:100, 30:130].ravel(), b[20:100, 30:130].ravel())
    assert aligned[0, 1] > 0.9 and unaligned[0, 1] < 0.5


def test_the_injected_noise_is_not_the_sigma_the_mapper_assumes() -> None:
    """The mapper assumes mapping.disparity_sigma_px (0.23); the simulator injects its own
    camera_sim.disparity_noise_px. Calibration recovers the injected one, and a mismatch
    shows as false occupancy in front of a wall."""
    assert PARAMS.disparity_sigma_px == pytest.approx(0.23)
    full = stereo_rig_from_params(MappingParams().camera)
    measured, expected = [], []
    for k, distance_m in enumerate([2.0, 3.0]):
        board = Checkerboard(distance_m, -0.45, -5.3, (9, 6), 0.1)
        sim = SimulatedStereoCamera(
            World(boards=[board]),
            full,
            MOUNT,
            CameraSimParams(disparity_noise_px=0.6),
            colour_downscale=1,
        )
        for shot in range(3):
            frame = sim.render(k + 0.1 * shot, LEVEL)
            corners = find_corners(frame.image_bgr.mean(axis=2).astype(np.uint8), (8, 5))
            measured.append(sample_disparity(frame.disparity_px, corners))
            expected.append(full.disparity_from_depth(corner_depths_m(full, corners, (8, 5), 0.1)))
    fit = fit_disparity_sigma(np.concatenate(measured), np.concatenate(expected))
    assert fit.sigma_px == pytest.approx(0.6, rel=0.15)

    def false_occupancy(injected_px: float) -> float:
        world = World(solids=[wall(6.0)], lighting=BEHIND)
        sim = camera(world, disparity_noise_px=injected_px)
        droan = DroanMap(RIG, PARAMS)
        for i in range(6):
            frame = sim.render(0.1 * i, Pose.from_yaw_pitch_roll(0, 0, 0, [0.0, 0.1 * i, -3.0]))
            droan.insert(frame.stamp_s, frame.world_from_camera, frame.disparity_px, None)
        n, e, d = np.meshgrid([4.5], np.linspace(-3, 3, 25), np.linspace(-5, -1, 17))
        free = np.stack([n.ravel(), e.ravel(), d.ravel()], 1)  # 1.5 m in front of the wall
        return float(droan.query(free).collision.mean())

    # measured: 0.27 with the assumed noise injected, 1.0 with 0.6 px injected
    matched, mismatched = false_occupancy(0.23), false_occupancy(0.6)
    assert matched < 0.5 and mismatched > 0.9


def test_sgbm_mode_matches_the_rendered_pair() -> None:
    sim = camera(World(solids=[wall(4.0, "concrete")], lighting=BEHIND), stereo_mode="sgbm")
    frame = sim.render(0.0, LEVEL)
    centre = frame.disparity_px[40:200, 150:310]  # right of SGBM's invalid band
    assert np.isfinite(centre).mean() > 0.8
    assert RIG.depth_from_disparity(np.nanmedian(centre)) == pytest.approx(4.0, rel=0.05)


def test_render_state_uses_the_vehicle_ground_truth() -> None:
    yaw = np.pi / 2
    state = SimpleNamespace(
        time_s=2.5,
        position_ned_m=np.array([0.0, 0.0, -5.0]),
        attitude_wxyz=np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)]),
    )
    east_box = Solid(Box([-1.0, 10.0, -6.0], [1.0, 12.0, -4.0]))
    sim = camera(World(solids=[east_box], ground_down_m=1000.0))
    frame = sim.render_state(state)
    assert frame.stamp_s == 2.5
    assert frame.depth_m[120, 160] == pytest.approx(10.0, abs=1e-4)
    facing = Pose.from_yaw_pitch_roll(yaw, 0.0, 0.0, [0.0, 0.0, -5.0])
    expected = (facing @ MOUNT).matrix()
    np.testing.assert_allclose(frame.world_from_camera.matrix(), expected, atol=1e-12)


def test_the_shipped_cnn_finds_the_rendered_ladder_wire_and_little_else() -> None:
    """The colour camera looks enough like a camera for the shipped model (320x240, the
    default rig): the thesis' wire between ladders 4 m and 6 m ahead, seed 0."""
    from dataclasses import replace

    from hil.world.scenarios import build_scenario
    from perception.metrics import image_counts
    from perception.params import PerceptionParams
    from perception.segmenter import WireSegmenter

    segmenter = WireSegmenter.load(params=PerceptionParams())
    params = MappingParams()
    rig = stereo_rig_from_params(params.camera)
    world = build_scenario("ladder-wire", 0)
    wire_north = world.wires[0].points_ned_m[0, 0]
    recall, false_share = [], []
    for distance_m, w in ((4.0, world), (6.0, world), (6.0, replace(world, wires=()))):
        sim = SimulatedStereoCamera(
            w, rig, body_from_camera_from_params(params.camera), CameraSimParams(),
            colour_downscale=CameraParams().colour_downscale,
        )  # fmt: skip
        position = world.takeoff_point_ned_m + np.array([wire_north - distance_m, 0.0, 0.0])
        frame = sim.render(0.0, Pose.from_yaw_pitch_roll(0.0, 0.0, 0.0, position))
        assert frame.image_bgr.shape == (240, 320, 3)
        mask = segmenter.mask(frame.image_bgr)  # thresholded at 0.95, speckle-filtered
        counts = image_counts(mask, frame.image_wire_mask, np.array([0.5]), tolerance_px=2)
        if counts.n_true:
            recall.append(counts.tp_true[0] / counts.n_true)
        false_share.append((counts.n_pred[0] - counts.tp_pred[0]) / mask.size)
    # measured within 2 px: recall 0.90 at 4 m and 0.87 at 6 m; false marks 0.29 %, 0.31 %
    # and 0.41 % of the frame without the wire (cloud edges, ladder rails, shadow edges)
    assert min(recall) > 0.7
    assert max(false_share) < 0.01


def test_a_photo_named_like_a_material_textures_it(tmp_path) -> None:
    import cv2

    from hil.sensors.textures import TILE_PX, TextureAtlas, photo_textures

    stripes = np.zeros((300, 400, 3), np.uint8)
    stripes[:, ::20] = 255  # a photo of vertical stripes, as brick.png would be a brick wall
    cv2.imwrite(str(tmp_path / "brick.png"), stripes)
    cv2.imwrite(str(tmp_path / "holiday.png"), stripes)  # not a material: ignored
    photos = photo_textures([str(tmp_path)])
    assert set(photos) == {"brick"}
    atlas = TextureAtlas.build(0, photos)
    procedural = TextureAtlas.build(0)
    k = atlas.index["brick"]
    start = atlas.offsets[k, 0]
    tile = atlas.texels[start : start + TILE_PX * TILE_PX].reshape(TILE_PX, TILE_PX, 3)
    columns = tile.mean(axis=(0, 2))
    assert columns.std() > 2 * tile.mean(axis=(1, 2)).std()  # the stripes run down the wall
    other = atlas.offsets[atlas.index["grass"], 0]
    np.testing.assert_array_equal(
        atlas.texels[other : other + 100], procedural.texels[other : other + 100]
    )
    assert not np.array_equal(
        atlas.texels[start : start + 100], procedural.texels[start : start + 100]
    )
